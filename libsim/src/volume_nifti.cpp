// NIfTI-1 single-file (.nii, .nii.gz) reading and writing. Reading takes 3-D scalar images of the
// common datatypes in either byte order, with scl_slope/scl_inter applied before the density
// window; writing stores density only, as uint8. docs/volumes.md.
#include "volume_io_detail.h"

#include <cmath>
#include <cstring>
#include <filesystem>

namespace trephine::detail {

namespace fs = std::filesystem;

namespace {

constexpr int kHeaderSize = 348;
constexpr int kNifti2HeaderSize = 540;

// Field offsets in the 348-byte header.
enum Offset : size_t {
    kSizeofHdr = 0,
    kRegular = 38,
    kDim = 40,
    kDatatype = 70,
    kBitpix = 72,
    kPixdim = 76,
    kVoxOffset = 108,
    kSclSlope = 112,
    kSclInter = 116,
    kXyztUnits = 123,
    kCalMax = 124,
    kCalMin = 128,
    kDescrip = 148,
    kQformCode = 252,
    kSformCode = 254,
    kSrowX = 280,
    kMagic = 344,
};

struct Reader {
    const uint8_t* bytes;
    bool swap;
    template <typename T>
    T get(size_t offset) const {
        T v;
        std::memcpy(&v, bytes + offset, sizeof v);
        if constexpr (sizeof(T) == 2) {
            uint16_t u;
            std::memcpy(&u, &v, 2);
            u = swap ? bswap(u) : u;
            std::memcpy(&v, &u, 2);
        } else if constexpr (sizeof(T) == 4) {
            uint32_t u;
            std::memcpy(&u, &v, 4);
            u = swap ? bswap(u) : u;
            std::memcpy(&v, &u, 4);
        }
        return v;
    }
};

struct Datatype {
    int16_t code;
    ScalarType type;
};
constexpr Datatype kDatatypes[] = {
    {2, ScalarType::UInt8},     {4, ScalarType::Int16},    {8, ScalarType::Int32},
    {16, ScalarType::Float32},  {64, ScalarType::Float64}, {256, ScalarType::Int8},
    {512, ScalarType::UInt16},  {768, ScalarType::UInt32}, {1024, ScalarType::Int64},
    {1280, ScalarType::UInt64},
};

Volume readNiftiFrom(ByteSource& src, const std::string& path,
                     const std::optional<DensityWindow>& window, uint64_t rawFileSize) {
    uint8_t hdr[kHeaderSize];
    size_t got = src.read(hdr, sizeof hdr);
    if (got < 4)
        fail(path, "truncated: not a NIfTI-1 file (" + std::to_string(got) + " bytes)");
    uint32_t sizeofHdr;
    std::memcpy(&sizeofHdr, hdr, 4);
    const bool swap = bswap(sizeofHdr) == kHeaderSize;
    if (sizeofHdr == kNifti2HeaderSize || bswap(sizeofHdr) == kNifti2HeaderSize)
        fail(path, "NIfTI-2 is not supported: save it as NIfTI-1 or NRRD");
    if (sizeofHdr != kHeaderSize && !swap)
        fail(path, "not a NIfTI-1 file: sizeof_hdr is " + std::to_string(int32_t(sizeofHdr)) +
                       ", expected 348");
    if (got < sizeof hdr)
        fail(path, "truncated: NIfTI-1 header needs 348 bytes, found " + std::to_string(got));
    Reader r{hdr, swap};

    const char* magic = reinterpret_cast<const char*>(hdr + kMagic);
    if (std::memcmp(magic, "ni1\0", 4) == 0)
        fail(path, "two-file NIfTI (.hdr + .img) is not supported: use a single .nii file");
    if (std::memcmp(magic, "n+1\0", 4) != 0)
        fail(path, "bad NIfTI-1 magic: expected \"n+1\" (single-file NIfTI-1)");

    int16_t dim[8];
    for (int i = 0; i < 8; ++i)
        dim[i] = r.get<int16_t>(kDim + 2 * size_t(i));
    if (dim[0] < 1 || dim[0] > 7)
        fail(path, "bad NIfTI dim[0] " + std::to_string(dim[0]) + ": expected 1..7");
    int64_t n[3] = {1, 1, 1};
    for (int i = 1; i <= dim[0]; ++i) {
        if (dim[i] < 1)
            fail(path, "bad NIfTI dim[" + std::to_string(i) + "] " + std::to_string(dim[i]) +
                           ": sizes must be positive");
        if (i <= 3)
            n[i - 1] = dim[i];
        else if (dim[i] != 1)
            fail(path, "NIfTI image has " + std::to_string(dim[0]) + " dimensions (dim[" +
                           std::to_string(i) + "] = " + std::to_string(dim[i]) +
                           "): expected a 3-D volume");
    }
    checkDims(n[0], n[1], n[2], path);
    glm::ivec3 dims{int(n[0]), int(n[1]), int(n[2])};

    DecodeSpec spec;
    spec.window = window;
    spec.bigEndian = swap != (std::endian::native == std::endian::big);
    int16_t datatype = r.get<int16_t>(kDatatype);
    const Datatype* dt = nullptr;
    for (const Datatype& d : kDatatypes)
        if (d.code == datatype)
            dt = &d;
    if (!dt)
        fail(path, "unsupported NIfTI datatype " + std::to_string(datatype) +
                       " (expected uint8, int8, int16, uint16, int32, uint32, float32 or "
                       "float64)");
    spec.type = dt->type;
    int16_t bitpix = r.get<int16_t>(kBitpix);
    if (bitpix != int16_t(8 * scalarSize(spec.type)))
        fail(path, "bad NIfTI bitpix " + std::to_string(bitpix) + " for datatype " +
                       scalarName(spec.type));

    float slope = r.get<float>(kSclSlope), inter = r.get<float>(kSclInter);
    // scl_slope 0 (or not finite) means "no scaling", per the NIfTI-1 standard.
    if (std::isfinite(slope) && slope != 0.0f) {
        spec.slope = slope;
        spec.inter = std::isfinite(inter) ? inter : 0.0;
    }

    glm::vec3 spacing(1.0f);
    double unit = 1.0;
    switch (hdr[kXyztUnits] & 0x07) {
    case 1:
        unit = 1000.0;
        break; // metre
    case 3:
        unit = 0.001;
        break; // micron
    default:
        break; // mm, or unknown: taken as mm
    }
    for (int i = 0; i < 3 && i < dim[0]; ++i) {
        const float p = std::fabs(r.get<float>(kPixdim + 4 * size_t(i + 1)));
        // NaN or 0 would load as 1 mm: a skull of the wrong size, silently.
        if (!std::isfinite(p) || p == 0.0f)
            fail(path, "bad NIfTI pixdim[" + std::to_string(i + 1) + "] " + formatFloat(p) +
                           ": a voxel's size must be finite and non-zero");
        spacing[i] = float(p * unit);
    }

    float voxOffset = r.get<float>(kVoxOffset);
    if (!(voxOffset >= float(kHeaderSize)) || voxOffset != std::floor(voxOffset) ||
        voxOffset > float(1 << 30))
        fail(path, "bad NIfTI vox_offset " + formatFloat(voxOffset) +
                       ": expected a whole byte offset of at least 348");
    const uint64_t offset = uint64_t(voxOffset);
    if (rawFileSize) {
        // Uncompressed: check the size before anything is allocated.
        uint64_t need = dataBytes(dims, spec);
        uint64_t have = rawFileSize > offset ? rawFileSize - offset : 0;
        if (have < need)
            fail(path, "truncated: expected " + std::to_string(need) + " bytes of data, found " +
                           std::to_string(have));
    }
    if (src.skip(offset - kHeaderSize) < offset - kHeaderSize)
        fail(path, "truncated: the file ends before vox_offset " + std::to_string(offset));
    return decodeVoxels(src, dims, spacing, spec, true);
}

void put16(uint8_t* h, size_t off, int16_t v) {
    std::memcpy(h + off, &v, 2);
}
void put32(uint8_t* h, size_t off, int32_t v) {
    std::memcpy(h + off, &v, 4);
}
void putF(uint8_t* h, size_t off, float v) {
    std::memcpy(h + off, &v, 4);
}

} // namespace

Volume readNifti(const std::string& path, const std::optional<DensityWindow>& window) {
    FileSource file(path, path);
    uint8_t head[2] = {};
    size_t n = file.read(head, 2);
    file.seek(0);
    if (isGzipMagic(head, n)) {
        GzipSource gz(file, path);
        return readNiftiFrom(gz, path, window, 0);
    }
    return readNiftiFrom(file, path, window, file.size());
}

void writeNifti(const Volume& v, const std::string& path, bool compress) {
    static_assert(std::endian::native == std::endian::little,
                  "the NIfTI writer stores host-order fields");
    uint8_t h[kHeaderSize + 4] = {}; // + 4 bytes of "no extensions"
    const glm::ivec3 d = v.dims();
    const glm::vec3 s = v.spacing();
    put32(h, kSizeofHdr, kHeaderSize);
    h[kRegular] = 'r';
    const int16_t dim[8] = {3, int16_t(d.x), int16_t(d.y), int16_t(d.z), 1, 1, 1, 1};
    if (d.x > 32767 || d.y > 32767 || d.z > 32767)
        fail(path, "NIfTI-1 cannot hold more than 32767 voxels along an axis");
    for (int i = 0; i < 8; ++i)
        put16(h, kDim + 2 * size_t(i), dim[i]);
    put16(h, kDatatype, 2); // DT_UINT8
    put16(h, kBitpix, 8);
    const float pixdim[8] = {1.0f, s.x, s.y, s.z, 1.0f, 1.0f, 1.0f, 1.0f};
    for (int i = 0; i < 8; ++i)
        putF(h, kPixdim + 4 * size_t(i), pixdim[i]);
    putF(h, kVoxOffset, float(sizeof h));
    putF(h, kSclSlope, 1.0f);
    putF(h, kSclInter, 0.0f);
    h[kXyztUnits] = 2; // mm
    putF(h, kCalMax, 255.0f);
    putF(h, kCalMin, 0.0f);
    std::strncpy(reinterpret_cast<char*>(h + kDescrip), "Trephine density (uint8)", 79);
    // sform "aligned anatomy": voxel centres in mm, volume centred on the origin as in Volume.
    put16(h, kQformCode, 0);
    put16(h, kSformCode, 2);
    const glm::vec3 o = v.voxelCenter(glm::ivec3(0));
    const float srow[12] = {s.x, 0, 0, o.x, 0, s.y, 0, o.y, 0, 0, s.z, o.z};
    for (int i = 0; i < 12; ++i)
        putF(h, kSrowX + 4 * size_t(i), srow[i]);
    std::memcpy(h + kMagic, "n+1\0", 4);

    // A temporary file renamed over `path` once complete (FileSink): a failure leaves whatever
    // was there before untouched.
    FileSink file(path);
    std::unique_ptr<GzipSink> gz;
    ByteSink* out = &file;
    if (compress) {
        gz = std::make_unique<GzipSink>(file, path);
        out = gz.get();
    }
    out->write(h, sizeof h);
    out->write(v.densityData(), v.voxelCount());
    out->finish();
    file.commit();
}

} // namespace trephine::detail

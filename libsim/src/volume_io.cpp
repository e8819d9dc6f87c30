// Volume specs and the plumbing under every format: byte sources and sinks (plain and gzip),
// decoding scalars through the density window, and the spec dispatcher.
//
// [SECTION] Window and materials
// [SECTION] Sources and sinks
// [SECTION] Decoding
// [SECTION] Spec parsing
// [SECTION] Raw voxels
// [SECTION] loadVolume / saveVolume / help
#include "libsim/volume_io.h"

#include "libsim/regular_file.h"
#include "libsim/replacing_file.h"

#include "libsim/skull.h"
#include "volume_io_detail.h"

#include <algorithm>
#include <bit>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fmt/format.h>
#include <type_traits>
#include <unistd.h>
#include <zlib.h>

namespace trephine {

namespace fs = std::filesystem;
using namespace detail;

// [SECTION] Window and materials

uint8_t windowDensity(double v, DensityWindow w) {
    if (std::isnan(v))
        return 0;
    double t = (v - w.lo) / (w.hi - w.lo) * 255.0;
    if (!(t > 0.0))
        return 0;
    if (t >= 255.0)
        return 255;
    return uint8_t(std::lround(t));
}

Material materialFromDensity(uint8_t density) {
    if (density < kSurfaceDensity)
        return Material::Air;
    return density < kCorticalDensity ? Material::Diploe : Material::Cortical;
}

namespace detail {

void fail(const std::string& name, const std::string& problem) {
    throw Error(name + ": " + problem);
}

std::string formatFloat(double v) {
    return fmt::format("{:.9g}", v);
}

bool endsWith(const std::string& s, const std::string& suffix) {
    return s.size() >= suffix.size() &&
           s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}

std::string toLower(std::string s) {
    for (char& c : s)
        c = char(std::tolower(static_cast<unsigned char>(c)));
    return s;
}

// [SECTION] Sources and sinks

namespace {
constexpr size_t kChunkBytes = size_t(1) << 18;
// Data past the voxels is counted up to the voxels' size or this, whichever is more.
constexpr uint64_t kMaxTrailingCount = uint64_t(64) << 20;

std::string systemError() {
    return std::strerror(errno);
}
} // namespace

size_t ByteSource::read(void* dst, size_t n) {
    size_t done = 0;
    auto* out = static_cast<uint8_t*>(dst);
    while (done < n) {
        size_t got = readSome(out + done, n - done);
        if (got == 0)
            break;
        done += got;
    }
    m_position += done;
    return done;
}

uint64_t ByteSource::skip(uint64_t n) {
    uint8_t scratch[16384];
    uint64_t done = 0;
    while (done < n) {
        size_t want = size_t(std::min<uint64_t>(n - done, sizeof scratch));
        size_t got = read(scratch, want);
        done += got;
        if (got < want)
            break;
    }
    return done;
}

FileSource::FileSource(const std::string& path, const std::string& name) : ByteSource(name) {
    // A device or a pipe has no size to check a header against and may never end or never open:
    // a NRRD's `data file: /dev/urandom` with a large line skip read forever, a FIFO blocked.
    requireRegularFile(path, name, "volumes are read from files");
    m_file = std::fopen(path.c_str(), "rb");
    if (!m_file)
        fail(name, "cannot open: " + systemError());
    std::error_code ec;
    uint64_t size = fs::file_size(path, ec);
    m_size = ec ? 0 : size;
}

FileSource::~FileSource() {
    if (m_file)
        std::fclose(m_file);
}

uint64_t FileSource::tell() const {
    return uint64_t(ftello(m_file));
}

void FileSource::seek(uint64_t offset) {
    if (fseeko(m_file, off_t(offset), SEEK_SET) != 0)
        fail(name(), "cannot seek: " + systemError());
}

size_t FileSource::readSome(void* dst, size_t n) {
    size_t got = std::fread(dst, 1, n, m_file);
    if (got == 0 && std::ferror(m_file))
        fail(name(), "read error: " + systemError());
    return got;
}

bool FileSource::readLine(std::string& line, size_t maxLength) {
    line.clear();
    int c;
    while ((c = std::fgetc(m_file)) != EOF) {
        if (c == '\n')
            break;
        line.push_back(char(c));
        if (line.size() > maxLength)
            fail(name(), "header line longer than " + std::to_string(maxLength) +
                             " characters: not a text header");
    }
    if (c == EOF && line.empty())
        return false;
    if (!line.empty() && line.back() == '\r')
        line.pop_back();
    return true;
}

bool FileSource::skipLine(size_t maxLength) {
    size_t length = 0;
    int c;
    while ((c = std::fgetc(m_file)) != EOF && c != '\n')
        if (++length > maxLength)
            fail(name(), "a line to skip is longer than " + std::to_string(maxLength) +
                             " characters: not a text line");
    if (c == EOF && std::ferror(m_file))
        fail(name(), "read error: " + systemError());
    return c != EOF || length > 0;
}

bool isGzipMagic(const uint8_t* bytes, size_t n) {
    return n >= 2 && bytes[0] == 0x1f && bytes[1] == 0x8b;
}

GzipSource::GzipSource(ByteSource& compressed, const std::string& name)
    : ByteSource(name), m_in(compressed), m_z(std::make_unique<z_stream>()),
      m_buffer(std::make_unique<uint8_t[]>(kChunkBytes)) {
    *m_z = z_stream{};
    // 15 + 32: accept gzip or zlib headers.
    if (inflateInit2(m_z.get(), 15 + 32) != Z_OK)
        fail(name, "cannot start gzip decompression");
}

GzipSource::~GzipSource() {
    inflateEnd(m_z.get());
}

size_t GzipSource::readSome(void* dst, size_t n) {
    if (m_end || n == 0)
        return 0;
    z_stream& z = *m_z;
    z.next_out = static_cast<Bytef*>(dst);
    z.avail_out = uInt(std::min<size_t>(n, size_t(1) << 30));
    const uInt wanted = z.avail_out;
    auto refill = [&] {
        size_t got = m_in.read(m_buffer.get(), kChunkBytes);
        z.next_in = m_buffer.get();
        z.avail_in = uInt(got);
        return got;
    };
    while (z.avail_out > 0) {
        if (z.avail_in == 0 && refill() == 0)
            fail(name(), "truncated gzip data: the compressed stream ends early");
        int r = inflate(&z, Z_NO_FLUSH);
        if (r == Z_STREAM_END) {
            // Another gzip member may follow (concatenated .gz files are one stream).
            if (z.avail_in == 0 && refill() == 0) {
                m_end = true;
                break;
            }
            if (z.next_in[0] != 0x1f) {
                m_end = true; // trailing bytes after the stream: ignored, as gzip does
                break;
            }
            inflateReset(&z);
        } else if (r != Z_OK && r != Z_BUF_ERROR) {
            fail(name(), std::string("corrupt gzip data: ") + (z.msg ? z.msg : zError(r)));
        }
    }
    return wanted - z.avail_out;
}

FileSink::FileSink(const std::string& path)
    : m_path(path), m_temp(path + ".trephine-" + std::to_string(::getpid()) + ".tmp") {
    std::error_code ec;
    if (fs::is_directory(path, ec))
        fail(path, "cannot write: it is a folder");
    removeAbandonedTemps(path); // a killed save's leftovers
    m_file = std::fopen(m_temp.c_str(), "wb");
    if (!m_file)
        fail(path, "cannot write: " + systemError());
}

FileSink::~FileSink() {
    if (m_file)
        std::fclose(m_file);
    if (!m_committed) {
        std::error_code ec;
        fs::remove(m_temp, ec);
    }
}

void FileSink::write(const void* data, size_t n) {
    if (!m_file)
        fail(m_path, "cannot write: already finished");
    if (n && std::fwrite(data, 1, n, m_file) != n)
        fail(m_path, "cannot write: " + systemError());
}

void FileSink::finish() {
    std::FILE* f = m_file;
    m_file = nullptr;
    if (!f)
        return;
    if (std::fflush(f) != 0 || std::ferror(f) || ::fsync(::fileno(f)) != 0) {
        const std::string why = systemError();
        std::fclose(f);
        fail(m_path, "cannot write: " + why);
    }
    if (std::fclose(f) != 0)
        fail(m_path, "cannot write: " + systemError());
}

void FileSink::commit() {
    finish();
    if (std::rename(m_temp.c_str(), m_path.c_str()) != 0)
        fail(m_path, "cannot write: " + systemError());
    m_committed = true;
}

GzipSink::GzipSink(ByteSink& out, const std::string& name)
    : m_out(out), m_name(name), m_z(std::make_unique<z_stream>()),
      m_buffer(std::make_unique<uint8_t[]>(kChunkBytes)) {
    *m_z = z_stream{};
    // Level 3: volumes are mostly air and smooth, so fast levels already compress them well.
    if (deflateInit2(m_z.get(), 3, Z_DEFLATED, 15 + 16, 8, Z_DEFAULT_STRATEGY) != Z_OK)
        fail(name, "cannot start gzip compression");
}

GzipSink::~GzipSink() {
    deflateEnd(m_z.get());
}

void GzipSink::pump(int flush) {
    z_stream& z = *m_z;
    int r;
    do {
        z.next_out = m_buffer.get();
        z.avail_out = uInt(kChunkBytes);
        r = deflate(&z, flush);
        if (r == Z_STREAM_ERROR)
            fail(m_name, "gzip compression failed");
        m_out.write(m_buffer.get(), kChunkBytes - z.avail_out);
    } while (z.avail_out == 0 || (flush == Z_FINISH && r != Z_STREAM_END));
}

void GzipSink::write(const void* data, size_t n) {
    auto* p = static_cast<const uint8_t*>(data);
    while (n > 0) {
        size_t part = std::min<size_t>(n, size_t(1) << 30);
        m_z->next_in = const_cast<Bytef*>(p);
        m_z->avail_in = uInt(part);
        pump(Z_NO_FLUSH);
        p += part;
        n -= part;
    }
}

void GzipSink::finish() {
    m_z->next_in = nullptr;
    m_z->avail_in = 0;
    pump(Z_FINISH);
    m_out.finish();
}

// [SECTION] Decoding

size_t scalarSize(ScalarType t) {
    switch (t) {
    case ScalarType::Int8:
    case ScalarType::UInt8:
        return 1;
    case ScalarType::Int16:
    case ScalarType::UInt16:
        return 2;
    case ScalarType::Int32:
    case ScalarType::UInt32:
    case ScalarType::Float32:
        return 4;
    case ScalarType::Int64:
    case ScalarType::UInt64:
    case ScalarType::Float64:
        return 8;
    }
    return 1;
}

const char* scalarName(ScalarType t) {
    switch (t) {
    case ScalarType::Int8:
        return "int8";
    case ScalarType::UInt8:
        return "uint8";
    case ScalarType::Int16:
        return "int16";
    case ScalarType::UInt16:
        return "uint16";
    case ScalarType::Int32:
        return "int32";
    case ScalarType::UInt32:
        return "uint32";
    case ScalarType::Int64:
        return "int64";
    case ScalarType::UInt64:
        return "uint64";
    case ScalarType::Float32:
        return "float32";
    case ScalarType::Float64:
        return "float64";
    }
    return "?";
}

void checkDims(int64_t nx, int64_t ny, int64_t nz, const std::string& name) {
    auto dimsText = [&] {
        return std::to_string(nx) + "x" + std::to_string(ny) + "x" + std::to_string(nz);
    };
    if (nx <= 0 || ny <= 0 || nz <= 0)
        fail(name, "bad dimensions " + dimsText() + ": every size must be positive");
    constexpr int64_t kMaxAxis = int64_t(1) << 20;
    if (nx > kMaxAxis || ny > kMaxAxis || nz > kMaxAxis ||
        uint64_t(nx) * uint64_t(ny) * uint64_t(nz) > kMaxVolumeVoxels)
        fail(name, "dimensions " + dimsText() + " are too large: at most " +
                       std::to_string(kMaxVolumeVoxels) + " voxels (1024^3) are accepted");
}

uint64_t dataBytes(glm::ivec3 dims, const DecodeSpec& spec) {
    return uint64_t(dims.x) * uint64_t(dims.y) * uint64_t(dims.z) * scalarSize(spec.type) *
           uint64_t(spec.components);
}

namespace {

template <typename T>
T loadScalar(const uint8_t* p, bool swap) {
    if constexpr (sizeof(T) == 1) {
        (void)swap;
        return T(*p);
    } else {
        using U = std::conditional_t<sizeof(T) == 2, uint16_t,
                                     std::conditional_t<sizeof(T) == 4, uint32_t, uint64_t>>;
        U u;
        std::memcpy(&u, p, sizeof u);
        if (swap)
            u = bswap(u);
        T v;
        std::memcpy(&v, &u, sizeof v);
        return v;
    }
}

template <typename T>
void convertScalars(const uint8_t* in, size_t n, bool swap, double slope, double inter,
                    DensityWindow w, uint8_t* density) {
    for (size_t i = 0; i < n; ++i)
        density[i] =
            windowDensity(double(loadScalar<T>(in + i * sizeof(T), swap)) * slope + inter, w);
}

// Decodes n voxels' bytes into density (and material, derived or read).
void decodeChunk(const uint8_t* in, size_t n, const DecodeSpec& spec, bool passThrough,
                 const std::string& name, uint8_t* density, uint8_t* material) {
    if (spec.components == 2) {
        for (size_t i = 0; i < n; ++i) {
            uint8_t m = in[2 * i + 1];
            if (m >= kMaterialCount)
                fail(name, "bad material label " + std::to_string(m) + " (known labels are 0.." +
                               std::to_string(kMaterialCount - 1) + ")");
            density[i] = in[2 * i];
            material[i] = m;
        }
        return;
    }
    if (passThrough) {
        std::memcpy(density, in, n);
    } else {
        const bool swap = spec.bigEndian != (std::endian::native == std::endian::big);
        DensityWindow w = spec.window.value_or(kDefaultWindow);
        const double a = spec.slope, b = spec.inter;
        switch (spec.type) {
        case ScalarType::Int8:
            convertScalars<int8_t>(in, n, swap, a, b, w, density);
            break;
        case ScalarType::UInt8:
            convertScalars<uint8_t>(in, n, swap, a, b, w, density);
            break;
        case ScalarType::Int16:
            convertScalars<int16_t>(in, n, swap, a, b, w, density);
            break;
        case ScalarType::UInt16:
            convertScalars<uint16_t>(in, n, swap, a, b, w, density);
            break;
        case ScalarType::Int32:
            convertScalars<int32_t>(in, n, swap, a, b, w, density);
            break;
        case ScalarType::UInt32:
            convertScalars<uint32_t>(in, n, swap, a, b, w, density);
            break;
        case ScalarType::Int64:
            convertScalars<int64_t>(in, n, swap, a, b, w, density);
            break;
        case ScalarType::UInt64:
            convertScalars<uint64_t>(in, n, swap, a, b, w, density);
            break;
        case ScalarType::Float32:
            convertScalars<float>(in, n, swap, a, b, w, density);
            break;
        case ScalarType::Float64:
            convertScalars<double>(in, n, swap, a, b, w, density);
            break;
        }
    }
    for (size_t i = 0; i < n; ++i)
        material[i] = uint8_t(materialFromDensity(density[i]));
}

} // namespace

void checkRawSize(const FileSource& file, uint64_t offset, uint64_t need) {
    uint64_t have = file.size() > offset ? file.size() - offset : 0;
    if (have < need)
        fail(file.name(), "truncated: expected " + std::to_string(need) + " bytes of data, found " +
                              std::to_string(have));
    if (have > need)
        fail(file.name(), "dimensions do not match the data: they need " + std::to_string(need) +
                              " bytes of data, found " + std::to_string(have));
}

Volume decodeVoxels(ByteSource& src, glm::ivec3 dims, glm::vec3 spacing, const DecodeSpec& spec,
                    bool exactEnd) {
    checkDims(dims.x, dims.y, dims.z, src.name());
    checkSpacing(src.name(), spacing);
    const uint64_t voxels = uint64_t(dims.x) * uint64_t(dims.y) * uint64_t(dims.z);
    const size_t voxelBytes = scalarSize(spec.type) * size_t(spec.components);
    const uint64_t need = voxels * voxelBytes;
    const bool passThrough = spec.components == 1 && spec.type == ScalarType::UInt8 &&
                             !spec.window && spec.slope == 1.0 && spec.inter == 0.0;

    // Grow the output as data arrives rather than trusting the header's size, so a short or
    // lying file costs no more memory than it holds; by doubling, capped at the size, so the
    // buffers end exactly full and become the volume without a copy (a 1024^3 load peaked at
    // twice its size, then a third copy).
    std::vector<uint8_t> density, material;
    auto grow = [&](size_t size) {
        if (size > density.capacity()) {
            const size_t want =
                size_t(std::min<uint64_t>(voxels, std::max<uint64_t>(size, 2 * density.size())));
            density.reserve(want);
            material.reserve(want);
        }
        density.resize(size);
        material.resize(size);
    };
    const size_t chunkVoxels = kChunkBytes / voxelBytes;
    std::vector<uint8_t> buffer(chunkVoxels * voxelBytes);
    const uint64_t start = src.position();
    uint64_t done = 0;
    while (done < voxels) {
        size_t n = size_t(std::min<uint64_t>(chunkVoxels, voxels - done));
        size_t got = src.read(buffer.data(), n * voxelBytes);
        if (got < n * voxelBytes)
            fail(src.name(), "truncated: expected " + std::to_string(need) +
                                 " bytes of data, found " + std::to_string(src.position() - start));
        grow(size_t(done) + n);
        decodeChunk(buffer.data(), n, spec, passThrough, src.name(), density.data() + done,
                    material.data() + done);
        done += n;
    }
    if (exactEnd) {
        // Counted only so far: a small gzip stream that inflates to gigabytes past the voxels is
        // refused after this much, not after inflating all of it (seconds per GiB).
        const uint64_t limit = std::max(need, kMaxTrailingCount);
        uint64_t extra = src.skip(limit + 1);
        if (extra > limit)
            fail(src.name(), "dimensions do not match the data: they need " + std::to_string(need) +
                                 " bytes of data, found more than " + std::to_string(need + limit));
        if (extra > 0)
            fail(src.name(), "dimensions do not match the data: they need " + std::to_string(need) +
                                 " bytes of data, found " + std::to_string(need + extra));
    }
    return Volume(dims, spacing, std::move(density), std::move(material));
}

} // namespace detail

// [SECTION] Spec parsing

namespace {

std::vector<std::string> split(const std::string& s, char sep) {
    std::vector<std::string> out;
    size_t start = 0;
    while (true) {
        size_t p = s.find(sep, start);
        out.push_back(s.substr(start, p == std::string::npos ? std::string::npos : p - start));
        if (p == std::string::npos)
            return out;
        start = p + 1;
    }
}

bool parseNumber(const std::string& s, double& out) {
    const char* end = s.data() + s.size();
    auto r = std::from_chars(s.data(), end, out);
    return r.ec == std::errc() && r.ptr == end && std::isfinite(out);
}

bool parseInteger(const std::string& s, int64_t& out) {
    const char* end = s.data() + s.size();
    auto r = std::from_chars(s.data(), end, out);
    return r.ec == std::errc() && r.ptr == end;
}

std::vector<double> parseNumbers(const std::string& text, size_t count, const std::string& key,
                                 const std::string& what) {
    std::vector<std::string> parts = split(text, ',');
    std::vector<double> out;
    for (const std::string& p : parts) {
        double v;
        if (!parseNumber(p, v))
            break;
        out.push_back(v);
    }
    if (out.size() != count || parts.size() != count)
        fail(what, "bad " + key + "='" + text + "': expected " + std::to_string(count) +
                       " comma-separated numbers");
    return out;
}

std::string usageOf(const std::string& key) {
    if (key == "dims")
        return "X,Y,Z";
    if (key == "spacing")
        return "a,b,c";
    if (key == "window")
        return "lo,hi";
    if (key == "type")
        return "uint8|int16|...";
    if (key == "endian")
        return "little|big";
    return "N";
}

} // namespace

std::string VolumeSpecQuery::get(const std::string& key) const {
    for (const auto& [k, v] : options)
        if (k == key)
            return v;
    return {};
}

bool VolumeSpecQuery::has(const std::string& key) const {
    for (const auto& [k, v] : options)
        if (k == key)
            return true;
    return false;
}

namespace {

// Parses "key=v&key=v" into q.options; errors name `what`.
void parseOptions(VolumeSpecQuery& q, const std::string& text, const std::string& allowedKeys,
                  const std::string& what) {
    std::vector<std::string> allowed;
    std::string allowedText;
    for (const std::string& k : split(allowedKeys, ',')) {
        if (k.empty())
            continue;
        allowed.push_back(k);
        allowedText += (allowedText.empty() ? "" : ", ") + k + "=" + usageOf(k);
    }
    for (const std::string& item : split(text, '&')) {
        size_t eq = item.find('=');
        std::string key = item.substr(0, eq);
        if (key.empty() || std::find(allowed.begin(), allowed.end(), key) == allowed.end())
            fail(what, "unknown option '" + key + "'" +
                           (allowedText.empty() ? std::string(" (this spec takes no options)")
                                                : " (options: " + allowedText + ")"));
        if (eq == std::string::npos || eq + 1 == item.size())
            fail(what, "option '" + key + "' needs a value: " + key + "=" + usageOf(key));
        if (q.has(key))
            fail(what, "option '" + key + "' given twice");
        q.options.emplace_back(key, item.substr(eq + 1));
    }
}

} // namespace

VolumeSpecQuery parseVolumeSpecQuery(const std::string& spec, const std::string& allowedKeys) {
    VolumeSpecQuery q;
    q.name = spec;
    std::error_code ec;
    size_t mark = spec.rfind('?');
    if (mark == std::string::npos || fs::exists(spec, ec))
        return q;
    q.name = spec.substr(0, mark);
    parseOptions(q, spec.substr(mark + 1), allowedKeys, spec);
    return q;
}

std::optional<DensityWindow> parseWindowOption(const VolumeSpecQuery& q, const std::string& what) {
    if (!q.has("window"))
        return std::nullopt;
    std::vector<double> w = parseNumbers(q.get("window"), 2, "window", what);
    if (!(w[0] < w[1]))
        fail(what, "bad window=" + q.get("window") + ": lo must be below hi");
    return DensityWindow{w[0], w[1]};
}

void checkSpacing(const std::string& what, glm::dvec3 spacing) {
    const glm::vec3 kept(spacing); // as it will be kept
    auto refuse = [&](const char* why) {
        fail(what, "spacing " + formatFloat(kept.x) + "," + formatFloat(kept.y) + "," +
                       formatFloat(kept.z) + " mm: " + why);
    };
    for (int i = 0; i < 3; ++i)
        if (!(kept[i] >= kMinSpacingMm && kept[i] <= kMaxSpacingMm))
            refuse("each must lie between 0.001 and 1000 mm");
    if (double(std::max({kept.x, kept.y, kept.z})) >
        double(std::min({kept.x, kept.y, kept.z})) * kMaxSpacingRatio)
        refuse("one axis more than 1000 times another's");
}

glm::vec3 parseSpacingOption(const VolumeSpecQuery& q, const std::string& what,
                             glm::vec3 fallback) {
    if (!q.has("spacing"))
        return fallback;
    std::vector<double> s = parseNumbers(q.get("spacing"), 3, "spacing", what);
    checkSpacing(what + " (spacing=" + q.get("spacing") + ")", {s[0], s[1], s[2]});
    return {float(s[0]), float(s[1]), float(s[2])};
}

// [SECTION] Raw voxels

namespace {

std::optional<ScalarType> rawType(const std::string& t) {
    static const std::pair<const char*, ScalarType> kNames[] = {
        {"uint8", ScalarType::UInt8},     {"int8", ScalarType::Int8},
        {"int16", ScalarType::Int16},     {"uint16", ScalarType::UInt16},
        {"int32", ScalarType::Int32},     {"uint32", ScalarType::UInt32},
        {"float32", ScalarType::Float32}, {"float64", ScalarType::Float64},
        {"float", ScalarType::Float32},   {"double", ScalarType::Float64},
    };
    for (const auto& [n, type] : kNames)
        if (t == n)
            return type;
    return std::nullopt;
}

Volume loadRaw(const std::string& spec, const std::string& rest) {
    VolumeSpecQuery q = parseVolumeSpecQuery(rest, "dims,spacing,type,endian,window,offset");
    const std::string& path = q.name;
    if (path.empty())
        fail(spec, "raw: needs a file: raw:PATH?dims=X,Y,Z&type=T");
    if (!q.has("dims"))
        fail(path, "raw voxels need their dimensions: raw:" + path + "?dims=X,Y,Z");
    std::vector<std::string> d = split(q.get("dims"), ',');
    int64_t dims[3];
    if (d.size() != 3 || !parseInteger(d[0], dims[0]) || !parseInteger(d[1], dims[1]) ||
        !parseInteger(d[2], dims[2]))
        fail(spec, "bad dims='" + q.get("dims") + "': expected three integers X,Y,Z");
    checkDims(dims[0], dims[1], dims[2], path);

    DecodeSpec ds;
    if (q.has("type")) {
        std::optional<ScalarType> t = rawType(q.get("type"));
        if (!t)
            fail(spec,
                 "unknown type '" + q.get("type") +
                     "' (types: uint8, int8, int16, uint16, int32, uint32, float32, float64)");
        ds.type = *t;
    }
    std::string endian = q.has("endian") ? q.get("endian") : "little";
    if (endian != "little" && endian != "big")
        fail(spec, "bad endian='" + endian + "': expected little or big");
    ds.bigEndian = endian == "big";
    ds.window = parseWindowOption(q, spec);
    int64_t offset = 0;
    if (q.has("offset") && (!parseInteger(q.get("offset"), offset) || offset < 0))
        fail(spec, "bad offset='" + q.get("offset") + "': expected a byte count");
    glm::vec3 spacing = parseSpacingOption(q, spec, glm::vec3(1.0f));
    glm::ivec3 size{int(dims[0]), int(dims[1]), int(dims[2])};

    FileSource file(path, path);
    if (endsWith(toLower(path), ".gz")) {
        GzipSource gz(file, path);
        if (gz.skip(uint64_t(offset)) < uint64_t(offset))
            fail(path, "truncated: shorter than offset=" + std::to_string(offset));
        return decodeVoxels(gz, size, spacing, ds, true);
    }
    checkRawSize(file, uint64_t(offset), dataBytes(size, ds));
    file.seek(uint64_t(offset));
    return decodeVoxels(file, size, spacing, ds, true);
}

// skull:N?seed=S, sphere:N, box:N.
Volume loadBuiltin(const std::string& spec, const std::string& kind, const std::string& rest) {
    std::string sizeText = rest;
    std::string query;
    if (size_t mark = rest.find('?'); mark != std::string::npos) {
        sizeText = rest.substr(0, mark);
        query = rest.substr(mark);
    }
    VolumeSpecQuery q;
    if (!query.empty())
        parseOptions(q, query.substr(1), kind == "skull" ? "seed" : "", spec);
    const int lo = kind == "skull" ? 32 : 8;
    int64_t n = kind == "skull" ? 128 : 64;
    if (!sizeText.empty() && !parseInteger(sizeText, n))
        fail(spec, "bad size '" + sizeText + "': expected " + kind + ":N with N an integer");
    if (n < lo || n > 512)
        fail(spec, "size " + std::to_string(n) + " out of range: N must be " + std::to_string(lo) +
                       "..512");
    if (kind == "sphere")
        return makeSphere(int(n));
    if (kind == "box")
        return makeBox(int(n));
    int64_t seed = kDefaultSkullSeed;
    if (q.has("seed") &&
        (!parseInteger(q.get("seed"), seed) || seed < 0 || seed > int64_t(UINT32_MAX)))
        fail(spec, "bad seed='" + q.get("seed") + "': expected an integer 0.." +
                       std::to_string(UINT32_MAX));
    return makeSkull(int(n), uint32_t(seed));
}

enum class FileFormat { Unknown, Nrrd, Nifti };

FileFormat sniffFormat(const std::string& path) {
    std::string lower = toLower(path);
    if (endsWith(lower, ".nrrd") || endsWith(lower, ".nhdr"))
        return FileFormat::Nrrd;
    if (endsWith(lower, ".nii") || endsWith(lower, ".nii.gz"))
        return FileFormat::Nifti;
    // Said here: below, every gzipped file is read as NIfTI and would be "not a NIfTI-1 file".
    if (endsWith(lower, ".nrrd.gz") || endsWith(lower, ".nhdr.gz"))
        fail(path, "a gzipped NRRD file: gunzip it first (NRRD's own `encoding: gzip` is read)");
    FileSource f(path, path);
    uint8_t head[8] = {};
    size_t n = f.read(head, sizeof head);
    if (n >= 4 && std::memcmp(head, "NRRD", 4) == 0)
        return FileFormat::Nrrd;
    if (isGzipMagic(head, n))
        return FileFormat::Nifti; // a gzipped file that is not .nii.gz: NIfTI is all we gzip
    uint32_t h;
    std::memcpy(&h, head, 4);
    if (n >= 4 && (h == 348 || bswap(h) == 348))
        return FileFormat::Nifti;
    return FileFormat::Unknown;
}

} // namespace

Volume detail::readVolumeFile(const std::string& path, const std::optional<DensityWindow>& window) {
    switch (sniffFormat(path)) {
    case FileFormat::Nrrd:
        return readNrrd(path, window);
    case FileFormat::Nifti:
        return readNifti(path, window);
    case FileFormat::Unknown:
        break;
    }
    fail(path, "unknown volume format: expected .nrrd, .nhdr, .nii or .nii.gz (for raw voxels use "
               "raw:" +
                   path + "?dims=X,Y,Z&type=T)");
}

// [SECTION] loadVolume / saveVolume / help

Volume loadVolume(const std::string& spec) {
    if (spec.empty())
        throw Error("empty volume spec: try skull:128, a .nrrd/.nii file or raw:PATH?dims=X,Y,Z");
    size_t colon = spec.find(':');
    size_t mark = spec.find('?');
    std::string kind = spec.substr(0, std::min(colon, mark));
    std::string rest = colon < mark && colon != std::string::npos ? spec.substr(colon + 1)
                       : mark != std::string::npos                ? spec.substr(mark)
                                                                  : std::string();
    if (kind == "skull" || kind == "sphere" || kind == "box")
        return loadBuiltin(spec, kind, rest);
    if (kind == "raw" && colon < mark)
        return loadRaw(spec, rest);
    if (kind == "slices" && colon < mark)
        fail(spec, "reading image slices needs sim_image (openVolume in "
                   "libsim_image/volume_slices.h)");

    VolumeSpecQuery q = parseVolumeSpecQuery(spec, "window,spacing,labels,names");
    const std::string& path = q.name;
    std::error_code ec;
    fs::file_status st = fs::status(path, ec);
    if (!fs::exists(st))
        fail(path, "no such file (specs: skull:N, sphere:N, box:N, raw:PATH?dims=X,Y,Z, or a "
                   ".nrrd/.nhdr/.nii/.nii.gz file)");
    if (fs::is_directory(st))
        fail(path, "is a folder: reading image slices needs sim_image (openVolume in "
                   "libsim_image/volume_slices.h)");
    std::optional<DensityWindow> window = parseWindowOption(q, spec);
    Volume v = readVolumeFile(path, window);
    v.setSpacing(parseSpacingOption(q, spec, v.spacing()));
    if (q.has("names") && !q.has("labels"))
        fail(spec, "names=FILE names the labels of a label map: give labels=FILE too");
    if (q.has("labels")) {
        // Relative to the scan's folder, as a NRRD's detached data file is to its header.
        const fs::path folder = fs::path(path).parent_path();
        auto beside = [&](const std::string& p) {
            return p.empty() || fs::path(p).is_absolute() ? p : (folder / p).string();
        };
        applyLabelMap(v, beside(q.get("labels")), beside(q.get("names")), spec);
    }
    return v;
}

namespace detail {

std::string detachedDataPath(const std::string& path, bool compress) {
    return path.substr(0, path.size() - 5) + (compress ? ".raw.gz" : ".raw");
}

} // namespace detail

namespace {

// A detached data file is replaced only when it is this header's own (an earlier save of the same
// .nhdr): OUT.raw beside a new OUT.nhdr may be someone's scan, even the one being converted
// (`volume convert 'raw:scan.raw?...' scan.nhdr`).
void checkDetachedData(const std::string& path, bool compress) {
    const std::string dataPath = detachedDataPath(path, compress);
    std::error_code ec;
    if (!fs::exists(dataPath, ec))
        return;
    bool ours = false;
    if (std::FILE* f = std::fopen(path.c_str(), "rb")) {
        std::string head(4096, '\0');
        head.resize(std::fread(head.data(), 1, head.size(), f));
        std::fclose(f);
        ours = head.rfind("NRRD", 0) == 0 &&
               head.find("\ndata file: " + fs::path(dataPath).filename().string() + "\n") !=
                   std::string::npos;
    }
    if (!ours)
        fail(dataPath, "exists and is not " + fs::path(path).filename().string() +
                           "'s data: not overwritten (remove it or save under another name)");
}

} // namespace

void checkSaveTarget(const std::string& path, const SaveOptions& options) {
    const std::string lower = toLower(path);
    if (!(endsWith(lower, ".nrrd") || endsWith(lower, ".nhdr") || endsWith(lower, ".nii") ||
          endsWith(lower, ".nii.gz")))
        fail(path, "unknown output format: use .nrrd, .nhdr, .nii or .nii.gz");
    if (endsWith(lower, ".nhdr"))
        checkDetachedData(path, options.compress);
    FileSink probe(path); // the folder takes a new file; removed again, `path` untouched
}

bool savesMaterials(const std::string& path) {
    const std::string lower = toLower(path);
    return endsWith(lower, ".nrrd") || endsWith(lower, ".nhdr");
}

void saveVolume(const Volume& volume, const std::string& path, const SaveOptions& options) {
    if (volume.empty())
        fail(path, "cannot save an empty volume");
    std::string lower = toLower(path);
    if (endsWith(lower, ".nhdr"))
        checkDetachedData(path, options.compress);
    if (endsWith(lower, ".nrrd") || endsWith(lower, ".nhdr"))
        writeNrrd(volume, path, options.compress);
    else if (endsWith(lower, ".nii.gz"))
        writeNifti(volume, path, true);
    else if (endsWith(lower, ".nii"))
        writeNifti(volume, path, false);
    else
        fail(path, "unknown output format: use .nrrd, .nhdr, .nii or .nii.gz");
}

std::string volumeSpecHelp() {
    return R"(A volume SPEC is one of:
  skull[:N][?seed=S]   procedural skull, N^3 voxels, N 32..512 (default 128), seed default 1
  sphere[:N]           solid cortical sphere, N^3 voxels of 1 mm, N 8..512 (default 64)
  box[:N]              solid cortical box filling the middle half, N 8..512 (default 64)
  FILE[?window=lo,hi&spacing=a,b,c&labels=SEG&names=TABLE]
                       .nrrd/.nhdr (raw or gzip) or NIfTI-1 .nii/.nii.gz; SEG a label map
                       naming dura, sinus, artery, brain (3D Slicer segment names or TABLE)
  raw:FILE?dims=X,Y,Z[&type=T&endian=little|big&spacing=a,b,c&offset=BYTES&window=lo,hi]
                       headerless voxels, x fastest; T: uint8 (default), int8, int16, uint16,
                       int32, uint32, float32, float64; FILE may end in .gz
  FOLDER or slices:FOLDER[?spacing=a,b,c&window=lo,hi]
                       2D image slices (PNG, TIFF, ...) in natural filename order
Spacing is in mm per voxel. Scalars other than uint8 map to density through the window
(default -300..900, Hounsfield units: 300 HU is the bone surface); uint8 passes through.
Materials: density >= 234 cortical, >= 128 diploe, else air (our NRRD keeps its own labels,
a label map adds the structures).
See docs/volumes.md.)";
}

} // namespace trephine

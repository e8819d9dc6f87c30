// Folders of 2D image slices through OpenImageIO, and openVolume on top of the core's loadVolume.
#include "libsim_image/volume_slices.h"

#include "image_limits.h"
#include "libsim/error.h"
#include "quiet_stderr.h"

#include <OpenImageIO/imageio.h>

#include <algorithm>
#include <cctype>
#include <cstring>
#include <filesystem>
#include <set>
#include <vector>

namespace trephine {

namespace fs = std::filesystem;
using detail::plausibleImageBytes;

namespace {

[[noreturn]] void fail(const std::string& name, const std::string& problem) {
    throw Error(name + ": " + problem);
}

// OpenImageIO's messages can span lines; ours are one line.
std::string firstLine(std::string s) {
    s = s.substr(0, s.find('\n'));
    return s.empty() ? "unreadable image" : s;
}

// "slice2.png" before "slice10.png": digit runs compare as numbers.
bool naturalLess(const std::string& a, const std::string& b) {
    size_t i = 0, j = 0;
    while (i < a.size() && j < b.size()) {
        if (std::isdigit(static_cast<unsigned char>(a[i])) &&
            std::isdigit(static_cast<unsigned char>(b[j]))) {
            size_t i0 = i, j0 = j;
            while (i < a.size() && std::isdigit(static_cast<unsigned char>(a[i])))
                ++i;
            while (j < b.size() && std::isdigit(static_cast<unsigned char>(b[j])))
                ++j;
            std::string_view da(a.data() + i0, i - i0), db(b.data() + j0, j - j0);
            size_t za = std::min(da.find_first_not_of('0'), da.size() - 1);
            size_t zb = std::min(db.find_first_not_of('0'), db.size() - 1);
            std::string_view na = da.substr(za), nb = db.substr(zb);
            if (na.size() != nb.size())
                return na.size() < nb.size();
            if (na != nb)
                return na < nb;
            if (da.size() != db.size())
                return da.size() < db.size();
            continue;
        }
        if (a[i] != b[j])
            return a[i] < b[j];
        ++i;
        ++j;
    }
    return a.size() - i < b.size() - j;
}

template <typename T>
double load(const uint8_t* p) {
    T v;
    std::memcpy(&v, p, sizeof v);
    return double(v);
}

std::set<std::string> imageExtensions() {
    std::set<std::string> out;
    for (const auto& [format, exts] : OIIO::get_extension_map())
        for (const std::string& e : exts)
            out.insert(e);
    return out;
}

std::string lower(std::string s) {
    for (char& c : s)
        c = char(std::tolower(static_cast<unsigned char>(c)));
    return s;
}

} // namespace

Volume loadVolumeSlices(const std::string& folder, glm::vec3 spacingMm,
                        const std::optional<DensityWindow>& window) {
    std::error_code ec;
    if (!fs::is_directory(folder, ec))
        fail(folder, fs::exists(folder, ec) ? "not a folder of image slices" : "no such folder");
    const std::set<std::string> known = imageExtensions();
    std::vector<std::string> names;
    // The listing's errors apart from each entry's: a dangling link (is_regular_file sets ENOENT
    // and leaves it set) listed last must not fail the whole folder as "cannot list folder".
    fs::directory_iterator it(folder, ec);
    for (; !ec && it != fs::directory_iterator(); it.increment(ec)) {
        const fs::directory_entry& e = *it;
        std::string name = e.path().filename().string();
        std::string ext = lower(e.path().extension().string());
        std::error_code entryEc;
        if (name.empty() || name[0] == '.' || !e.is_regular_file(entryEc) || ext.size() < 2)
            continue;
        if (known.count(ext.substr(1)))
            names.push_back(name);
    }
    if (ec)
        fail(folder, "cannot list folder: " + ec.message());
    if (names.empty())
        fail(folder, "no image slices found (expected files such as PNG or TIFF)");
    std::sort(names.begin(), names.end(), naturalLess);

    // The voxels grow slice by slice as slices are read, by doubling capped at the volume, and
    // become the Volume without a copy: a folder whose first slice is honest and the rest are not
    // costs what was read, not the whole volume (2 GiB for a 1024^2 slice and 1023 broken files).
    std::vector<uint8_t> densities, materials;
    size_t total = 0;
    int width = 0, height = 0;
    OIIO::TypeDesc::BASETYPE baseType = OIIO::TypeDesc::UNKNOWN;
    std::string firstName;
    std::vector<uint8_t> bytes;
    const QuietStderr quiet; // our own line says what libpng would (restored before it is said)
    for (size_t z = 0; z < names.size(); ++z) {
        const std::string path = (fs::path(folder) / names[z]).string();
        auto in = OIIO::ImageInput::open(path);
        if (!in)
            fail(path, "cannot read image: " + firstLine(OIIO::geterror()));
        const OIIO::ImageSpec& spec = in->spec();
        // Before anything is allocated for it (by us or by OpenImageIO): a 109-byte PNG may claim
        // 32768 x 32768 pixels, 2.2 GB (4.3 GB as RGBA16) before the read would fail.
        std::error_code sizeError;
        const uint64_t fileBytes = fs::file_size(path, sizeError);
        const uint64_t claimed = spec.image_bytes(true);
        if (!sizeError && !plausibleImageBytes(claimed, fileBytes))
            fail(path, "the header claims " + std::to_string(spec.width) + "x" +
                           std::to_string(spec.height) + " pixels of " +
                           std::to_string(spec.nchannels) + " channels (" +
                           std::to_string(claimed) + " bytes) but the file holds only " +
                           std::to_string(fileBytes) + " bytes: a corrupt image");
        if (spec.depth > 1)
            fail(path, "is a 3-D image; slices must be 2-D");
        auto type = OIIO::TypeDesc::BASETYPE(spec.format.basetype);
        if (z == 0) {
            width = spec.width;
            height = spec.height;
            baseType = type;
            firstName = names[z];
            if (width <= 0 || height <= 0)
                fail(path, "image has no pixels");
            if (uint64_t(width) * uint64_t(height) * names.size() > kMaxVolumeVoxels)
                fail(folder, std::to_string(width) + "x" + std::to_string(height) + "x" +
                                 std::to_string(names.size()) +
                                 " voxels are too many: at most 1024^3 are accepted");
            total = size_t(width) * size_t(height) * names.size();
        } else if (spec.width != width || spec.height != height) {
            fail(path, "slice is " + std::to_string(spec.width) + "x" +
                           std::to_string(spec.height) + " but " + firstName + " is " +
                           std::to_string(width) + "x" + std::to_string(height) +
                           ": all slices must be the same size");
        } else if (type != baseType) {
            fail(path, "slice pixel type " + std::string(spec.format.c_str()) + " differs from " +
                           firstName + "'s: all slices must share a pixel type");
        }
        const size_t n = size_t(width) * size_t(height);
        if ((z + 1) * n > densities.capacity()) {
            const size_t want = std::min(total, std::max((z + 1) * n, 2 * densities.size()));
            densities.reserve(want);
            materials.reserve(want);
        }
        densities.resize((z + 1) * n);
        materials.resize((z + 1) * n);
        uint8_t* density = densities.data() + z * n;
        const bool passThrough = type == OIIO::TypeDesc::UINT8 && !window;
        bool ok;
        if (passThrough) {
            ok = in->read_image(0, 0, 0, 1, OIIO::TypeDesc::UINT8, density);
        } else {
            // Integers are read as their own type so 16-bit values stay raw numbers (a float read
            // would normalise them to 0..1), then widened.
            OIIO::TypeDesc readType = type == OIIO::TypeDesc::HALF ||
                                              type == OIIO::TypeDesc::FLOAT ||
                                              type == OIIO::TypeDesc::DOUBLE
                                          ? OIIO::TypeDesc::FLOAT
                                          : OIIO::TypeDesc(type);
            bytes.resize(n * readType.size());
            ok = in->read_image(0, 0, 0, 1, readType, bytes.data());
            if (ok) {
                const DensityWindow w = window.value_or(kDefaultWindow);
                for (size_t i = 0; i < n; ++i) {
                    double v = 0.0;
                    const uint8_t* p = bytes.data() + i * readType.size();
                    switch (readType.basetype) {
                    case OIIO::TypeDesc::UINT8:
                        v = *p;
                        break;
                    case OIIO::TypeDesc::INT8:
                        v = int8_t(*p);
                        break;
                    case OIIO::TypeDesc::UINT16:
                        v = load<uint16_t>(p);
                        break;
                    case OIIO::TypeDesc::INT16:
                        v = load<int16_t>(p);
                        break;
                    case OIIO::TypeDesc::UINT32:
                        v = load<uint32_t>(p);
                        break;
                    case OIIO::TypeDesc::INT32:
                        v = load<int32_t>(p);
                        break;
                    case OIIO::TypeDesc::FLOAT:
                        v = load<float>(p);
                        break;
                    default:
                        fail(path, "unsupported pixel type " + std::string(spec.format.c_str()));
                    }
                    density[i] = windowDensity(v, w);
                }
            }
        }
        if (!ok)
            fail(path, "cannot read image: " + firstLine(in->geterror()));
        uint8_t* material = materials.data() + z * n;
        for (size_t i = 0; i < n; ++i)
            material[i] = uint8_t(materialFromDensity(density[i]));
    }
    return Volume({width, height, int(names.size())}, spacingMm, std::move(densities),
                  std::move(materials));
}

Volume openVolume(const std::string& spec) {
    std::string rest;
    std::error_code ec;
    if (spec.rfind("slices:", 0) == 0) {
        rest = spec.substr(7);
    } else {
        size_t mark = spec.rfind('?');
        std::string name = fs::exists(spec, ec) ? spec : spec.substr(0, mark);
        if (spec.empty() || !fs::is_directory(name, ec))
            return loadVolume(spec);
        rest = spec;
    }
    VolumeSpecQuery q = parseVolumeSpecQuery(rest, "spacing,window");
    if (q.name.empty())
        fail(spec, "slices: needs a folder: slices:FOLDER[?spacing=a,b,c]");
    return loadVolumeSlices(q.name, parseSpacingOption(q, spec, glm::vec3(1.0f)),
                            parseWindowOption(q, spec));
}

void saveVolumeSlices(const Volume& volume, const std::string& folder,
                      const std::string& extension) {
    if (volume.empty())
        fail(folder, "cannot save an empty volume");
    std::error_code ec;
    // Into a new or empty folder only: slices already there would be read back with ours (a
    // folder holds one volume), and converting a slice folder onto itself overwrote the original.
    if (fs::exists(folder, ec) && !fs::is_empty(folder, ec))
        fail(folder, "the folder is not empty: save slices into a new or empty folder");
    fs::create_directories(folder, ec);
    if (ec)
        fail(folder, "cannot create folder: " + ec.message());
    const glm::ivec3 d = volume.dims();
    const int digits = std::max(4, int(std::to_string(d.z - 1).size()));
    for (int z = 0; z < d.z; ++z) {
        std::string index = std::to_string(z);
        index.insert(0, size_t(digits) - index.size(), '0');
        const std::string path = (fs::path(folder) / ("slice_" + index + "." + extension)).string();
        auto out = OIIO::ImageOutput::create(path);
        if (!out)
            fail(path, "cannot write image: " + firstLine(OIIO::geterror()));
        OIIO::ImageSpec spec(d.x, d.y, 1, OIIO::TypeDesc::UINT8);
        const uint8_t* data = volume.densityData() + size_t(z) * size_t(d.x) * size_t(d.y);
        if (!out->open(path, spec) || !out->write_image(OIIO::TypeDesc::UINT8, data) ||
            !out->close())
            fail(path, "cannot write image: " + firstLine(out->geterror()));
    }
}

} // namespace trephine

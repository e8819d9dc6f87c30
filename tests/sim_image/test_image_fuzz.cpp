// Hostile and truncated image files against the readers of sim_image: folders of 2D slices (PNG,
// TIFF, through OpenImageIO) and DBI files (OpenEXR). Small valid files are mutated (truncated,
// bits flipped, bytes inserted and deleted, size fields set to huge, zero and negative values) and
// must either be refused with one line of trephine::Error or load as something sane: never a
// crash, undefined behaviour (run it under -fsanitize=address,undefined) or an allocation far
// beyond what the file holds. The seeds are fixed and the counts bounded; TREPHINE_FUZZ_SCALE=N
// runs N times as many mutations for a long run.
#include "libsim/error.h"
#include "libsim_image/dbi_io.h"
#include "libsim_image/volume_slices.h"

#include <gtest/gtest.h>

#include <OpenImageIO/imageio.h>

#include <algorithm>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <new>
#include <random>
#include <string>
#include <unistd.h>
#include <vector>

namespace fs = std::filesystem;
using namespace trephine;

// [SECTION] allocation probe

// The largest single allocation this thread makes while a probe is alive. Every operator new of
// the test binary goes through here; it only forwards to malloc unless a probe watches.
namespace {
thread_local bool t_probing = false;
thread_local size_t t_largestAllocation = 0;

struct AllocationProbe {
    AllocationProbe() { t_probing = true, t_largestAllocation = 0; }
    ~AllocationProbe() { t_probing = false; }
    size_t largest() const { return t_largestAllocation; }
};
} // namespace

// GCC sees free() on what operator new returned and warns; here they are one malloc and free.
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic ignored "-Wmismatched-new-delete"
#endif
void* operator new(size_t n) {
    if (t_probing)
        t_largestAllocation = std::max(t_largestAllocation, n);
    if (void* p = std::malloc(n ? n : 1))
        return p;
    throw std::bad_alloc();
}
void operator delete(void* p) noexcept {
    std::free(p);
}
void operator delete(void* p, size_t) noexcept {
    std::free(p);
}

namespace {

using Bytes = std::vector<uint8_t>;

// [SECTION] mutations

int fuzzScale() {
    const char* s = std::getenv("TREPHINE_FUZZ_SCALE");
    const int n = s ? std::atoi(s) : 1;
    return std::max(n, 1);
}

constexpr uint64_t kSpecialValues[] = {0,          1,          0x7f,       0x80,
                                       0xff,       0x7fff,     0x8000,     0xffff,
                                       0x7fffffff, 0x80000000, 0xffffffff, ~uint64_t(0)};

void writeLittleEndian(Bytes& b, size_t at, uint64_t v, size_t width) {
    for (size_t i = 0; i < width && at + i < b.size(); ++i)
        b[at + i] = uint8_t(v >> (8 * i));
}

void writeBigEndian(Bytes& b, size_t at, uint64_t v, size_t width) {
    for (size_t i = 0; i < width && at + i < b.size(); ++i)
        b[at + i] = uint8_t(v >> (8 * (width - 1 - i)));
}

// Deterministic edits of a byte string (std::mt19937 is the same sequence everywhere; the
// distributions are not, so draws use plain modulo).
class Mutator {
public:
    explicit Mutator(uint32_t seed) : m_rng(seed) {}

    uint32_t below(uint32_t n) { return n ? uint32_t(m_rng() % n) : 0; }

    Bytes mutate(Bytes b) {
        const uint32_t edits = 1 + below(3);
        for (uint32_t e = 0; e < edits; ++e) {
            const size_t at = below(uint32_t(b.size()));
            switch (below(7)) {
            case 0: // flip a bit
                if (!b.empty())
                    b[at] ^= uint8_t(1u << below(8));
                break;
            case 1: // a random byte
                if (!b.empty())
                    b[at] = uint8_t(m_rng());
                break;
            case 2: // a hostile value in a field of 1, 2, 4 or 8 bytes, either byte order
                if (below(2))
                    writeLittleEndian(b, at, kSpecialValues[below(std::size(kSpecialValues))],
                                      size_t(1) << below(4));
                else
                    writeBigEndian(b, at, kSpecialValues[below(std::size(kSpecialValues))],
                                   size_t(1) << below(4));
                break;
            case 3: // truncated
                b.resize(below(uint32_t(b.size()) + 1));
                break;
            case 4: { // bytes inserted
                const size_t n = 1 + below(8);
                Bytes ins(n);
                for (uint8_t& v : ins)
                    v = uint8_t(m_rng());
                b.insert(b.begin() + std::ptrdiff_t(at), ins.begin(), ins.end());
                break;
            }
            case 5: // bytes deleted
                b.erase(b.begin() + std::ptrdiff_t(at),
                        b.begin() + std::ptrdiff_t(std::min(b.size(), at + 1 + below(8))));
                break;
            default: // appended junk
                b.push_back(uint8_t(m_rng()));
                break;
            }
        }
        return b;
    }

private:
    std::mt19937 m_rng;
};

// [SECTION] files

// A fresh folder, removed with everything in it on destruction: in memory (/dev/shm) unless TMPDIR
// says otherwise, since many small files written to a disk-backed /tmp take seconds.
struct FuzzDir {
    fs::path path;
    FuzzDir() {
        static int counter = 0;
        std::error_code ec;
        fs::path base = fs::temp_directory_path();
        if (!std::getenv("TMPDIR") && fs::is_directory("/dev/shm", ec) &&
            ::access("/dev/shm", W_OK) == 0)
            base = "/dev/shm";
        path = base / ("trephine_image_fuzz_" + std::to_string(::getpid()) + "_" +
                       std::to_string(counter++));
        fs::remove_all(path, ec);
        fs::create_directories(path);
    }
    ~FuzzDir() {
        std::error_code ec;
        fs::remove_all(path, ec);
    }
    FuzzDir(const FuzzDir&) = delete;
    FuzzDir& operator=(const FuzzDir&) = delete;
    std::string operator/(const std::string& name) const { return (path / name).string(); }
};

// Replaces the file by a new one (truncating in place makes ext4 flush it on close).
void writeFile(const std::string& path, const Bytes& data) {
    std::error_code ec;
    fs::remove(path, ec);
    std::ofstream f(path, std::ios::binary);
    f.write(reinterpret_cast<const char*>(data.data()), std::streamsize(data.size()));
}

Bytes readFile(const std::string& path) {
    std::ifstream f(path, std::ios::binary);
    return Bytes(std::istreambuf_iterator<char>(f), {});
}

template <typename T>
void writeImage(const std::string& path, int w, int h, int channels, OIIO::TypeDesc type) {
    std::vector<T> pixels(size_t(w) * size_t(h) * size_t(channels));
    for (size_t i = 0; i < pixels.size(); ++i)
        pixels[i] = T((i * 37) % 200);
    auto out = OIIO::ImageOutput::create(path);
    ASSERT_TRUE(out) << OIIO::geterror();
    OIIO::ImageSpec spec(w, h, channels, type);
    ASSERT_TRUE(out->open(path, spec)) << out->geterror();
    ASSERT_TRUE(out->write_image(type, pixels.data())) << out->geterror();
    ASSERT_TRUE(out->close());
}

// [SECTION] the checks

struct Tally {
    int loaded = 0;
    int refused = 0;
};

// OpenImageIO's read_image reads through a buffer of 64 MiB, whatever the image's size.
constexpr size_t kOiioChunkBytes = size_t(64) << 20;

// Beyond OpenImageIO's chunk buffer, what deflate (1032:1) on 1-bit pixels unpacked to bytes can
// honestly hold. OpenImageIO's buffer grows with the width of a row, whatever the height: over
// three chunks (201 MB) for an EXR of 65536-pixel rows and 5 rows.
size_t allocationBound(size_t fileBytes) {
    return 4 * kOiioChunkBytes + 8256 * fileBytes;
}

template <typename F>
void expectRefusedOrSane(const std::string& what, size_t fileBytes, Tally& tally, F&& load) {
    AllocationProbe probe;
    try {
        load();
        t_probing = false;
        ++tally.loaded;
    } catch (const Error& e) {
        t_probing = false;
        ++tally.refused;
        const std::string msg = e.what();
        EXPECT_FALSE(msg.empty()) << what;
        EXPECT_EQ(msg.find('\n'), std::string::npos) << what << ": not one line: " << msg;
    } catch (const std::exception& e) {
        t_probing = false;
        ADD_FAILURE() << what << ": threw " << typeid(e).name() << " (" << e.what()
                      << ") instead of trephine::Error";
    }
    EXPECT_LE(probe.largest(), allocationBound(fileBytes))
        << what << ": allocated " << probe.largest() << " bytes for a file of " << fileBytes;
}

void expectSaneVolume(const Volume& v, const std::string& what) {
    const glm::ivec3 d = v.dims();
    ASSERT_TRUE(d.x > 0 && d.y > 0 && d.z > 0) << what;
    ASSERT_LE(v.voxelCount(), kMaxVolumeVoxels) << what;
    for (size_t i = 0; i < v.voxelCount(); ++i)
        ASSERT_LT(v.materialData()[i], kMaterialCount) << what << " voxel " << i;
}

// Every truncation in a long run (by default ever sparser), `random` mutations.
template <typename F>
void forEachMutation(const Bytes& valid, uint32_t seed, int random, F&& f) {
    const bool every = fuzzScale() > 1;
    for (size_t len = 0; len < valid.size(); len += every ? 1 : 1 + len / 16)
        f(Bytes(valid.begin(), valid.begin() + std::ptrdiff_t(len)));
    Mutator m(seed);
    for (int i = 0; i < random; ++i)
        f(m.mutate(valid));
}

} // namespace

// [SECTION] slices

TEST(ImageFuzz, SliceFoldersRefuseMutatedImagesOrLoadSanely) {
    FuzzDir dir;
    const int random = 40 * fuzzScale();
    Tally tally;
    struct Case {
        const char* name;
        std::function<void(const std::string&)> write;
    };
    const Case cases[] = {
        {"a.png",
         [](const std::string& p) { writeImage<uint8_t>(p, 6, 5, 1, OIIO::TypeDesc::UINT8); }},
        {"b.png",
         [](const std::string& p) { writeImage<uint16_t>(p, 6, 5, 2, OIIO::TypeDesc::UINT16); }},
        {"c.tif",
         [](const std::string& p) { writeImage<float>(p, 6, 5, 1, OIIO::TypeDesc::FLOAT); }},
        {"d.tif",
         [](const std::string& p) { writeImage<int16_t>(p, 6, 5, 1, OIIO::TypeDesc::INT16); }},
    };
    uint32_t seed = 1;
    for (const Case& c : cases) {
        SCOPED_TRACE(c.name);
        const std::string folder = dir / (std::string("slices_") + c.name);
        fs::create_directories(folder);
        // Two good slices and the one being mutated between them.
        c.write(folder + "/s1_" + c.name);
        c.write(folder + "/s3_" + c.name);
        const std::string target = folder + "/s2_" + c.name;
        c.write(target);
        const Bytes valid = readFile(target);
        EXPECT_NO_THROW(expectSaneVolume(loadVolumeSlices(folder, glm::vec3(1.0f)), folder));
        forEachMutation(valid, seed++, random, [&](const Bytes& b) {
            writeFile(target, b);
            expectRefusedOrSane(target, 3 * valid.size() + b.size(), tally, [&] {
                expectSaneVolume(loadVolumeSlices(folder, glm::vec3(1.0f)), target);
            });
        });
    }
    EXPECT_GT(tally.loaded, 0);
    EXPECT_GT(tally.refused, 0);
}

// [SECTION] DBI

TEST(ImageFuzz, DbiFilesRefuseMutationsOrLoadSanely) {
    FuzzDir dir;
    const int random = 150 * fuzzScale();
    Tally tally;
    Dbi d(7, 5);
    for (int y = 0; y < 5; ++y)
        for (int x = 0; x < 7; ++x) {
            uint8_t* c = d.color(x, y);
            c[0] = uint8_t(x * 30), c[1] = uint8_t(y * 40), c[2] = 7, c[3] = 255;
            d.depth()[d.index(x, y)] = float(x + y) / 20.0f;
        }
    const std::string path = dir / "f.exr";
    writeDbiExr(path, d, PixelRect{3, 2, 7, 5}, 20, 10);
    const Bytes valid = readFile(path);
    auto check = [&](const Bytes& b) {
        writeFile(path, b);
        expectRefusedOrSane(path, b.size(), tally, [&] {
            DbiFile f = readDbiExr(path);
            ASSERT_GT(f.image.width(), 0);
            ASSERT_GT(f.image.height(), 0);
        });
    };
    forEachMutation(valid, 7, random, check);
    // The data and display windows (box2i, four int32) set to hostile values.
    for (const char* attribute : {"dataWindow", "displayWindow"}) {
        const std::string key = std::string(attribute) + std::string("\0box2i\0", 7);
        auto at = std::search(valid.begin(), valid.end(), key.begin(), key.end());
        ASSERT_NE(at, valid.end()) << attribute;
        const size_t box = size_t(at - valid.begin()) + key.size() + 4;
        const int32_t values[] = {INT32_MIN, INT32_MIN + 1, -65536, -1, 0, 1, 65535, INT32_MAX};
        for (size_t field = 0; field < 4; ++field)
            for (int32_t v : values) {
                Bytes b = valid;
                writeLittleEndian(b, box + 4 * field, uint32_t(v), 4);
                check(b);
            }
        for (int32_t v : values) { // a box from (0, 0) to (v, v)
            Bytes b = valid;
            writeLittleEndian(b, box, 0, 8);
            writeLittleEndian(b, box + 8, uint32_t(v), 4);
            writeLittleEndian(b, box + 12, uint32_t(v), 4);
            check(b);
        }
    }
    EXPECT_GT(tally.loaded, 0);
    EXPECT_GT(tally.refused, 0);
}

// [SECTION] defects the fuzzing found

// Runs f expecting a one-line Error containing `problem`; returns the largest allocation.
template <typename F>
size_t expectRefused(F&& f, const std::string& problem) {
    AllocationProbe probe;
    try {
        f();
        ADD_FAILURE() << "no Error; expected one saying '" << problem << "'";
    } catch (const Error& e) {
        const std::string msg = e.what();
        EXPECT_NE(msg.find(problem), std::string::npos) << msg;
        EXPECT_EQ(msg.find('\n'), std::string::npos) << msg;
    }
    return probe.largest();
}

TEST(ImageFuzz, ASliceFolderAllocatesOnlyWhatItsSlicesHold) {
    // The whole volume was allocated from the first slice's size times the number of files:
    // an honest 1024 x 1024 slice among 1023 broken files cost 2 GiB before the first of them
    // failed.
    FuzzDir dir;
    const std::string folder = dir / "slices";
    fs::create_directories(folder);
    writeImage<uint8_t>(folder + "/s0000.png", 1024, 1024, 1, OIIO::TypeDesc::UINT8);
    for (int z = 1; z < 1024; ++z)
        writeFile(folder + "/s" + std::to_string(10000 + z).substr(1) + ".png", {});
    // OpenImageIO's read_image takes 64 MiB for its chunk buffer, whatever the image.
    EXPECT_LE(expectRefused([&] { loadVolumeSlices(folder, glm::vec3(1.0f)); }, "s0001.png"),
              kOiioChunkBytes);
}

// The CRC-32 of PNG chunks (and zlib).
uint32_t crc32Of(const uint8_t* p, size_t n) {
    uint32_t c = 0xffffffffu;
    for (size_t i = 0; i < n; ++i) {
        c ^= p[i];
        for (int k = 0; k < 8; ++k)
            c = (c >> 1) ^ (0xedb88320u & (0u - (c & 1u)));
    }
    return ~c;
}

// A valid PNG whose IHDR claims width x height (with a matching CRC).
Bytes pngClaiming(const std::string& path, uint32_t width, uint32_t height, int channels,
                  OIIO::TypeDesc type) {
    if (type == OIIO::TypeDesc::UINT16)
        writeImage<uint16_t>(path, 8, 8, channels, type);
    else
        writeImage<uint8_t>(path, 8, 8, channels, type);
    std::ifstream f(path, std::ios::binary);
    Bytes b{std::istreambuf_iterator<char>(f), {}};
    EXPECT_EQ(std::string(b.begin() + 12, b.begin() + 16), "IHDR");
    writeBigEndian(b, 16, width, 4);
    writeBigEndian(b, 20, height, 4);
    writeBigEndian(b, 29, crc32Of(b.data() + 12, 17), 4);
    return b;
}

TEST(ImageFuzz, ASliceClaimingMorePixelsThanItsFileCanHoldIsRefusedBeforeReading) {
    // A 109-byte PNG claiming 32768 x 32768 pixels cost 2.2 GB (an RGBA16 one 4.3 GB and 14 s)
    // before the read failed: the volume, our read buffer and OpenImageIO's each took the claim.
    FuzzDir dir;
    for (auto [channels, type] :
         {std::pair{1, OIIO::TypeDesc::UINT8}, std::pair{4, OIIO::TypeDesc::UINT16}}) {
        const std::string folder = dir / (channels == 1 ? "gray8" : "rgba16");
        fs::create_directories(folder);
        const Bytes png = pngClaiming(folder + "/s0.png", 32768, 32768, channels, type);
        writeFile(folder + "/s0.png", png);
        EXPECT_LT(expectRefused([&] { loadVolumeSlices(folder, glm::vec3(1.0f)); },
                                "the header claims 32768x32768 pixels of " +
                                    std::to_string(channels) + " channels"),
                  size_t(1) << 20);
    }
    // An honest blank slice of 4096 x 4096 compresses far less than that.
    const std::string folder = dir / "honest";
    fs::create_directories(folder);
    auto out = OIIO::ImageOutput::create(folder + "/s0.png");
    ASSERT_TRUE(out);
    const std::vector<uint8_t> blank(size_t(4096) * 4096, 0);
    ASSERT_TRUE(
        out->open(folder + "/s0.png", OIIO::ImageSpec(4096, 4096, 1, OIIO::TypeDesc::UINT8)));
    ASSERT_TRUE(out->write_image(OIIO::TypeDesc::UINT8, blank.data()));
    ASSERT_TRUE(out->close());
    EXPECT_EQ(loadVolumeSlices(folder, glm::vec3(1.0f)).dims(), glm::ivec3(4096, 4096, 1));
}

// A DBI file with the value of its attribute `name` claiming `size` bytes.
Bytes exrWithAttributeSize(const std::string& path, const std::string& name, int32_t size) {
    writeDbiExr(path, Dbi(4, 3));
    std::ifstream f(path, std::ios::binary);
    Bytes b{std::istreambuf_iterator<char>(f), {}};
    const std::string key = name + '\0';
    auto at = std::search(b.begin() + 8, b.end(), key.begin(), key.end());
    EXPECT_NE(at, b.end()) << name;
    auto type = std::find(at + std::ptrdiff_t(key.size()), b.end(), '\0');
    writeLittleEndian(b, size_t(type - b.begin()) + 1, uint32_t(size), 4);
    return b;
}

TEST(ImageFuzz, ADbiWhoseHeaderAttributesClaimMoreThanTheFileIsRefusedBeforeOpenExrReadsThem) {
    // OpenEXR allocates an attribute's declared size before reading its value: a 597-byte DBI
    // whose 'Software' string claimed 2 GiB allocated 2 GiB before failing.
    FuzzDir dir;
    const std::string path = dir / "f.exr";
    for (const char* name : {"Software", "dataWindow", "channels"}) {
        SCOPED_TRACE(name);
        writeFile(path, exrWithAttributeSize(path, name, 0x7f000000));
        EXPECT_LT(expectRefused([&] { readDbiExr(path); },
                                std::string("attribute '") + name + "' claims 2130706432 bytes"),
                  size_t(1) << 20);
        writeFile(path, exrWithAttributeSize(path, name, -1));
        expectRefused([&] { readDbiExr(path); }, "f.exr");
    }
}

TEST(ImageFuzz, ADbiWhoseFixedSizeAttributesHaveAnotherSizeIsRefused) {
    // OpenEXR reads a 'compression' value as 1 byte whatever its declared size and parses the
    // bytes after it as the next attribute: a declared size of 129 hid, from the check of sizes
    // against the file, an attribute claiming 1.7 GB (found by the DBI fuzzing above). Here
    // OpenEXR allocated 64 MiB before failing.
    FuzzDir dir;
    const std::string path = dir / "f.exr";
    Bytes b = exrWithAttributeSize(path, "compression", 129);
    const std::string key = "dataWindow";
    auto at = std::search(b.begin(), b.end(), key.begin(), key.end());
    ASSERT_NE(at, b.end());
    // The attribute after it (read by OpenEXR, skipped by a reader trusting the size) claims 1.7
    // GB.
    const size_t after = size_t(at - b.begin()) + key.size() + 1 + 6;
    writeLittleEndian(b, after, 0x69696969, 4);
    writeFile(path, b);
    EXPECT_LT(
        expectRefused([&] { readDbiExr(path); },
                      "attribute 'compression' of type compression has 129 bytes, expected 1"),
        size_t(1) << 20);
}

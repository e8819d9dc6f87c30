// Hostile and truncated volume files against every reader of the core: NRRD (attached and detached,
// raw and gzip, our layout and scalars), NIfTI-1 (.nii, .nii.gz, either byte order), raw: specs
// and files sniffed by content. Small valid files of each kind are mutated (truncated at every
// length, bits flipped, bytes inserted and deleted, header fields set to hostile values: huge,
// zero, negative and overflowing sizes, unknown types and encodings, NaN, infinite, zero and
// negative spacings, offsets past the end, NaN and infinite voxels) and must either be refused
// with one line of trephine::Error or load as a sane volume: never a crash, a hang, undefined
// behaviour (run it under -fsanitize=address,undefined) or an allocation far beyond what the file
// holds. The seeds are fixed and the counts bounded; TREPHINE_FUZZ_SCALE=N runs N times as many
// mutations for a long run.
#include "libsim/error.h"
#include "libsim/volume_io.h"

#include <gtest/gtest.h>

#include "byte_files.h"

#include "fuzz.h"

#include <algorithm>
#include <cmath>
#include <csignal>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <new>
#include <random>
#include <string>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>
#include <vector>
#include <zlib.h>

namespace fs = std::filesystem;
using namespace trephine;

// [SECTION] allocation probe

TREPHINE_FUZZ_ALLOCATION_PROBE()

namespace {

using namespace trephine::testing;

// [SECTION] files

Bytes bytesOf(const std::string& s) {
    return Bytes(s.begin(), s.end());
}

Bytes concat(Bytes a, const Bytes& b) {
    a.insert(a.end(), b.begin(), b.end());
    return a;
}

// Voxel values of a 5 x 4 x 3 volume: a spread of Hounsfield numbers, and for floats NaN and
// infinities among them.
constexpr int kNx = 5, kNy = 4, kNz = 3, kVoxels = kNx * kNy * kNz;

template <typename T>
std::vector<T> voxelValues() {
    std::vector<T> v(kVoxels);
    for (int i = 0; i < kVoxels; ++i)
        v[size_t(i)] = T((i * 97) % 1500 - (std::is_signed_v<T> ? 400 : 0));
    if constexpr (std::is_floating_point_v<T>) {
        v[1] = std::numeric_limits<T>::quiet_NaN();
        v[2] = std::numeric_limits<T>::infinity();
        v[3] = -std::numeric_limits<T>::infinity();
        v[4] = std::numeric_limits<T>::max();
        v[5] = std::numeric_limits<T>::denorm_min();
    }
    return v;
}

std::string nrrdHeader(const std::string& type, const std::string& extra,
                       const std::string& encoding) {
    return "NRRD0004\ntype: " + type + "\ndimension: 3\nsizes: " + std::to_string(kNx) + " " +
           std::to_string(kNy) + " " + std::to_string(kNz) + "\n" + extra +
           "encoding: " + encoding + "\n";
}

// A NIfTI-1 header of our 5 x 4 x 3 volume, 352 bytes with the empty extension block.
Bytes niftiHeader(int16_t datatype, int16_t bitpix, bool bigEndian) {
    return trephine::testing::niftiHeader({kNx, kNy, kNz}, datatype, bitpix, {0.5f, 0.75f, 1.25f},
                                          1.5f, -20.0f, bigEndian);
}

// [SECTION] the check

struct Tally {
    int loaded = 0;
    int refused = 0;
};

// Loads spec: a trephine::Error of one line naming something, or a volume that is sane. The file
// (or files) it reads hold `fileBytes` in all; no single allocation may exceed what decoding them
// can honestly need (the reader's fixed buffers, and what the data inflates to).
void expectRefusedOrSane(const std::string& spec, size_t fileBytes, Tally& tally, bool compressed) {
    // Gzip inflates at most ~1032:1; 1 MiB covers the readers' own buffers.
    const size_t bound = (size_t(1) << 20) + (compressed ? 1032 : 4) * fileBytes;
    AllocationProbe probe;
    try {
        Volume v = loadVolume(spec);
        t_probing = false;
        ++tally.loaded;
        const glm::ivec3 d = v.dims();
        ASSERT_TRUE(d.x > 0 && d.y > 0 && d.z > 0) << spec;
        ASSERT_LE(v.voxelCount(), kMaxVolumeVoxels) << spec;
        for (size_t i = 0; i < v.voxelCount(); ++i)
            ASSERT_LT(v.materialData()[i], kMaterialCount) << spec << " voxel " << i;
        const glm::vec3 s = v.spacing();
        for (int i = 0; i < 3; ++i)
            ASSERT_TRUE(s[i] >= kMinSpacingMm && s[i] <= kMaxSpacingMm) << spec << " spacing " << i;
    } catch (const Error& e) {
        t_probing = false;
        ++tally.refused;
        const std::string msg = e.what();
        EXPECT_FALSE(msg.empty()) << spec;
        EXPECT_EQ(msg.find('\n'), std::string::npos) << spec << ": not one line: " << msg;
    } catch (const std::exception& e) {
        t_probing = false;
        ADD_FAILURE() << spec << ": threw " << typeid(e).name() << " (" << e.what()
                      << ") instead of trephine::Error";
    }
    EXPECT_LE(probe.largest(), bound)
        << spec << ": allocated " << probe.largest() << " bytes for a file of " << fileBytes;
}

// Writes each input to `path` and loads `spec`.
template <typename Inputs>
void fuzzFile(const std::string& path, const std::string& spec, const Bytes& valid, uint32_t seed,
              int random, bool compressed, Tally& tally, Inputs&& extra) {
    auto check = [&](const Bytes& b) {
        writeFile(path, b);
        expectRefusedOrSane(spec, b.size(), tally, compressed);
    };
    // The valid file loads.
    writeFile(path, valid);
    EXPECT_NO_THROW(loadVolume(spec)) << spec;
    // Every truncation in a long run; by default every one of the first 64 bytes, then ever
    // sparser.
    const bool every = fuzzScale() > 1;
    for (size_t len = 0; len < valid.size(); len += every ? 1 : 1 + len / 64)
        check(Bytes(valid.begin(), valid.begin() + std::ptrdiff_t(len)));
    extra(check);
    Mutator m(seed);
    for (int i = 0; i < random; ++i)
        check(m.mutate(valid));
}

auto noExtra = [](auto&&) {};

// Hostile values at every offset of a binary header, in fields of 1, 2, 4 and 8 bytes.
auto hostileAt(const Bytes& valid, size_t from, size_t to) {
    return [&valid, from, to](auto&& check) {
        for (size_t at = from; at < std::min(to, valid.size()); ++at)
            for (size_t width : {1, 2, 4, 8})
                for (uint64_t v : kSpecialValues) {
                    Bytes b = valid;
                    writeLittleEndian(b, at, v, width);
                    check(b);
                }
    };
}

// A NRRD header's field replaced by each of `values` (the line removed for "<none>"); the data
// after the blank line is kept.
Bytes withField(const Bytes& valid, const std::string& field, const std::string& value) {
    const std::string text(valid.begin(), valid.end());
    const size_t end = text.find("\n\n");
    std::string header = text.substr(0, end + 1);
    const std::string rest = text.substr(end + 1);
    const size_t at = header.find("\n" + field + ": ");
    if (at != std::string::npos) {
        const size_t eol = header.find('\n', at + 1);
        header.erase(at + 1, eol - at);
    }
    if (value != "<none>")
        header += field + ": " + value + "\n";
    return bytesOf(header + rest);
}

const std::vector<std::pair<std::string, std::vector<std::string>>> kHostileNrrdFields = {
    {"type",
     {"float", "double", "int64", "uint64", "short", "uchar", "char", "block", "", "<none>"}},
    {"dimension", {"0", "-1", "1", "2", "4", "17", "99999999999999999999", "x", "", "<none>"}},
    {"sizes",
     {"0 4 3", "5 -4 3", "5 4", "5 4 3 1", "1 5 4 3", "1 1 1", "5 4 1", "1024 1024 1024",
      "1024 1024 1025", "100000 100000 100000", "1048576 1 1", "1048577 1 1",
      "9223372036854775807 1 1", "18446744073709551617 2 2", "4294967296 4294967296 1",
      "2147483648 1 1", "5 4 3x", "", "<none>"}},
    {"endian", {"big", "little", "middle", "", "<none>"}},
    {"encoding", {"raw", "gzip", "gz", "ascii", "text", "hex", "bzip2", "", "<none>"}},
    {"spacings",
     {"nan nan nan", "inf 1 1", "-inf 1 1", "0 0 0", "-1 -2 -3", "1e-300 1 1", "1e300 1 1",
      "0.001 1 1000", "1 1 1e6", "1e-4 1 1", "1 1", "1 1 1 1", "", "x y z"}},
    {"space directions",
     {"(nan,0,0) (0,1,0) (0,0,1)", "(inf,0,0) (0,1,0) (0,0,1)", "(0,0,0) (0,1,0) (0,0,1)",
      "(1e200,0,0) (0,1,0) (0,0,1)", "(1e-200,0,0) (0,1,0) (0,0,1)", "(1e-3,0,0) (0,1,0) (0,0,1e3)",
      "none (1,0,0) (0,1,0)", "(1,0,0)", "((((", "(,,) (,,) (,,)", "(1,0,0 (0,1,0) (0,0,1)",
      "() () ()", "(1) (1) (1)", "(1,0,0) none (0,0,1)", ""}},
    {"space units", {"\"km\" \"mm\" \"mm\"", "\"\"", "\"m\" \"m\" \"m\"", "\"um\"", "\"", ""}},
    {"byte skip",
     {"-1", "-2", "1", "60", "1000000", "9223372036854775807", "-9223372036854775808",
      "18446744073709551616", "x", ""}},
    {"line skip", {"-1", "1", "3", "1000000", "9223372036854775807", "x", ""}},
    {"data file",
     {"missing.raw", ".", "..", "/", "/dev/null", "/dev/zero", "LIST", "LIST 1", "a b c", "%s %d",
      "", std::string(5000, 'a')}},
};

auto hostileNrrdFields(const Bytes& valid) {
    return [&valid](auto&& check) {
        for (const auto& [field, values] : kHostileNrrdFields)
            for (const std::string& v : values)
                check(withField(valid, field, v));
        // Header lines repeated, doubled in length, key-values and comments thrown in.
        const std::string text(valid.begin(), valid.end());
        check(bytesOf("NRRD0004\n" + std::string(70000, 'x') + "\n\n"));
        check(bytesOf("NRRD0004\n" + std::string(1 << 16, '#') + "\n" + text.substr(9)));
        check(bytesOf("NRRD9999\n" + text.substr(9)));
        check(bytesOf("NRRD0004\r\n" + text.substr(9)));
        check(bytesOf("NRRD0004\nk:=v\n# c\n:=\n: \n" + text.substr(9)));
    };
}

const std::vector<float> kHostileFloats = {
    std::numeric_limits<float>::quiet_NaN(),
    std::numeric_limits<float>::infinity(),
    -std::numeric_limits<float>::infinity(),
    0.0f,
    -0.0f,
    -1.0f,
    1e-30f,
    1e30f,
    std::numeric_limits<float>::max(),
    std::numeric_limits<float>::denorm_min(),
    347.0f,
    348.0f,
    352.5f,
    1e9f,
    float(1 << 30),
    2147483648.0f,
    -352.0f,
};

// Hostile NIfTI header fields, in the header's own byte order.
auto hostileNiftiFields(const Bytes& valid, bool bigEndian) {
    return [&valid, bigEndian](auto&& check) {
        auto put = [&](Bytes b, size_t off, auto v) {
            uint8_t raw[sizeof v];
            std::memcpy(raw, &v, sizeof v);
            if (bigEndian)
                std::reverse(raw, raw + sizeof v);
            std::memcpy(b.data() + off, raw, sizeof v);
            return b;
        };
        const int16_t shorts[] = {-32768, -1, 0, 1, 2, 3, 4, 7, 8, 1024, 1025, 32767};
        for (size_t i = 0; i < 8; ++i)
            for (int16_t v : shorts)
                check(put(valid, 40 + 2 * i, v));
        for (int16_t d : {16, 32767}) // several at once: 32767^3 voxels, ~2^45
            check(put(put(put(valid, 42, d), 44, d), 46, d));
        check(put(put(put(valid, 42, int16_t(1024)), 44, int16_t(1024)), 46, int16_t(1024)));
        const int16_t types[] = {0,   1,   2,   4,    8,    16,   32,   64,   128,  256,
                                 511, 512, 768, 1024, 1280, 1536, 1792, 2048, 2304, -1};
        for (int16_t t : types)
            for (int16_t bits : {0, 1, 8, 16, 32, 64, 128, -8})
                check(put(put(valid, 70, t), 72, bits));
        const size_t floats[] = {76, 80, 84, 88, 108, 112, 116};
        for (size_t off : floats)
            for (float v : kHostileFloats)
                check(put(valid, off, v));
        for (int units : {0, 1, 2, 3, 7, 8, 255}) {
            Bytes b = valid;
            b[123] = uint8_t(units);
            check(b);
        }
        for (int32_t size : {0, 348, 540, -348, 1 << 30}) {
            check(put(valid, 0, size));
        }
        for (const char* magic : {"ni1", "n+2", "", "n+1x"}) {
            Bytes b = valid;
            char m[4] = {};
            std::memcpy(m, magic, std::min<size_t>(std::strlen(magic), 4)); // no terminator
            std::memcpy(b.data() + 344, m, 4);
            check(b);
        }
    };
}

} // namespace

// [SECTION] NRRD

TEST(VolumeFuzz, NrrdScalarFilesRefuseMutationsOrLoadSanely) {
    FuzzDir dir;
    const int random = 80 * fuzzScale();
    Tally tally;
    struct Case {
        const char* name;
        std::string type;
        Bytes data;
        bool bigEndian;
    };
    const Case cases[] = {
        {"int16le", "short", encode(voxelValues<int16_t>(), false), false},
        {"uint16be", "ushort", encode(voxelValues<uint16_t>(), true), true},
        {"float", "float", encode(voxelValues<float>(), false), false},
        {"double", "double", encode(voxelValues<double>(), true), true},
        {"uint8", "uchar", encode(voxelValues<uint8_t>(), false), false},
        {"int64", "int64", encode(voxelValues<int64_t>(), false), false},
    };
    uint32_t seed = 1;
    for (const Case& c : cases) {
        SCOPED_TRACE(c.name);
        const std::string endian =
            std::string("endian: ") + (c.bigEndian ? "big" : "little") + "\n";
        const std::string extra = endian + "spacings: 0.5 0.75 1.25\n";
        const std::string path = dir / (std::string(c.name) + ".nrrd");
        const Bytes raw = concat(bytesOf(nrrdHeader(c.type, extra, "raw") + "\n"), c.data);
        fuzzFile(path, path, raw, seed++, random, false, tally, hostileNrrdFields(raw));
        const Bytes gz = concat(bytesOf(nrrdHeader(c.type, extra, "gzip") + "\n"), gzip(c.data));
        fuzzFile(path, path, gz, seed++, random, true, tally, hostileNrrdFields(gz));
        // The window option on top of hostile data.
        fuzzFile(path, path + "?window=-1e308,1e308", raw, seed++, random / 4, false, tally,
                 noExtra);
    }
    EXPECT_GT(tally.loaded, 0);
    EXPECT_GT(tally.refused, 0);
}

TEST(VolumeFuzz, OurNrrdLayoutRefusesMutationsOrLoadsSanely) {
    FuzzDir dir;
    const int random = 300 * fuzzScale();
    Tally tally;
    Volume v({kNx, kNy, kNz}, glm::vec3(0.5f, 0.75f, 1.25f));
    for (int i = 0; i < kVoxels; ++i) {
        v.densityData()[i] = uint8_t(i * 37);
        v.materialData()[i] = uint8_t(i % kMaterialCount);
    }
    for (bool compress : {false, true}) {
        SCOPED_TRACE(compress ? "gzip" : "raw");
        const std::string path = dir / "ours.nrrd";
        saveVolume(v, path, {.compress = compress});
        const Bytes valid = readFile(path);
        fuzzFile(path, path, valid, compress ? 11 : 12, random, compress, tally,
                 hostileNrrdFields(valid));
    }
    EXPECT_GT(tally.loaded, 0);
    EXPECT_GT(tally.refused, 0);
}

TEST(VolumeFuzz, DetachedNrrdHeadersAndTheirDataRefuseMutationsOrLoadSanely) {
    FuzzDir dir;
    const int random = 100 * fuzzScale();
    Tally tally;
    for (bool compress : {false, true}) {
        SCOPED_TRACE(compress ? "gzip" : "raw");
        const std::string header = dir / "d.nhdr";
        const std::string data = dir / (compress ? "d.raw.gz" : "d.raw");
        const Bytes values = encode(voxelValues<int16_t>(), false);
        const Bytes stored = compress ? gzip(values) : values;
        const Bytes valid = bytesOf(
            nrrdHeader("short", "endian: little\nbyte skip: 0\n", compress ? "gzip" : "raw") +
            "data file: " + fs::path(data).filename().string() + "\n");
        // The header mutated (its data intact), then the data mutated (the header intact).
        writeFile(data, stored);
        fuzzFile(header, header, valid, compress ? 21 : 22, random, compress, tally, [&](auto&& c) {
            for (const auto& [field, values] : kHostileNrrdFields)
                for (const std::string& v : values)
                    c(withField(concat(valid, bytesOf("\n")), field, v));
        });
        writeFile(header, valid);
        fuzzFile(data, header, stored, compress ? 23 : 24, random, compress, tally, noExtra);
        writeFile(data, stored);
    }
    EXPECT_GT(tally.loaded, 0);
    EXPECT_GT(tally.refused, 0);
}

// [SECTION] NIfTI

TEST(VolumeFuzz, NiftiFilesRefuseMutationsOrLoadSanely) {
    FuzzDir dir;
    const int random = 80 * fuzzScale();
    Tally tally;
    struct Case {
        const char* name;
        int16_t datatype, bitpix;
        Bytes data;
    };
    uint32_t seed = 100;
    for (bool big : {false, true}) {
        const Case cases[] = {
            {"int16", 4, 16, encode(voxelValues<int16_t>(), big)},
            {"float32", 16, 32, encode(voxelValues<float>(), big)},
            {"float64", 64, 64, encode(voxelValues<double>(), big)},
            {"uint64", 1280, 64, encode(voxelValues<uint64_t>(), big)},
            {"uint8", 2, 8, encode(voxelValues<uint8_t>(), big)},
        };
        for (const Case& c : cases) {
            SCOPED_TRACE(std::string(c.name) + (big ? " big-endian" : " little-endian"));
            const Bytes header = niftiHeader(c.datatype, c.bitpix, big);
            const Bytes valid = concat(header, c.data);
            const std::string nii = dir / "a.nii", gz = dir / "a.nii.gz";
            fuzzFile(nii, nii, valid, seed++, random, false, tally, [&](auto&& check) {
                hostileNiftiFields(valid, big)(check);
                if (fuzzScale() > 1) // every offset of the header: 17k inputs a case
                    hostileAt(valid, 0, 352)(check);
            });
            const Bytes zipped = gzip(valid);
            fuzzFile(gz, gz, zipped, seed++, random / 2, true, tally, [&](auto&& check) {
                if (&c == &cases[0] || fuzzScale() > 1)
                    hostileNiftiFields(valid, big)([&](const Bytes& b) { check(gzip(b)); });
            });
        }
    }
    // Our own writer's output, plain and gzip.
    Volume v({kNx, kNy, kNz}, glm::vec3(0.5f));
    for (bool compress : {false, true}) {
        const std::string path = dir / (compress ? "w.nii.gz" : "w.nii");
        saveVolume(v, path);
        fuzzFile(path, path, readFile(path), seed++, random, compress, tally, noExtra);
    }
    EXPECT_GT(tally.loaded, 0);
    EXPECT_GT(tally.refused, 0);
}

// [SECTION] raw: specs and sniffed files

TEST(VolumeFuzz, RawSpecsRefuseHostileOptionsAndDataOrLoadSanely) {
    FuzzDir dir;
    const int random = 150 * fuzzScale();
    Tally tally;
    const Bytes values = encode(voxelValues<float>(), false);
    const std::string path = dir / "v.bin", gzPath = dir / "v.bin.gz";
    const std::string dims =
        "dims=" + std::to_string(kNx) + "," + std::to_string(kNy) + "," + std::to_string(kNz);
    const std::string spec = "raw:" + path + "?" + dims + "&type=float32";
    const std::string gzSpec = "raw:" + gzPath + "?" + dims + "&type=float32";
    fuzzFile(path, spec, values, 200, random, false, tally, noExtra);
    fuzzFile(gzPath, gzSpec, gzip(values), 201, random, true, tally, noExtra);

    writeFile(path, values);
    writeFile(gzPath, gzip(values));
    const std::string options[] = {
        "dims=0,1,1",
        "dims=-1,4,4",
        "dims=100000,100000,100000",
        "dims=1024,1024,1024",
        "dims=1048577,1,1",
        "dims=9223372036854775807,9223372036854775807,1",
        "dims=99999999999999999999,1,1",
        "dims=1,1",
        "dims=1,1,1,1",
        "dims=,,",
        "dims=1.5,2,3",
        "dims=15,4,1&type=float32&offset=0",
        "dims=60,1,1&type=float32",
        "dims=59,1,1&type=float32",
        "dims=59,1,1&type=float32&offset=4",
        "dims=59,1,1&type=float32&offset=9223372036854775807",
        "dims=59,1,1&type=float32&offset=18446744073709551615",
        "dims=59,1,1&type=float32&offset=-4",
        "dims=240,1,1&type=uint8",
        "dims=30,1,1&type=float64&endian=big",
        "dims=120,1,1&type=int16&endian=middle",
        "dims=60,1,1&type=float32&spacing=nan,1,1",
        "dims=60,1,1&type=float32&spacing=inf,1,1",
        "dims=60,1,1&type=float32&spacing=0,1,1",
        "dims=60,1,1&type=float32&spacing=-1,1,1",
        "dims=60,1,1&type=float32&spacing=1e-30,1,1",
        "dims=60,1,1&type=float32&window=1,1",
        "dims=60,1,1&type=float32&window=nan,1",
        "dims=60,1,1&type=float32&window=-1e308,1e308",
        "dims=60,1,1&type=float32&window=0,1e-300",
        "dims=60,1,1&type=complex",
        "dims=60,1,1&type=float32&dims=1,1,1",
        "dims=60,1,1&type=float32&",
        "dims=60,1,1&type",
        "&&&",
        "",
    };
    for (const std::string& o : options)
        for (const std::string& p : {path, gzPath}) {
            const std::string s = "raw:" + p + "?" + o;
            expectRefusedOrSane(s, values.size(), tally, p == gzPath);
        }
    for (const std::string& s :
         {std::string("raw:"), std::string("raw:?dims=1,1,1"),
          "raw:" + dir.path.string() + "?dims=1,1,1", std::string("raw:/dev/null?dims=1,1,1"),
          std::string("raw:/dev/zero?dims=1024,1024,1024")})
        expectRefusedOrSane(s, 0, tally, false);
    EXPECT_GT(tally.loaded, 0);
    EXPECT_GT(tally.refused, 0);
}

TEST(VolumeFuzz, FilesSniffedByContentRefuseMutationsOrLoadSanely) {
    // Names without a known extension: the format comes from the first bytes, so mutations there
    // switch readers.
    FuzzDir dir;
    const int random = 150 * fuzzScale();
    Tally tally;
    const Bytes nrrd = concat(bytesOf(nrrdHeader("short", "endian: little\n", "raw") + "\n"),
                              encode(voxelValues<int16_t>(), false));
    const Bytes nii = concat(niftiHeader(4, 16, true), encode(voxelValues<int16_t>(), true));
    const std::string path = dir / "scan.dat";
    fuzzFile(path, path, nrrd, 300, random, false, tally, noExtra);
    fuzzFile(path, path, nii, 301, random, false, tally, noExtra);
    fuzzFile(path, path, gzip(nii), 302, random, true, tally, noExtra);
    EXPECT_GT(tally.loaded, 0);
    EXPECT_GT(tally.refused, 0);
}

// [SECTION] gzip

TEST(VolumeFuzz, GzipStreamsThatLieRefuseOrLoadSanely) {
    // Concatenated members, trailing junk, zlib instead of gzip headers, empty members, a stored
    // stream with a bad CRC, and a stream of zeros far longer than the header's size (a small file
    // that inflates to 16 MiB: refused, and no buffer beyond the voxels is kept).
    FuzzDir dir;
    Tally tally;
    const Bytes values = encode(voxelValues<int16_t>(), false);
    const Bytes header = bytesOf(nrrdHeader("short", "endian: little\n", "gzip") + "\n");
    const std::string path = dir / "g.nrrd";
    Bytes half1(values.begin(), values.begin() + 50), half2(values.begin() + 50, values.end());
    Bytes zlib(compressBound(uLong(values.size())));
    uLongf zlibSize = uLongf(zlib.size());
    ASSERT_EQ(compress(zlib.data(), &zlibSize, values.data(), uLong(values.size())), Z_OK);
    zlib.resize(zlibSize);
    Bytes badCrc = gzip(values);
    badCrc[badCrc.size() - 8] ^= 1;
    const Bytes bodies[] = {
        concat(gzip(half1), gzip(half2)),
        concat(gzip(values), gzip({})),
        concat(gzip({}), gzip(values)),
        concat(gzip(values), bytesOf("junk after the stream")),
        concat(gzip(values), Bytes{0x1f}),
        concat(gzip(values), Bytes{0x1f, 0x8b}),
        concat(gzip(values), Bytes{0x1f, 0x8b, 0x08, 0, 0, 0, 0, 0, 0, 3}),
        zlib,
        badCrc,
        gzip(Bytes(size_t(16) << 20, 0)),
        Bytes{0x1f, 0x8b},
        Bytes{0x1f, 0x8b, 0x08, 0xff},
        Bytes(100, 0x1f),
        {},
    };
    for (const Bytes& body : bodies) {
        const Bytes file = concat(header, body);
        writeFile(path, file);
        expectRefusedOrSane(path, file.size(), tally, true);
    }
    EXPECT_GT(tally.loaded, 0);
    EXPECT_GT(tally.refused, 0);
}

// [SECTION] defects the fuzzing found

// Loads spec expecting a one-line Error containing `problem`; returns the largest allocation.
size_t expectSpecRefused(const std::string& spec, const std::string& problem) {
    return expectRefused([&] { loadVolume(spec); }, problem);
}

TEST(VolumeFuzz, ALineSkipOverBinaryDataKeepsNothingAndStopsAtOneMebibyte) {
    // `line skip` read each skipped line into memory, up to 1 GiB: a header pointing it at 8 MiB
    // without a newline allocated 8 MiB (at /dev/zero: 2 GB and 23 s before the Error).
    FuzzDir dir;
    writeFile(dir / "d.raw", Bytes(size_t(8) << 20, 'x'));
    writeFile(dir / "d.nhdr",
              bytesOf(nrrdHeader("uchar", "line skip: 1\n", "raw") + "data file: d.raw\n"));
    EXPECT_LT(expectSpecRefused(dir / "d.nhdr", "longer than 1048576 characters"), size_t(1) << 20);
    // Lines that are text are skipped as before.
    Bytes data = bytesOf("# a text header\n\n" + std::string(size_t(1) << 20, 'y') + "\n");
    data.resize(data.size() + kVoxels, 7);
    writeFile(dir / "d.raw", data);
    writeFile(dir / "d.nhdr",
              bytesOf(nrrdHeader("uchar", "line skip: 3\n", "raw") + "data file: d.raw\n"));
    EXPECT_EQ(loadVolume(dir / "d.nhdr").densityData()[kVoxels - 1], 7);
}

TEST(VolumeFuzz, DataPastTheVoxelsOfAGzipStreamIsCountedOnlySoFar) {
    // The check for data past the voxels inflated the whole rest of the stream to count it: a
    // one-voxel header before 1 MB of gzip holding 1 GiB of zeros took 3.3 s to refuse, and a
    // 100 MB one minutes. Here 256 MiB of zeros (concatenated members, 256 KB): refused after
    // 64 MiB.
    FuzzDir dir;
    const Bytes member = gzip(Bytes(size_t(1) << 20, 0));
    Bytes body;
    for (int i = 0; i < 256; ++i)
        body.insert(body.end(), member.begin(), member.end());
    writeFile(dir / "bomb.nrrd",
              concat(bytesOf("NRRD0004\ntype: uchar\ndimension: 3\nsizes: 1 1 1\nencoding: "
                             "gzip\n\n"),
                     body));
    expectSpecRefused(
        dir / "bomb.nrrd",
        "dimensions do not match the data: they need 1 bytes of data, found more than " +
            std::to_string((uint64_t(64) << 20) + 1));
    // A little data too many is still counted exactly.
    writeFile(dir / "more.nrrd",
              concat(bytesOf("NRRD0004\ntype: uchar\ndimension: 3\nsizes: 1 1 1\nencoding: "
                             "gzip\n\n"),
                     gzip(Bytes(100, 0))));
    expectSpecRefused(dir / "more.nrrd", "they need 1 bytes of data, found 100");
}

// Loads spec in a child process: true when it throws an Error containing `problem` within
// `seconds` (a reader that hangs is killed).
bool refusedWithin(int seconds, const std::string& spec, const std::string& problem) {
    const pid_t pid = ::fork();
    if (pid == 0) {
        int code = 2;
        try {
            loadVolume(spec);
        } catch (const Error& e) {
            code = std::string(e.what()).find(problem) != std::string::npos ? 0 : 3;
        } catch (...) {
        }
        ::_exit(code);
    }
    for (int i = 0; i < seconds * 100; ++i) {
        int status = 0;
        if (::waitpid(pid, &status, WNOHANG) == pid)
            return WIFEXITED(status) && WEXITSTATUS(status) == 0;
        ::usleep(10000);
    }
    ::kill(pid, SIGKILL);
    ::waitpid(pid, nullptr, 0);
    return false;
}

TEST(VolumeFuzz, DataFilesThatAreDevicesOrPipesAreRefusedInsteadOfReadForever) {
    // A NRRD's detached data came from any path: `data file: /dev/urandom` with a large line
    // skip read forever, and a FIFO blocked on opening.
    FuzzDir dir;
    const std::string header = nrrdHeader("uchar", "", "raw");
    writeFile(dir / "urandom.nhdr",
              bytesOf(header + "data file: /dev/urandom\nline skip: 9223372036854775807\n"));
    EXPECT_TRUE(refusedWithin(10, dir / "urandom.nhdr", "not a regular file"));
    ASSERT_EQ(::mkfifo((dir / "fifo.raw").c_str(), 0600), 0);
    writeFile(dir / "fifo.nhdr", bytesOf(header + "data file: fifo.raw\n"));
    EXPECT_TRUE(refusedWithin(10, dir / "fifo.nhdr", "not a regular file"));
    EXPECT_TRUE(refusedWithin(10, "raw:" + dir / "fifo.raw?dims=1,1,1", "not a regular file"));
}

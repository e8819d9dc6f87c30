// Volume specs and files: NRRD / NIfTI-1 / raw round trips, the density window and material
// rules, byte order, and one clear one-line Error for every malformed input.
#include "libsim/error.h"
#include "libsim/skull.h"
#include "libsim/volume_io.h"

#include "test_support.h"

#include <gtest/gtest.h>

#include "byte_files.h"

#include <algorithm>
#include <cmath>
#include <csignal>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <map>
#include <string>
#include <sys/resource.h>
#include <unistd.h>
#include <vector>
#include <zlib.h>

namespace fs = std::filesystem;
using namespace trephine;

namespace {

using namespace trephine::testing;

Bytes concat(const std::string& text, const Bytes& data) {
    Bytes out(text.begin(), text.end());
    out.insert(out.end(), data.begin(), data.end());
    return out;
}

// A volume with every material and a spread of densities.
Volume patterned(glm::ivec3 dims, glm::vec3 spacing) {
    Volume v(dims, spacing);
    for (int z = 0; z < dims.z; ++z)
        for (int y = 0; y < dims.y; ++y)
            for (int x = 0; x < dims.x; ++x)
                v.set(x, y, z, uint8_t((x * 37 + y * 11 + z * 5) % 256),
                      Material((x + 2 * y + 3 * z) % kMaterialCount));
    return v;
}

// Materials as the loaders derive them, so a density-only format round-trips exactly.
Volume derived(glm::ivec3 dims, glm::vec3 spacing) {
    Volume v(dims, spacing);
    for (int z = 0; z < dims.z; ++z)
        for (int y = 0; y < dims.y; ++y)
            for (int x = 0; x < dims.x; ++x) {
                uint8_t d = uint8_t((x * 37 + y * 11 + z * 5) % 256);
                v.set(x, y, z, d, materialFromDensity(d));
            }
    return v;
}

std::vector<uint8_t> densities(const Volume& v) {
    return {v.densityData(), v.densityData() + v.voxelCount()};
}

// Expects Error with a one-line message that contains `name` and `problem`.
void expectError(const std::function<void()>& f, const std::string& name,
                 const std::string& problem) {
    try {
        f();
        ADD_FAILURE() << "no Error thrown; expected one naming " << name << " (" << problem << ")";
    } catch (const Error& e) {
        std::string msg = e.what();
        EXPECT_NE(msg.find(name), std::string::npos)
            << "message does not name " << name << ": " << msg;
        EXPECT_NE(msg.find(problem), std::string::npos)
            << "message lacks '" << problem << "': " << msg;
        EXPECT_EQ(msg.find('\n'), std::string::npos) << "message is not one line: " << msg;
    }
}

// An attached-data NRRD header; `extra` is more field lines, newline-separated.
std::string nrrdHeader(const std::string& type, const std::string& sizes,
                       const std::string& encoding, const std::string& extra = "") {
    return "NRRD0004\ntype: " + type + "\ndimension: 3\nsizes: " + sizes +
           "\nencoding: " + encoding + "\n" + (extra.empty() ? "" : extra + "\n") + "\n";
}

// Hounsfield values and their densities through the default window (-300..900).
const std::vector<int16_t> kHu = {-1000, -300, 0, 300, 600, 900, 1500, 800};
const std::vector<uint8_t> kHuDensity = {0, 0, 64, 128, 191, 255, 255, 234};
const std::vector<Material> kHuMaterial = {
    Material::Air,    Material::Air,      Material::Air,      Material::Diploe,
    Material::Diploe, Material::Cortical, Material::Cortical, Material::Cortical};

void expectHu(const Volume& v) {
    ASSERT_EQ(v.voxelCount(), kHu.size());
    EXPECT_EQ(densities(v), kHuDensity);
    for (size_t i = 0; i < kHu.size(); ++i)
        EXPECT_EQ(Material(v.materialData()[i]), kHuMaterial[i]) << "voxel " << i;
}

} // namespace

// [Window and materials]

TEST(VolumeIo, WindowMapsHounsfieldToDensity) {
    EXPECT_EQ(windowDensity(-1000, kDefaultWindow), 0);
    EXPECT_EQ(windowDensity(-300, kDefaultWindow), 0);
    EXPECT_EQ(windowDensity(0, kDefaultWindow), 64);
    EXPECT_EQ(windowDensity(300, kDefaultWindow), kSurfaceDensity);
    EXPECT_EQ(windowDensity(900, kDefaultWindow), 255);
    EXPECT_EQ(windowDensity(3000, kDefaultWindow), 255);
    EXPECT_EQ(windowDensity(std::nan(""), kDefaultWindow), 0);
    EXPECT_EQ(windowDensity(50, DensityWindow{0, 100}), 128);
}

TEST(VolumeIo, MaterialThresholds) {
    EXPECT_EQ(materialFromDensity(0), Material::Air);
    EXPECT_EQ(materialFromDensity(127), Material::Air);
    EXPECT_EQ(materialFromDensity(128), Material::Diploe);
    EXPECT_EQ(materialFromDensity(233), Material::Diploe);
    EXPECT_EQ(materialFromDensity(234), Material::Cortical);
    EXPECT_EQ(materialFromDensity(255), Material::Cortical);
}

// [NRRD]

TEST(VolumeIo, NrrdGzipRoundTripKeepsDensityMaterialsAndSpacing) {
    TempDir dir;
    Volume v = patterned({7, 5, 3}, {0.5f, 0.75f, 1.25f});
    saveVolume(v, dir / "a.nrrd");
    std::string text(reinterpret_cast<const char*>(readFile(dir / "a.nrrd").data()), 400);
    EXPECT_NE(text.find("encoding: gzip"), std::string::npos);
    EXPECT_NE(text.find("sizes: 2 7 5 3"), std::string::npos);
    EXPECT_NE(text.find("trephine_layout:=density,material"), std::string::npos);
    Volume back = loadVolume(dir / "a.nrrd");
    EXPECT_EQ(back.dims(), v.dims());
    EXPECT_EQ(back.spacing(), v.spacing());
    EXPECT_TRUE(back == v);
}

TEST(VolumeIo, NrrdRawRoundTrip) {
    TempDir dir;
    Volume v = patterned({9, 4, 6}, {0.3f, 0.3f, 0.6f});
    saveVolume(v, dir / "a.nrrd", SaveOptions{.compress = false});
    Bytes file = readFile(dir / "a.nrrd");
    // Attached raw data: the file ends with the interleaved pairs.
    ASSERT_GT(file.size(), 2 * v.voxelCount());
    const uint8_t* data = file.data() + file.size() - 2 * v.voxelCount();
    EXPECT_EQ(data[0], v.densityData()[0]);
    EXPECT_EQ(data[1], v.materialData()[0]);
    EXPECT_EQ(data[2 * 17], v.densityData()[17]);
    EXPECT_EQ(data[2 * 17 + 1], v.materialData()[17]);
    EXPECT_TRUE(loadVolume(dir / "a.nrrd") == v);
}

TEST(VolumeIo, NhdrDetachedRoundTrip) {
    TempDir dir;
    Volume v = patterned({4, 4, 4}, {1.0f, 2.0f, 3.0f});
    saveVolume(v, dir / "a.nhdr");
    EXPECT_TRUE(fs::exists(dir / "a.raw.gz"));
    EXPECT_TRUE(loadVolume(dir / "a.nhdr") == v);
    saveVolume(v, dir / "b.nhdr", SaveOptions{.compress = false});
    EXPECT_EQ(fs::file_size(dir / "b.raw"), 2 * v.voxelCount());
    EXPECT_TRUE(loadVolume(dir / "b.nhdr") == v);
}

TEST(VolumeIo, NrrdInt16LittleEndianThroughTheWindow) {
    TempDir dir;
    writeFile(dir / "ct.nrrd",
              concat(nrrdHeader("short", "8 1 1", "raw", "endian: little\nspacings: 0.5 0.5 2"),
                     encode(kHu, false)));
    Volume v = loadVolume(dir / "ct.nrrd");
    EXPECT_EQ(v.dims(), glm::ivec3(8, 1, 1));
    EXPECT_EQ(v.spacing(), glm::vec3(0.5f, 0.5f, 2.0f));
    expectHu(v);
}

TEST(VolumeIo, NrrdInt16BigEndianGzip) {
    TempDir dir;
    writeFile(dir / "ct.nrrd", concat(nrrdHeader("int16", "2 2 2", "gzip",
                                                 "endian: big\nspace directions: (0.4,0,0) "
                                                 "(0,0.4,0) (0,0,1.5)\nspace: RAS"),
                                      gzip(encode(kHu, true))));
    Volume v = loadVolume(dir / "ct.nrrd");
    EXPECT_EQ(v.dims(), glm::ivec3(2, 2, 2));
    EXPECT_FLOAT_EQ(v.spacing().x, 0.4f);
    EXPECT_FLOAT_EQ(v.spacing().z, 1.5f);
    expectHu(v);
}

TEST(VolumeIo, NrrdWindowOverride) {
    TempDir dir;
    writeFile(dir / "ct.nrrd", concat(nrrdHeader("short", "4 1 1", "raw", "endian: little"),
                                      encode(std::vector<int16_t>{0, 300, 1000, -5}, false)));
    Volume v = loadVolume(dir / "ct.nrrd?window=0,1000");
    EXPECT_EQ(densities(v), (std::vector<uint8_t>{0, 77, 255, 0}));
}

TEST(VolumeIo, NrrdOtherScalarTypes) {
    TempDir dir;
    writeFile(dir / "u8.nrrd", concat(nrrdHeader("uchar", "3 1 1", "raw"), Bytes{0, 200, 240}));
    Volume u8 = loadVolume(dir / "u8.nrrd");
    EXPECT_EQ(densities(u8), (std::vector<uint8_t>{0, 200, 240})); // passes through
    EXPECT_EQ(u8.material(1, 0, 0), Material::Diploe);
    EXPECT_EQ(u8.material(2, 0, 0), Material::Cortical);

    writeFile(dir / "f.nrrd", concat(nrrdHeader("float", "3 1 1", "raw", "endian: big"),
                                     encode(std::vector<float>{-300.0f, 300.0f, 900.0f}, true)));
    EXPECT_EQ(densities(loadVolume(dir / "f.nrrd")), (std::vector<uint8_t>{0, 128, 255}));

    writeFile(dir / "d.nrrd", concat(nrrdHeader("double", "2 1 1", "gzip", "endian: little"),
                                     gzip(encode(std::vector<double>{0.0, 1500.0}, false))));
    EXPECT_EQ(densities(loadVolume(dir / "d.nrrd")), (std::vector<uint8_t>{64, 255}));

    writeFile(dir / "us.nrrd", concat(nrrdHeader("unsigned short", "2 1 1", "raw", "endian: big"),
                                      encode(std::vector<uint16_t>{300, 60000}, true)));
    EXPECT_EQ(densities(loadVolume(dir / "us.nrrd")), (std::vector<uint8_t>{128, 255}));

    writeFile(dir / "i.nrrd", concat(nrrdHeader("int", "2 1 1", "raw", "endian: little"),
                                     encode(std::vector<int32_t>{-2000, 600}, false)));
    EXPECT_EQ(densities(loadVolume(dir / "i.nrrd")), (std::vector<uint8_t>{0, 191}));

    writeFile(dir / "c.nrrd", concat(nrrdHeader("char", "2 1 1", "raw"), Bytes{0x80, 100}));
    EXPECT_EQ(densities(loadVolume(dir / "c.nrrd")),
              (std::vector<uint8_t>{37, 85})); // -128, 100 HU

    writeFile(dir / "ui.nrrd", concat(nrrdHeader("uint", "1 1 1", "raw", "endian: big"),
                                      encode(std::vector<uint32_t>{900}, true)));
    EXPECT_EQ(densities(loadVolume(dir / "ui.nrrd")), (std::vector<uint8_t>{255}));
}

TEST(VolumeIo, NrrdDetachedScalarWithByteSkip) {
    TempDir dir;
    writeFile(dir / "ct.raw", concat("JUNK", encode(kHu, false)));
    std::ofstream(dir / "ct.nhdr") << "NRRD0004\n# comment\ntype: short\ndimension: 3\n"
                                      "sizes: 8 1 1\nendian: little\nencoding: raw\n"
                                      "byte skip: 4\ndata file: ct.raw\n";
    expectHu(loadVolume(dir / "ct.nhdr"));
    std::ofstream(dir / "end.nhdr") << "NRRD0004\ntype: short\ndimension: 3\nsizes: 8 1 1\n"
                                       "endian: little\nencoding: raw\nbyte skip: -1\n"
                                       "datafile: ct.raw\n";
    expectHu(loadVolume(dir / "end.nhdr"));
}

TEST(VolumeIo, NrrdSpaceUnitsScaleToMillimetres) {
    TempDir dir;
    writeFile(dir / "cm.nrrd",
              concat(nrrdHeader("uchar", "2 1 1", "raw",
                                "space directions: (0.1,0,0) (0,0.05,0) (0,0,0.2)\n"
                                "space units: \"cm\" \"cm\" \"cm\""),
                     Bytes{1, 2}));
    Volume v = loadVolume(dir / "cm.nrrd");
    EXPECT_FLOAT_EQ(v.spacing().x, 1.0f);
    EXPECT_FLOAT_EQ(v.spacing().y, 0.5f);
    EXPECT_FLOAT_EQ(v.spacing().z, 2.0f);
}

// [NIfTI]

TEST(VolumeIo, NiftiRoundTrip) {
    TempDir dir;
    Volume v = derived({6, 5, 4}, {0.5f, 0.6f, 2.0f});
    saveVolume(v, dir / "a.nii");
    EXPECT_EQ(fs::file_size(dir / "a.nii"), 352 + v.voxelCount());
    EXPECT_TRUE(loadVolume(dir / "a.nii") == v);
    saveVolume(v, dir / "a.nii.gz");
    Bytes gz = readFile(dir / "a.nii.gz");
    ASSERT_GE(gz.size(), 2u);
    EXPECT_EQ(gz[0], 0x1f);
    EXPECT_TRUE(loadVolume(dir / "a.nii.gz") == v);
}

TEST(VolumeIo, NiftiInt16WithSlopeAndWindow) {
    TempDir dir;
    // Stored s, Hounsfield 2 s - 1000.
    std::vector<int16_t> stored;
    for (int16_t hu : kHu)
        stored.push_back(int16_t((hu + 1000) / 2));
    Bytes header = niftiHeader({4, 2, 1}, 4, 16, {0.8f, 0.8f, 1.0f}, 2.0f, -1000.0f, false);
    writeFile(dir / "ct.nii",
              concat(std::string(header.begin(), header.end()), encode(stored, false)));
    Volume v = loadVolume(dir / "ct.nii");
    EXPECT_EQ(v.dims(), glm::ivec3(4, 2, 1));
    EXPECT_FLOAT_EQ(v.spacing().x, 0.8f);
    expectHu(v);
}

TEST(VolumeIo, NiftiBigEndianAndGzip) {
    TempDir dir;
    Bytes header = niftiHeader({8, 1, 1}, 4, 16, {1, 1, 1}, 0.0f, 0.0f, true);
    Bytes file = concat(std::string(header.begin(), header.end()), encode(kHu, true));
    writeFile(dir / "be.nii", file);
    expectHu(loadVolume(dir / "be.nii"));
    writeFile(dir / "be.nii.gz", gzip(file));
    expectHu(loadVolume(dir / "be.nii.gz"));

    Bytes fh = niftiHeader({3, 1, 1}, 16, 32, {1, 1, 1}, 1.0f, 0.0f, false);
    writeFile(dir / "f.nii", concat(std::string(fh.begin(), fh.end()),
                                    encode(std::vector<float>{300.0f, 900.0f, -5000.0f}, false)));
    EXPECT_EQ(densities(loadVolume(dir / "f.nii")), (std::vector<uint8_t>{128, 255, 0}));
}

// [Raw and built-ins]

TEST(VolumeIo, RawSpec) {
    TempDir dir;
    writeFile(dir / "ct.bin", encode(kHu, true));
    Volume v = loadVolume("raw:" + (dir / "ct.bin") +
                          "?dims=2,2,2&type=int16&endian=big&spacing=0.5,0.5,1");
    EXPECT_EQ(v.dims(), glm::ivec3(2, 2, 2));
    EXPECT_EQ(v.spacing(), glm::vec3(0.5f, 0.5f, 1.0f));
    expectHu(v);

    writeFile(dir / "u8.raw", Bytes{1, 2, 3, 250});
    Volume u8 = loadVolume("raw:" + (dir / "u8.raw") + "?dims=4,1,1");
    EXPECT_EQ(densities(u8), (std::vector<uint8_t>{1, 2, 3, 250}));

    writeFile(dir / "f.raw", encode(std::vector<float>{0.0f, 0.5f, 1.0f}, false));
    EXPECT_EQ(
        densities(loadVolume("raw:" + (dir / "f.raw") + "?dims=3,1,1&type=float32&window=0,1")),
        (std::vector<uint8_t>{0, 128, 255}));

    writeFile(dir / "us.raw.gz", gzip(encode(std::vector<uint16_t>{300, 0}, false)));
    EXPECT_EQ(densities(loadVolume("raw:" + (dir / "us.raw.gz") + "?dims=2,1,1&type=uint16")),
              (std::vector<uint8_t>{128, 64}));
}

TEST(VolumeIo, RawSpecErrors) {
    TempDir dir;
    const std::string f = dir / "x.raw";
    writeFile(f, Bytes(64, 0));
    expectError([&] { loadVolume("raw:" + f); }, f, "dims=X,Y,Z");
    expectError([&] { loadVolume("raw:" + f + "?dims=4,4"); }, f, "bad dims");
    expectError([&] { loadVolume("raw:" + f + "?dims=4,4,4&type=int12"); }, f, "unknown type");
    expectError([&] { loadVolume("raw:" + f + "?dims=4,4,4&endian=middle"); }, f, "endian");
    expectError([&] { loadVolume("raw:" + f + "?dims=4,4,4&colour=red"); }, f, "unknown option");
    expectError([&] { loadVolume("raw:" + f + "?dims=4,4,4&spacing=1,0,1"); }, f, "spacing");
    expectError([&] { loadVolume("raw:" + f + "?dims=4,4,4&window=5,1"); }, f, "window");
    expectError([&] { loadVolume("raw:" + f + "?dims=4,4,8"); }, f, "truncated: expected 128");
    expectError([&] { loadVolume("raw:" + f + "?dims=4,4,2"); }, f, "do not match the data");
    expectError([&] { loadVolume("raw:" + f + "?dims=4,4,4&type=int16"); }, f, "truncated");
    expectError([&] { loadVolume("raw:" + f + "?dims=2048,2048,2048"); }, f, "too large");
    expectError([&] { loadVolume("raw:" + f + "?dims=0,4,4"); }, f, "positive");
}

TEST(VolumeIo, BuiltinSpecs) {
    Volume sphere = loadVolume("sphere:32");
    EXPECT_EQ(sphere.dims(), glm::ivec3(32));
    EXPECT_GT(sphere.materialCounts()[int(Material::Cortical)], 0);
    EXPECT_EQ(loadVolume("box:16").dims(), glm::ivec3(16));
    Volume skull = loadVolume("skull:32?seed=7");
    EXPECT_EQ(skull.dims(), glm::ivec3(32));
    EXPECT_TRUE(skull == loadVolume("skull:32?seed=7"));
    expectError([] { loadVolume("skull:9999"); }, "skull:9999", "32..512");
    expectError([] { loadVolume("skull:abc"); }, "skull:abc", "bad size");
    expectError([] { loadVolume("sphere:32?seed=1"); }, "sphere:32?seed=1", "unknown option");
    expectError([] { loadVolume("skull:64?seed=-1"); }, "skull:64?seed=-1", "bad seed");
    expectError([] { loadVolume(""); }, "", "empty volume spec");
}

TEST(VolumeIo, SaveErrors) {
    TempDir dir;
    Volume v = patterned({2, 2, 2}, glm::vec3(1.0f));
    expectError([&] { saveVolume(v, dir / "a.png"); }, dir / "a.png", "unknown output format");
    expectError([&] { saveVolume(v, dir / "no/such/dir/a.nrrd"); }, "a.nrrd", "cannot write");
}

// [Malformed files]

TEST(VolumeIo, MissingFile) {
    TempDir dir;
    expectError([&] { loadVolume(dir / "nope.nrrd"); }, dir / "nope.nrrd", "no such file");
    expectError([&] { loadVolume(dir / "nope.nii.gz"); }, dir / "nope.nii.gz", "no such file");
    std::ofstream(dir / "d.nhdr") << "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 2 2\n"
                                     "encoding: raw\ndata file: gone.raw\n";
    expectError([&] { loadVolume(dir / "d.nhdr"); }, "gone.raw", "cannot open");
}

TEST(VolumeIo, FolderNeedsSimImage) {
    TempDir dir;
    expectError([&] { loadVolume(dir.path.string()); }, dir.path.string(), "sim_image");
    expectError([&] { loadVolume("slices:" + dir.path.string()); }, dir.path.string(), "sim_image");
}

TEST(VolumeIo, TruncatedData) {
    TempDir dir;
    writeFile(dir / "t.nrrd", concat(nrrdHeader("uchar", "128 128 128", "raw"), Bytes(1000, 7)));
    expectError([&] { loadVolume(dir / "t.nrrd"); }, dir / "t.nrrd",
                "truncated: expected 2097152 bytes of data, found 1000");

    Volume v = derived({8, 8, 8}, glm::vec3(1.0f));
    saveVolume(v, dir / "a.nii");
    Bytes nii = readFile(dir / "a.nii");
    nii.resize(nii.size() - 10);
    writeFile(dir / "t.nii", nii);
    expectError([&] { loadVolume(dir / "t.nii"); }, dir / "t.nii", "truncated");
    nii.resize(200);
    writeFile(dir / "h.nii", nii);
    expectError([&] { loadVolume(dir / "h.nii"); }, dir / "h.nii", "truncated");

    // A header with no blank line and no data file.
    std::ofstream(dir / "h.nrrd") << "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 2 2\n"
                                     "encoding: raw\n";
    expectError([&] { loadVolume(dir / "h.nrrd"); }, dir / "h.nrrd", "truncated");
    writeFile(dir / "empty.nrrd", {});
    expectError([&] { loadVolume(dir / "empty.nrrd"); }, dir / "empty.nrrd", "empty");
}

TEST(VolumeIo, WrongMagic) {
    TempDir dir;
    std::ofstream(dir / "m.nrrd") << "HELLO WORLD\ntype: uchar\n";
    expectError([&] { loadVolume(dir / "m.nrrd"); }, dir / "m.nrrd", "not a NRRD file");
    writeFile(dir / "m.nii", Bytes(400, 0));
    expectError([&] { loadVolume(dir / "m.nii"); }, dir / "m.nii", "sizeof_hdr is 0");
    Bytes header = niftiHeader({2, 2, 2}, 2, 8, glm::vec3(1.0f), 1.0f, 0.0f, false);
    std::memcpy(header.data() + 344, "ni1", 4);
    writeFile(dir / "pair.nii", concat(std::string(header.begin(), header.end()), Bytes(8, 0)));
    expectError([&] { loadVolume(dir / "pair.nii"); }, dir / "pair.nii", "two-file NIfTI");
    std::memcpy(header.data() + 344, "xyz", 4);
    writeFile(dir / "magic.nii", concat(std::string(header.begin(), header.end()), Bytes(8, 0)));
    expectError([&] { loadVolume(dir / "magic.nii"); }, dir / "magic.nii", "magic");
    writeFile(dir / "what.dat", Bytes(100, 1));
    expectError([&] { loadVolume(dir / "what.dat"); }, dir / "what.dat", "unknown volume format");
    // A gzipped NRRD was read as NIfTI (all we gzip whole) and refused as "not a NIfTI-1 file".
    const std::string gz = dir / "scan.NRRD.gz";
    saveVolume(makeSphere(8), dir / "scan.nii.gz");
    std::filesystem::rename(dir / "scan.nii.gz", gz);
    expectError([&] { loadVolume(gz); }, gz, "a gzipped NRRD file: gunzip it first");
}

TEST(VolumeIo, BadHeaderFields) {
    TempDir dir;
    auto check = [&](const std::string& name, const std::string& header,
                     const std::string& problem) {
        writeFile(dir / name, concat(header, Bytes(64, 0)));
        expectError([&] { loadVolume(dir / name); }, dir / name, problem);
    };
    check("type.nrrd", nrrdHeader("quaternion", "4 4 4", "raw"), "unsupported NRRD type");
    check("enc.nrrd", nrrdHeader("uchar", "4 4 4", "bzip2"), "unsupported NRRD encoding");
    check("sizes.nrrd", nrrdHeader("uchar", "4 x 4", "raw"), "bad NRRD sizes");
    check("count.nrrd", nrrdHeader("uchar", "4 4", "raw"), "dimension is 3 but 2 sizes");
    check("endian.nrrd", nrrdHeader("short", "4 4 2", "raw"), "missing NRRD field 'endian'");
    check("nosizes.nrrd", "NRRD0004\ntype: uchar\ndimension: 3\nencoding: raw\n\n",
          "missing NRRD field 'sizes'");
    check("line.nrrd", nrrdHeader("uchar", "4 4 4", "raw", "this is not a field"),
          "bad NRRD header line");
    check("twice.nrrd", nrrdHeader("uchar", "4 4 4", "raw", "type: uchar"), "given twice");
    check("sp.nrrd", nrrdHeader("uchar", "4 4 4", "raw", "spacings: 1 1"), "bad NRRD 'spacings'");
    check("dir.nrrd",
          nrrdHeader("uchar", "4 4 4", "raw", "space directions: (1,0,0) (0,0,0) (0,0,1)"),
          "zero length");
    check("4d.nrrd", "NRRD0004\ntype: uchar\ndimension: 4\nsizes: 3 2 2 2\nencoding: raw\n\n",
          "4-D NRRD with 3 values per voxel");
    check("big.nrrd", nrrdHeader("uchar", "4096 4096 4096", "raw"), "too large");
    check("layout.nrrd",
          "NRRD0004\ntype: short\ndimension: 4\nsizes: 2 2 2 2\nendian: little\nencoding: "
          "raw\ntrephine_layout:=density,material\n\n",
          "needs type uchar");

    Bytes h = niftiHeader({2, 2, 2}, 128, 24, glm::vec3(1.0f), 1.0f, 0.0f, false); // RGB24
    writeFile(dir / "rgb.nii", concat(std::string(h.begin(), h.end()), Bytes(24, 0)));
    expectError([&] { loadVolume(dir / "rgb.nii"); }, dir / "rgb.nii",
                "unsupported NIfTI datatype");
    h = niftiHeader({2, 2, 2}, 4, 8, glm::vec3(1.0f), 1.0f, 0.0f, false);
    writeFile(dir / "bitpix.nii", concat(std::string(h.begin(), h.end()), Bytes(16, 0)));
    expectError([&] { loadVolume(dir / "bitpix.nii"); }, dir / "bitpix.nii", "bitpix");
    h = niftiHeader({2, -2, 2}, 2, 8, glm::vec3(1.0f), 1.0f, 0.0f, false);
    writeFile(dir / "dim.nii", concat(std::string(h.begin(), h.end()), Bytes(8, 0)));
    expectError([&] { loadVolume(dir / "dim.nii"); }, dir / "dim.nii", "dim[2]");
    h = niftiHeader({2, 2, 2}, 2, 8, glm::vec3(1.0f), 1.0f, 0.0f, false);
    float badOffset = 100.0f;
    std::memcpy(h.data() + 108, &badOffset, 4);
    writeFile(dir / "off.nii", concat(std::string(h.begin(), h.end()), Bytes(8, 0)));
    expectError([&] { loadVolume(dir / "off.nii"); }, dir / "off.nii", "vox_offset");
}

TEST(VolumeIo, DimensionsDoNotMatchData) {
    TempDir dir;
    writeFile(dir / "more.nrrd", concat(nrrdHeader("uchar", "4 4 4", "raw"), Bytes(100, 0)));
    expectError([&] { loadVolume(dir / "more.nrrd"); }, dir / "more.nrrd",
                "do not match the data: they need 64 bytes of data, found 100");
    writeFile(dir / "more.gz.nrrd",
              concat(nrrdHeader("uchar", "4 4 4", "gzip"), gzip(Bytes(100, 0))));
    expectError([&] { loadVolume(dir / "more.gz.nrrd"); }, dir / "more.gz.nrrd",
                "do not match the data");
    writeFile(dir / "less.gz.nrrd",
              concat(nrrdHeader("uchar", "4 4 4", "gzip"), gzip(Bytes(50, 0))));
    expectError([&] { loadVolume(dir / "less.gz.nrrd"); }, dir / "less.gz.nrrd",
                "truncated: expected 64 bytes of data, found 50");
    Bytes h = niftiHeader({4, 4, 4}, 2, 8, glm::vec3(1.0f), 1.0f, 0.0f, false);
    writeFile(dir / "more.nii", concat(std::string(h.begin(), h.end()), Bytes(80, 0)));
    expectError([&] { loadVolume(dir / "more.nii"); }, dir / "more.nii", "do not match the data");
}

TEST(VolumeIo, CorruptGzip) {
    TempDir dir;
    Volume v = patterned({16, 16, 16}, glm::vec3(1.0f));
    saveVolume(v, dir / "a.nii.gz");
    Bytes gz = readFile(dir / "a.nii.gz");
    Bytes bad = gz;
    for (size_t i = 20; i < bad.size() - 20; i += 7)
        bad[i] ^= 0x5a;
    writeFile(dir / "bad.nii.gz", bad);
    expectError([&] { loadVolume(dir / "bad.nii.gz"); }, dir / "bad.nii.gz", "gzip");
    Bytes cut(gz.begin(), gz.begin() + std::ptrdiff_t(gz.size() / 2));
    writeFile(dir / "cut.nii.gz", cut);
    expectError([&] { loadVolume(dir / "cut.nii.gz"); }, dir / "cut.nii.gz", "truncated");

    saveVolume(v, dir / "a.nrrd");
    Bytes nrrd = readFile(dir / "a.nrrd");
    nrrd[nrrd.size() - 6] ^= 0xff; // in the CRC32 trailer: a bad checksum must be noticed
    writeFile(dir / "crc.nrrd", nrrd);
    expectError([&] { loadVolume(dir / "crc.nrrd"); }, dir / "crc.nrrd", "corrupt gzip data");
    writeFile(dir / "junk.nrrd", concat(nrrdHeader("uchar", "4 4 4", "gzip"), Bytes(64, 0x33)));
    expectError([&] { loadVolume(dir / "junk.nrrd"); }, dir / "junk.nrrd", "corrupt gzip data");
}

TEST(VolumeIo, SpecOptionsOnFiles) {
    TempDir dir;
    Volume v = patterned({3, 3, 3}, glm::vec3(1.0f));
    saveVolume(v, dir / "a.nrrd");
    EXPECT_EQ(loadVolume(dir / "a.nrrd?spacing=0.2,0.3,0.4").spacing(),
              glm::vec3(0.2f, 0.3f, 0.4f));
    expectError([&] { loadVolume(dir / "a.nrrd?dims=1,2,3"); }, "a.nrrd", "unknown option 'dims'");
    EXPECT_NE(volumeSpecHelp().find("raw:FILE?dims=X,Y,Z"), std::string::npos);
}

// A save that fails part-way (here the file-size limit: EFBIG, as a full disk would) leaves the
// files that were there exactly as they were, and no temporary file behind: the bytes go to
// temporary files beside them, renamed over them only once complete (before, the old file was
// truncated, then deleted).
TEST(VolumeIo, AFailedSaveLeavesTheFilesThatWereThereUntouched) {
    TempDir dir;
    const Volume small = makeSkull(32);
    const Volume big = makeSkull(64);
    auto snapshot = [&] {
        std::map<std::string, Bytes> files;
        for (const auto& e : std::filesystem::directory_iterator(dir.path)) {
            std::ifstream in(e.path(), std::ios::binary);
            files[e.path().filename().string()] =
                Bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
        }
        return files;
    };
    for (const char* name : {"scan.nrrd", "scan.nhdr", "scan.nii", "scan.nii.gz"}) {
        SCOPED_TRACE(name);
        const std::string path = (dir.path / name).string();
        SaveOptions raw;
        raw.compress = false;
        saveVolume(small, path, raw);
        const std::map<std::string, Bytes> before = snapshot();
        size_t largest = 0;
        for (const auto& [file, bytes] : before)
            largest = std::max(largest, bytes.size());
        ASSERT_GT(largest, 1000u);
        // The limit lets the small volume's files through but not the big one's.
        struct rlimit old {};
        ASSERT_EQ(getrlimit(RLIMIT_FSIZE, &old), 0);
        auto* oldHandler = std::signal(SIGXFSZ, SIG_IGN);
        struct rlimit lim = old;
        lim.rlim_cur = rlim_t(largest + 4096);
        ASSERT_EQ(setrlimit(RLIMIT_FSIZE, &lim), 0);
        EXPECT_THROW(saveVolume(big, path, raw), Error);
        setrlimit(RLIMIT_FSIZE, &old);
        std::signal(SIGXFSZ, oldHandler);
        EXPECT_TRUE(snapshot() == before) << "the old files are untouched, nothing else is left";
        EXPECT_EQ(loadVolume(path).dims(), small.dims());
        std::filesystem::remove_all(dir.path);
        std::filesystem::create_directories(dir.path);
    }
}

// A .nhdr's data file OUT.raw is replaced only when it is that header's own: converting a
// headerless scan.raw to scan.nhdr used to overwrite the scan it had just read.
TEST(VolumeIo, ANhdrSaveNeverOverwritesADataFileThatIsNotItsOwn) {
    TempDir dir;
    const std::string scan = (dir.path / "scan.raw").string();
    {
        std::ofstream out(scan, std::ios::binary);
        for (int i = 0; i < 16 * 16 * 16; ++i)
            out.put(char(i % 251));
    }
    const Volume v = loadVolume("raw:" + scan + "?dims=16,16,16");
    SaveOptions raw;
    raw.compress = false;
    const std::string header = (dir.path / "scan.nhdr").string();
    try {
        saveVolume(v, header, raw);
        FAIL() << "expected an error";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("not overwritten"), std::string::npos) << e.what();
    }
    EXPECT_THROW(checkSaveTarget(header, raw), Error);
    EXPECT_FALSE(std::filesystem::exists(header));
    EXPECT_EQ(std::filesystem::file_size(scan), 16u * 16u * 16u) << "the scan is untouched";
    EXPECT_EQ(loadVolume("raw:" + scan + "?dims=16,16,16").densityData()[250], 250);

    // Its own pair is rewritten as often as wanted.
    const std::string mine = (dir.path / "mine.nhdr").string();
    saveVolume(v, mine, raw);
    EXPECT_NO_THROW(checkSaveTarget(mine, raw));
    saveVolume(makeSkull(32), mine, raw);
    EXPECT_EQ(loadVolume(mine).dims(), glm::ivec3(32));

    // Nothing to write to, or no format: refused before any work, nothing written.
    EXPECT_THROW(checkSaveTarget((dir.path / "no-such-folder" / "x.nrrd").string()), Error);
    EXPECT_THROW(checkSaveTarget((dir.path / "x.txt").string()), Error);
    EXPECT_THROW(checkSaveTarget(dir.path.string() + "/"), Error);
    int files = 0;
    for ([[maybe_unused]] const auto& e : std::filesystem::directory_iterator(dir.path))
        ++files;
    EXPECT_EQ(files, 3) << "scan.raw, mine.nhdr, mine.raw";
}

// Spacings from 1 um to 1 m and within 1000x of each other, checked the way they are kept
// (float): a zero or vanishing one (1e-50 became 0) made the burr-site search and the ray caster
// step forever.
TEST(VolumeIo, SpacingsOutsideWhatTrephineCanWorkWithAreRefused) {
    TempDir dir;
    writeFile(dir / "v.raw", Bytes{0, 200});
    const std::string raw = "raw:" + std::string(dir / "v.raw") + "?dims=2,1,1&spacing=";
    for (const char* bad : {"1e-50,1,1", "1,1,1e6", "0.01,1,20", "0,1,1", "inf,1,1"}) {
        SCOPED_TRACE(bad);
        try {
            loadVolume(raw + bad);
            FAIL() << "expected an error";
        } catch (const Error& e) {
            EXPECT_NE(std::string(e.what()).find("spacing"), std::string::npos) << e.what();
            EXPECT_EQ(std::string(e.what()).find('\n'), std::string::npos) << "one line";
        }
    }
    EXPECT_EQ(loadVolume(raw + "0.5,0.5,2").spacing(), glm::vec3(0.5f, 0.5f, 2.0f));
    // A file's own spacing goes through the same check.
    writeFile(dir / "tiny.nrrd",
              concat(nrrdHeader("uchar", "2 1 1", "raw", "spacings: 1e-30 1 1"), Bytes{0, 200}));
    EXPECT_THROW(loadVolume(dir / "tiny.nrrd"), Error);
}

TEST(VolumeIo, NanOrZeroSpacingInAHeaderIsRefusedNotTakenAsOneMillimetre) {
    TempDir dir;
    for (const char* bad : {"nan 1 1", "1 0 1", "1 1 NaN"}) {
        SCOPED_TRACE(bad);
        writeFile(dir / "v.nrrd",
                  concat(nrrdHeader("uchar", "2 1 1", "raw", std::string("spacings: ") + bad),
                         Bytes{0, 200}));
        expectError([&] { loadVolume(dir / "v.nrrd"); }, "v.nrrd", "'spacings' entry");
    }
    for (float bad : {std::numeric_limits<float>::quiet_NaN(), 0.0f}) {
        SCOPED_TRACE(bad);
        Bytes header = niftiHeader({2, 1, 1}, 2, 8, {1.0f, bad, 1.0f}, 1.0f, 0.0f, false);
        writeFile(dir / "v.nii", concat(std::string(header.begin(), header.end()), Bytes{0, 200}));
        expectError([&] { loadVolume(dir / "v.nii"); }, "v.nii", "pixdim[2]");
    }
}

TEST(VolumeIo, APathWithANewlineIsNamedOnOneLine) {
    TempDir dir;
    const std::string path = std::string(dir / "two\nlines.nrrd");
    try {
        loadVolume(path);
        FAIL() << "expected an error";
    } catch (const Error& e) {
        const std::string msg = e.what();
        EXPECT_EQ(msg.find('\n'), std::string::npos) << msg;
        EXPECT_NE(msg.find("two\\nlines.nrrd"), std::string::npos) << msg;
    }
    EXPECT_EQ(oneLine("a\tb\x01"
                      "c\x7f"),
              "a\\tb\\x01c\\x7F");
}

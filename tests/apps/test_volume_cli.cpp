// `trephine volume info|convert` run as a user would: exit codes, output, and one-line errors that
// name the file.
#include "libsim/volume_io.h"

#include "test_support.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#include <unistd.h>

namespace fs = std::filesystem;

namespace {

using namespace trephine::testing;
using Result = CommandResult;

std::string quote(const std::string& s) {
    return "'" + s + "'";
}

} // namespace

TEST(VolumeCli, InfoOfBuiltinSphere) {
    TempDir dir;
    Result r = runTrephine(dir, "volume info sphere:32");
    EXPECT_EQ(r.exitCode, 0) << r.err;
    EXPECT_EQ(r.err, "");
    EXPECT_NE(r.out.find("32 x 32 x 32 voxels"), std::string::npos) << r.out;
    EXPECT_NE(r.out.find("spacing:     1 x 1 x 1 mm"), std::string::npos) << r.out;
    EXPECT_NE(r.out.find("65536"), std::string::npos) << r.out;
    EXPECT_NE(r.out.find("cortical"), std::string::npos) << r.out;
}

TEST(VolumeCli, ConvertWritesALoadableVolume) {
    TempDir dir;
    const std::string out = dir / "sphere.nrrd";
    Result r = runTrephine(dir, "volume convert sphere:32 " + quote(out));
    EXPECT_EQ(r.exitCode, 0) << r.err;
    EXPECT_EQ(r.err, "");
    ASSERT_TRUE(fs::exists(out));
    EXPECT_TRUE(trephine::loadVolume(out) == trephine::loadVolume("sphere:32"));

    Result info = runTrephine(dir, "volume info " + quote(out) + " --spacing 0.5,0.5,0.5");
    EXPECT_EQ(info.exitCode, 0) << info.err;
    EXPECT_NE(info.out.find("extent:      16 x 16 x 16 mm"), std::string::npos) << info.out;
}

TEST(VolumeCli, RawFileWithDimsAndType) {
    TempDir dir;
    const std::string raw = dir / "ct.raw";
    std::ofstream(raw, std::ios::binary).write("\x2c\x01\x84\x03", 4); // int16 300, 900
    Result r = runTrephine(dir, "volume info " + quote(raw) + " --dims 2,1,1 --type int16");
    EXPECT_EQ(r.exitCode, 0) << r.err;
    EXPECT_NE(r.out.find("2 x 1 x 1 voxels"), std::string::npos) << r.out;
}

TEST(VolumeCli, TruncatedFileIsOneLineNamingIt) {
    TempDir dir;
    const std::string bad = dir / "head.nrrd";
    std::ofstream(bad) << "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 64 64 64\n"
                          "encoding: raw\n\nshort";
    for (const std::string& args :
         {"volume info " + quote(bad),
          "volume convert " + quote(bad) + " " + quote(dir / "out.nrrd")}) {
        Result r = runTrephine(dir, args);
        EXPECT_NE(r.exitCode, 0);
        EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
        EXPECT_EQ(r.err.back(), '\n');
        EXPECT_NE(r.err.find(bad), std::string::npos) << r.err;
        EXPECT_NE(r.err.find("truncated"), std::string::npos) << r.err;
    }
    EXPECT_FALSE(fs::exists(dir / "out.nrrd"));
}

TEST(VolumeCli, MissingFileAndBadFlags) {
    TempDir dir;
    const std::string missing = dir / "nope.nii.gz";
    Result r = runTrephine(dir, "volume info " + quote(missing));
    EXPECT_NE(r.exitCode, 0);
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
    EXPECT_NE(r.err.find(missing), std::string::npos) << r.err;

    Result t = runTrephine(dir, "volume info sphere:16 --type int16");
    EXPECT_NE(t.exitCode, 0);
    EXPECT_EQ(std::count(t.err.begin(), t.err.end(), '\n'), 1) << t.err;
    EXPECT_NE(t.err.find("--dims"), std::string::npos) << t.err;

    Result help = runTrephine(dir, "volume info --help");
    EXPECT_EQ(help.exitCode, 0);
    EXPECT_NE(help.out.find("raw:FILE?dims=X,Y,Z"), std::string::npos) << help.out;
}

// `slices:` with no folder failed as ": cannot create folder: Invalid argument", naming nothing,
// and `slices:FILE` said "the folder is not empty" of a file; both are named before the volume
// is read, and the file is left as it was.
TEST(VolumeCli, ConvertToSlicesNamesAMissingOrWrongFolder) {
    TempDir dir;
    Result r = runTrephine(dir, "volume convert sphere:16 slices:");
    EXPECT_EQ(r.exitCode, 1);
    EXPECT_EQ(r.err, "trephine: OUT slices:: name the folder for the slices, e.g. slices:out/\n");

    const std::string file = dir / "head.nrrd";
    std::ofstream(file) << "not slices\n";
    r = runTrephine(dir, "volume convert sphere:16 " + quote("slices:" + file));
    EXPECT_EQ(r.exitCode, 1);
    EXPECT_EQ(r.err, "trephine: OUT slices:" + file + ": " + file +
                         " is a file, not a folder: name a new or empty folder for the slices\n");
    EXPECT_EQ(trephine::testing::slurp(file), "not slices\n");
}

// A corrupt slice in a folder is one line naming it: libpng (inside OpenImageIO) printed its own
// "libpng error: ..." line before ours.
TEST(VolumeCli, ACorruptSliceIsOneLineNamingIt) {
    TempDir dir;
    const std::string folder = dir / "slices";
    ASSERT_EQ(runTrephine(dir, "volume convert sphere:16 slices:" + quote(folder)).exitCode, 0);
    const std::string first = (fs::path(folder) / "slice_0000.png").string();
    std::string bytes = slurp((fs::path(folder) / "slice_0005.png").string());
    std::ofstream(first, std::ios::binary) << bytes.substr(0, 60);
    Result r = runTrephine(dir, "volume info " + quote(folder));
    EXPECT_NE(r.exitCode, 0);
    EXPECT_NE(r.err.find("slice_0000.png"), std::string::npos) << r.err;
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
}

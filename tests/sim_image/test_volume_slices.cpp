// Folders of 2D slices through OpenImageIO: natural order, 8-bit pass-through, 16-bit and float
// through the window, spacing from the spec, and one-line errors for bad folders and images.
#include "libsim/error.h"
#include "libsim_image/volume_slices.h"

#include "test_support.h"

#include <gtest/gtest.h>

#include "image_files.h"

#include <OpenImageIO/imageio.h>

#include <filesystem>
#include <fstream>
#include <functional>
#include <string>
#include <unistd.h>
#include <vector>

namespace fs = std::filesystem;
using namespace trephine;

namespace {

using namespace trephine::testing;
void expectError(const std::function<void()>& f, const std::string& name,
                 const std::string& problem) {
    try {
        f();
        ADD_FAILURE() << "no Error thrown; expected one naming " << name;
    } catch (const Error& e) {
        std::string msg = e.what();
        EXPECT_NE(msg.find(name), std::string::npos) << msg;
        EXPECT_NE(msg.find(problem), std::string::npos) << msg;
        EXPECT_EQ(msg.find('\n'), std::string::npos) << msg;
    }
}

} // namespace

TEST(VolumeSlices, EightBitPngInNaturalOrder) {
    TempDir dir;
    // Names that sort wrongly as plain strings; slice k holds 40 * pixel index + 10 * k.
    const char* names[] = {"img1.png", "img2.png", "img10.png"};
    for (int k = 0; k < 3; ++k) {
        // Two channels: only the first is used.
        std::vector<uint8_t> px;
        for (int i = 0; i < 3 * 2; ++i) {
            px.push_back(uint8_t(40 * i + 10 * k));
            px.push_back(255);
        }
        writeImage(dir / names[k], 3, 2, 2, OIIO::TypeDesc::UINT8, px);
    }
    std::ofstream(dir / "notes.txt") << "not an image";
    std::ofstream(dir / ".hidden.png") << "not an image either";

    Volume v = openVolume(dir.path.string() + "?spacing=0.5,0.5,2");
    ASSERT_EQ(v.dims(), glm::ivec3(3, 2, 3));
    EXPECT_EQ(v.spacing(), glm::vec3(0.5f, 0.5f, 2.0f));
    EXPECT_EQ(v.density(0, 0, 0), 0);
    EXPECT_EQ(v.density(1, 0, 0), 40);
    EXPECT_EQ(v.density(0, 1, 0), 120); // row 1 starts at pixel index 3
    EXPECT_EQ(v.density(0, 0, 1), 10);
    EXPECT_EQ(v.density(0, 0, 2), 20); // img10.png is the last slice
    EXPECT_EQ(v.density(2, 1, 2), 220);
    EXPECT_EQ(v.material(0, 0, 0), Material::Air);
    EXPECT_EQ(v.material(0, 1, 0), Material::Air);
    EXPECT_EQ(v.material(2, 1, 2), Material::Diploe);
}

TEST(VolumeSlices, SixteenBitAndFloatGoThroughTheWindow) {
    TempDir dir;
    const std::vector<uint16_t> s0 = {0, 300, 900, 65535};
    writeImage(dir / "a_0.tif", 2, 2, 1, OIIO::TypeDesc::UINT16, s0);
    writeImage(dir / "a_1.tif", 2, 2, 1, OIIO::TypeDesc::UINT16,
               std::vector<uint16_t>{600, 800, 0, 0});
    Volume v = openVolume("slices:" + dir.path.string());
    ASSERT_EQ(v.dims(), glm::ivec3(2, 2, 2));
    EXPECT_EQ(v.density(0, 0, 0), 64);
    EXPECT_EQ(v.density(1, 0, 0), 128);
    EXPECT_EQ(v.density(0, 1, 0), 255);
    EXPECT_EQ(v.density(1, 1, 0), 255);
    EXPECT_EQ(v.density(0, 0, 1), 191);
    EXPECT_EQ(v.material(1, 0, 1), Material::Cortical);
    Volume w = openVolume("slices:" + dir.path.string() + "?window=0,1200");
    EXPECT_EQ(w.density(1, 0, 0), 64);

    TempDir fdir;
    writeImage(fdir / "f0.exr", 2, 1, 1, OIIO::TypeDesc::FLOAT, std::vector<float>{0.0f, 1.0f});
    Volume f = openVolume(fdir.path.string() + "?window=0,1");
    EXPECT_EQ(f.density(0, 0, 0), 0);
    EXPECT_EQ(f.density(1, 0, 0), 255);
}

TEST(VolumeSlices, SaveAndReadBack) {
    TempDir dir;
    Volume v({5, 4, 12}, glm::vec3(1.0f));
    for (int z = 0; z < 12; ++z)
        for (int y = 0; y < 4; ++y)
            for (int x = 0; x < 5; ++x) {
                uint8_t d = uint8_t(x * 50 + y * 3 + z * 7);
                v.set(x, y, z, d, materialFromDensity(d));
            }
    saveVolumeSlices(v, dir / "out");
    EXPECT_TRUE(fs::exists(dir / "out/slice_0011.png"));
    EXPECT_TRUE(openVolume(dir / "out") == v);
    // Never into a folder that holds something: its slices would be read back with ours, and
    // converting a slice folder onto itself overwrote the original.
    Volume smaller(glm::ivec3(5, 4, 3), glm::vec3(1.0f));
    expectError([&] { saveVolumeSlices(smaller, dir / "out"); }, dir / "out", "not empty");
    EXPECT_TRUE(openVolume(dir / "out") == v) << "the slices there are untouched";
}

TEST(VolumeSlices, DelegatesOtherSpecsToLoadVolume) {
    EXPECT_EQ(openVolume("sphere:16").dims(), glm::ivec3(16));
    expectError([] { openVolume("/no/such/file.nrrd"); }, "/no/such/file.nrrd", "no such file");
}

TEST(VolumeSlices, Errors) {
    TempDir dir;
    expectError([&] { openVolume("slices:" + dir.path.string()); }, dir.path.string(),
                "no image slices");
    expectError([&] { openVolume("slices:" + (dir / "missing")); }, dir / "missing",
                "no such folder");
    expectError([&] { openVolume(dir.path.string() + "?dims=1,2,3"); }, dir.path.string(),
                "unknown option 'dims'");

    writeImage(dir / "s1.png", 4, 4, 1, OIIO::TypeDesc::UINT8, std::vector<uint8_t>(16, 1));
    writeImage(dir / "s2.png", 4, 3, 1, OIIO::TypeDesc::UINT8, std::vector<uint8_t>(12, 1));
    expectError([&] { openVolume(dir.path.string()); }, dir / "s2.png", "same size");

    TempDir bad;
    writeImage(bad / "s1.png", 2, 2, 1, OIIO::TypeDesc::UINT8, std::vector<uint8_t>(4, 1));
    std::ofstream(bad / "s2.png") << "this is not a PNG at all";
    expectError([&] { openVolume(bad.path.string()); }, bad / "s2.png", "cannot read image");

    TempDir mixed;
    writeImage(mixed / "s1.png", 2, 2, 1, OIIO::TypeDesc::UINT8, std::vector<uint8_t>(4, 1));
    writeImage(mixed / "s2.png", 2, 2, 1, OIIO::TypeDesc::UINT16, std::vector<uint16_t>(4, 1));
    expectError([&] { openVolume(mixed.path.string()); }, mixed / "s2.png", "pixel type");
}

// A dangling link among the slices (a moved scan's leftovers) is skipped like any non-image; listed
// last, it failed the whole folder as "cannot list folder: No such file or directory".
TEST(VolumeSlices, ADanglingLinkAmongTheSlicesIsSkipped) {
    TempDir dir;
    for (int k = 0; k < 3; ++k)
        writeImage(dir / (std::to_string(k) + ".png"), 2, 2, 1, OIIO::TypeDesc::UINT8,
                   std::vector<uint8_t>(4, uint8_t(50 * k)));
    // Links named as slices, until one is listed last (the order is the file system's).
    auto lastListedIsALink = [&] {
        fs::path last;
        for (const fs::directory_entry& e : fs::directory_iterator(dir.path))
            last = e.path();
        return fs::is_symlink(last);
    };
    for (int i = 0; i < 200 && !lastListedIsALink(); ++i)
        fs::create_symlink(dir.path / "gone", dir.path / std::to_string(1000 + i).append(".png"));
    ASSERT_TRUE(lastListedIsALink());
    Volume v = openVolume(dir.path.string());
    EXPECT_EQ(v.dims(), glm::ivec3(2, 2, 3));
    EXPECT_EQ(v.density(1, 1, 2), 100);
}

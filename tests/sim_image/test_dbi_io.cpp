// DBI files: EXR round trips keep every channel (depth bit for bit), files are top-down, a
// rectangle keeps its place in the frame, and files that are not DBIs fail with one clear line.
#include "libsim_image/dbi_io.h"

#include "libsim/error.h"

#include <OpenImageIO/imageio.h>
#include <csignal>
#include <filesystem>
#include <fstream>
#include <gtest/gtest.h>
#include <random>
#include <sys/resource.h>

namespace trephine {
namespace {

namespace fs = std::filesystem;

class DbiIo : public ::testing::Test {
protected:
    void SetUp() override {
        m_dir = fs::temp_directory_path() /
                ("trephine_dbi_io_" +
                 std::to_string(::testing::UnitTest::GetInstance()->random_seed()) + "_" +
                 ::testing::UnitTest::GetInstance()->current_test_info()->name());
        fs::create_directories(m_dir);
    }
    void TearDown() override { fs::remove_all(m_dir); }
    std::string path(const std::string& name) const { return (m_dir / name).string(); }

    fs::path m_dir;
};

// Every colour value and awkward depths: 0, 1 (background), values near 1, tiny ones.
Dbi randomDbi(int w, int h, uint32_t seed) {
    Dbi d(w, h);
    std::mt19937 rng(seed);
    std::uniform_int_distribution<int> byte(0, 255);
    std::uniform_real_distribution<float> depth(0.0f, 1.0f);
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
            uint8_t* c = d.color(x, y);
            for (int i = 0; i < 4; ++i)
                c[i] = uint8_t(byte(rng));
            float z = depth(rng);
            if ((x + y) % 7 == 0)
                z = 1.0f;
            if ((x + y) % 11 == 0)
                z = std::nextafter(1.0f, 0.0f);
            if ((x * y) % 13 == 5)
                z = 1e-30f;
            d.depth()[d.index(x, y)] = z;
        }
    for (int i = 0; i < 256; ++i) // all 256 values in the red channel
        d.color(i % w, (i / w) % h)[0] = uint8_t(i);
    return d;
}

TEST_F(DbiIo, ExrRoundTripKeepsEveryChannelBitForBit) {
    Dbi d = randomDbi(37, 23, 5);
    writeDbiExr(path("frame.exr"), d);
    DbiFile back = readDbiExr(path("frame.exr"));
    EXPECT_EQ(back.frameWidth, 37);
    EXPECT_EQ(back.frameHeight, 23);
    EXPECT_EQ(back.rectInFrame, (PixelRect{0, 0, 37, 23}));
    EXPECT_TRUE(back.image == d) << compare(back.image, d).describe();
}

TEST_F(DbiIo, ExrHasChannelsRGBAZWithFloatDepthAndTopRowFirst) {
    Dbi d(4, 3);
    d.color(0, 2)[0] = 255; // top-left pixel: red
    d.depth()[d.index(0, 2)] = 0.25f;
    d.depth()[d.index(0, 0)] = 0.75f; // bottom-left
    writeDbiExr(path("f.exr"), d);
    auto in = OIIO::ImageInput::open(path("f.exr"));
    ASSERT_TRUE(in);
    const OIIO::ImageSpec& spec = in->spec();
    std::vector<std::string> names(spec.channelnames.begin(), spec.channelnames.end());
    EXPECT_EQ(names, (std::vector<std::string>{"R", "G", "B", "A", "Z"}));
    EXPECT_EQ(spec.channelformat(4), OIIO::TypeDesc::FLOAT);
    EXPECT_EQ(spec.z_channel, 4);
    std::vector<float> px(4 * 3 * 5);
    ASSERT_TRUE(in->read_image(0, 0, 0, 5, OIIO::TypeDesc::FLOAT, px.data()));
    EXPECT_EQ(px[0], 1.0f);              // file row 0 = top row: red
    EXPECT_EQ(px[4], 0.25f);             // and its depth
    EXPECT_EQ(px[2 * 4 * 5 + 4], 0.75f); // file's last row = DBI row 0
}

TEST_F(DbiIo, RectangleSitsAtItsPlaceInTheFullFrame) {
    Dbi part = randomDbi(20, 10, 9);
    PixelRect rect{30, 5, 20, 10}; // rows 5..14 from the bottom of a 100 x 60 frame
    writeDbiExr(path("rect.exr"), part, rect, 100, 60);
    auto in = OIIO::ImageInput::open(path("rect.exr"));
    ASSERT_TRUE(in);
    EXPECT_EQ(in->spec().x, 30);
    EXPECT_EQ(in->spec().y, 60 - 15); // top-down: the rectangle's top row is row 45 from the top
    EXPECT_EQ(in->spec().width, 20);
    EXPECT_EQ(in->spec().full_width, 100);
    EXPECT_EQ(in->spec().full_height, 60);
    in.reset();
    DbiFile back = readDbiExr(path("rect.exr"));
    EXPECT_EQ(back.rectInFrame, rect);
    EXPECT_EQ(back.frameWidth, 100);
    EXPECT_EQ(back.frameHeight, 60);
    EXPECT_TRUE(back.image == part);
}

TEST_F(DbiIo, PngIsColourTopRowFirst) {
    Dbi d(3, 2);
    d.color(2, 1)[1] = 200; // top-right pixel: green channel
    writeColorPng(path("c.png"), d);
    auto in = OIIO::ImageInput::open(path("c.png"));
    ASSERT_TRUE(in);
    EXPECT_EQ(in->spec().nchannels, 3);
    std::vector<uint8_t> px(3 * 2 * 3);
    ASSERT_TRUE(in->read_image(0, 0, 0, 3, OIIO::TypeDesc::UINT8, px.data()));
    EXPECT_EQ(px[2 * 3 + 1], 200);
    EXPECT_EQ(px[3 * 3 + 2 * 3 + 1], kBackgroundRgba[1]);
}

void expectOneLineError(const std::function<void()>& f, const std::string& mention) {
    try {
        f();
        ADD_FAILURE() << "expected trephine::Error";
    } catch (const Error& e) {
        std::string msg = e.what();
        EXPECT_NE(msg.find(mention), std::string::npos) << msg;
        EXPECT_EQ(msg.find('\n'), std::string::npos) << msg;
    }
}

// A write that fails part way (here: the process may not grow a file past 4 KiB, as on a full
// disk) leaves the earlier EXR and PNG of that name whole, and no temporary file behind; it used
// to have truncated them already.
TEST_F(DbiIo, AWriteThatFailsLeavesTheEarlierFileWhole) {
    const Dbi small = randomDbi(8, 8, 1), big = randomDbi(256, 256, 2);
    const std::string exr = path("kept.exr"), png = path("kept.png");
    writeDbiExr(exr, small);
    writeColorPng(png, small);
    const auto exrBytes = fs::file_size(exr), pngBytes = fs::file_size(png);
    rlimit old{};
    ASSERT_EQ(getrlimit(RLIMIT_FSIZE, &old), 0);
    const auto oldHandler = std::signal(SIGXFSZ, SIG_IGN);
    rlimit tight = old;
    tight.rlim_cur = 4096;
    ASSERT_EQ(setrlimit(RLIMIT_FSIZE, &tight), 0);
    bool exrThrew = false, pngThrew = false;
    try {
        writeDbiExr(exr, big);
    } catch (const Error&) {
        exrThrew = true;
    }
    try {
        writeColorPng(png, big);
    } catch (const Error&) {
        pngThrew = true;
    }
    setrlimit(RLIMIT_FSIZE, &old);
    std::signal(SIGXFSZ, oldHandler);
    EXPECT_TRUE(exrThrew);
    EXPECT_TRUE(pngThrew);
    EXPECT_EQ(fs::file_size(exr), exrBytes);
    EXPECT_EQ(fs::file_size(png), pngBytes);
    EXPECT_EQ(readDbiExr(exr).image.width(), 8);
    int files = 0;
    for (const auto& e : fs::directory_iterator(m_dir))
        files += e.is_regular_file();
    EXPECT_EQ(files, 2) << "no temporary file left";
    // And a write that succeeds replaces the file.
    writeColorPng(png, big);
    EXPECT_GT(fs::file_size(png), pngBytes);
}

TEST_F(DbiIo, FilesThatAreNotDbisAreOneLineErrors) {
    expectOneLineError([&] { readDbiExr(path("missing.exr")); }, "no such file");

    writeColorPng(path("colour.png"), Dbi(4, 4));
    expectOneLineError([&] { readDbiExr(path("colour.png")); }, "not OpenEXR");

    { // An EXR with colour only.
        OIIO::ImageSpec spec(4, 4, 3, OIIO::TypeDesc::FLOAT);
        std::vector<float> px(4 * 4 * 3, 0.5f);
        auto out = OIIO::ImageOutput::create(path("rgb.exr"));
        ASSERT_TRUE(out && out->open(path("rgb.exr"), spec));
        ASSERT_TRUE(out->write_image(OIIO::TypeDesc::FLOAT, px.data()));
        out->close();
    }
    expectOneLineError([&] { readDbiExr(path("rgb.exr")); }, "no Z channel");

    { // Garbage with the right name, and a truncated real EXR.
        std::ofstream(path("garbage.exr")) << "this is not an image\n";
        writeDbiExr(path("whole.exr"), randomDbi(64, 64, 1));
        auto size = fs::file_size(path("whole.exr"));
        fs::copy_file(path("whole.exr"), path("cut.exr"));
        fs::resize_file(path("cut.exr"), size / 2);
    }
    expectOneLineError([&] { readDbiExr(path("garbage.exr")); }, "garbage.exr");
    expectOneLineError([&] { readDbiExr(path("cut.exr")); }, "cut.exr");

    expectOneLineError([&] { writeDbiExr(path("frame.png"), Dbi(2, 2)); }, ".exr");
    expectOneLineError([&] { writeDbiExr(path("no/such/dir/f.exr"), Dbi(2, 2)); }, "f.exr");
}

} // namespace
} // namespace trephine

// `trephine demo` windowed, end to end: an embedded server, the trainee window over loopback, a
// scripted burr hole, and the screenshot it writes. Needs a display (xvfb-run).
#include "gl_window_test.h"
#include "ui/window.h"

#include "screenshot.h"
#include "test_support.h"
#include <OpenImageIO/imageio.h>

#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <sys/wait.h>
#include <vector>

namespace {

using trephine::testing::Image;
using trephine::testing::readPng;
using trephine::testing::shellQuote;

bool boneColoured(const uint8_t* p) {
    return p[0] > 150 && p[1] > 140 && p[2] > 110 && p[0] >= p[2] && p[0] - p[2] < 90;
}

std::string shoot(const std::string& name, const std::string& extra) {
    std::string out = (std::filesystem::temp_directory_path() / name).string();
    std::filesystem::remove(out);
    std::string cmd = shellQuote(TREPHINE_BIN) + " demo --volume skull:128 --tilt 0 --screenshot " +
                      shellQuote(out) + " --frames 3 --timeout 80 " + extra + " > " +
                      shellQuote(out + ".log") + " 2>&1";
    int rc = std::system(cmd.c_str());
    EXPECT_EQ(rc, 0) << cmd;
    return out;
}

} // namespace

TEST(DemoWindow, ScreenshotShowsBoneTheDrilledHoleAndPanels) {
    TREPHINE_NEED_DISPLAY("the demo window");
    Image plain = readPng(shoot("trephine_demo_plain.png", ""));
    Image drilled = readPng(shoot("trephine_demo_drilled.png", "--script burrhole"));
    ASSERT_EQ(plain.w, 1280);
    ASSERT_EQ(plain.h, 900);
    ASSERT_EQ(drilled.w, plain.w);
    ASSERT_EQ(drilled.h, plain.h);
    // The view is 500x500 at the top left, looking straight at the burr site (its centre): the
    // default working angle tilted off (--tilt 0), so the ring below is all exposed bone.
    const int cx = 250, cy = 250;
    int ring = 0, ringBone = 0, centre = 0, centreBonePlain = 0, centreChanged = 0;
    for (int y = 0; y < 500; ++y)
        for (int x = 0; x < 500; ++x) {
            double r = std::hypot(x + 0.5 - cx, y + 0.5 - cy);
            if (r > 80 && r < 100 && x > cx) { // exposed bone, away from where the drill rests
                ++ring;
                ringBone += boneColoured(plain.at(x, y));
            }
            if (r < 12) {
                ++centre;
                centreBonePlain += boneColoured(plain.at(x, y));
                const uint8_t *a = plain.at(x, y), *b = drilled.at(x, y);
                int d =
                    std::max({std::abs(a[0] - b[0]), std::abs(a[1] - b[1]), std::abs(a[2] - b[2])});
                centreChanged += d > 30;
            }
        }
    EXPECT_GT(ringBone, ring * 8 / 10) << "bone-coloured pixels where the skull is exposed";
    EXPECT_GT(centreBonePlain, centre * 9 / 10) << "intact bone at the site before drilling";
    EXPECT_GT(centreChanged, centre / 2) << "the drilled hole at the site";
    // Panels: ImGui text (bright pixels) in the right-hand column and under the view.
    int bright = 0;
    for (int y = 0; y < drilled.h; ++y)
        for (int x = 500; x < drilled.w; ++x)
            bright += drilled.at(x, y)[0] > 200 && drilled.at(x, y)[1] > 200;
    EXPECT_GT(bright, 1000) << "panel text in the right-hand column";
}

// A display whose X server has no OpenGL (no GLX: ssh -X to some servers) let the demo commit to
// the window, start its server, say "trainee window connected", then fail with exit 1: it runs
// the headless demo instead, saying why. Its own X server (xvfb-run -a with GLX off).
TEST(DemoWindow, ADisplayWithoutOpenGlRunsTheHeadlessDemo) {
    if (std::system("command -v xvfb-run > /dev/null 2>&1") != 0)
        GTEST_SKIP() << "xvfb-run is not installed";
    trephine::testing::TempDir dir;
    const std::string log = dir / "demo.log";
    const std::string cmd = "xvfb-run -a -s '-screen 0 640x480x24 -extension GLX' " +
                            shellQuote(TREPHINE_BIN) + " demo --frames 3 > " + shellQuote(log) +
                            " 2>&1";
    const int rc = std::system(cmd.c_str());
    const std::string out = trephine::testing::slurp(log);
    ASSERT_TRUE(WIFEXITED(rc)) << out;
    EXPECT_EQ(WEXITSTATUS(rc), 0) << out;
    EXPECT_NE(out.find("demo: no window (no OpenGL 3.3 core context"), std::string::npos) << out;
    EXPECT_NE(out.find("running the headless demo"), std::string::npos) << out;
    EXPECT_EQ(out.find("trainee window connected"), std::string::npos) << out;
}

// Headless, the demo shows the product: an embedded server and the headless trainee core over
// loopback drill the burr hole; it prints the session's figures and writes the trainee's final
// picture, which shows the hole's dura where the burr site is (the view looks at the site).
TEST(DemoWindow, TheHeadlessDemoRunsASessionOverLoopbackAndWritesItsPicture) {
    trephine::testing::TempDir dir;
    const std::string png = dir / "demo.png";
    const auto r =
        trephine::testing::runTrephine(dir, "demo --headless --picture " + shellQuote(png));
    ASSERT_EQ(r.exitCode, 0) << r.out << r.err;
    for (const char* line :
         {"session  server on 127.0.0.1:", "trainee joined as client", "image updates",
          "latency p50", "KB/s of image updates", "tool states sent", "haptics  ",
          "force round trip", "forces   peak |F| felt", "result   the drill stopped cutting",
          "picture  "})
        EXPECT_NE(r.out.find(line), std::string::npos) << line << "\n" << r.out;
    const auto at = r.out.find("\nupdates  ");
    ASSERT_NE(at, std::string::npos) << r.out;
    EXPECT_GT(std::stoll(r.out.substr(at + 10)), 10) << r.out; // drilling sent many updates
    const auto hz = r.out.find("\nhaptics  ");
    ASSERT_NE(hz, std::string::npos) << r.out;
    EXPECT_GT(std::stod(r.out.substr(hz + 10)), 500.0) << r.out; // the 1 kHz loop ran
    const trephine::testing::Image img = trephine::testing::readPng(png);
    ASSERT_EQ(img.w, 400);
    ASSERT_EQ(img.h, 400);
    // Dura is red, bone is cream: red pixels in the middle of the picture, few at its edge.
    auto reddish = [&](int x0, int y0, int n) {
        int count = 0;
        for (int y = y0; y < y0 + n; ++y)
            for (int x = x0; x < x0 + n; ++x)
                count += int(img.at(x, y)[0]) - int(img.at(x, y)[1]) > 40;
        return count;
    };
    EXPECT_GT(reddish(160, 160, 80), 400) << "the hole at the site";
    EXPECT_LT(reddish(0, 0, 80), 40) << "no hole in the corner";
}

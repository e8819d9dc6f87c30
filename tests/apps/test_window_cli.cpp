// Windowed-mode flags checked before anything connects: one line naming what is wrong.
#include "test_support.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <string>

using trephine::testing::CommandResult;
using trephine::testing::runTrephine;
using trephine::testing::shellQuote;
using trephine::testing::TempDir;

TEST(WindowCli, AHeadlessTraineeHasNoScreenshot) {
    TempDir dir;
    CommandResult r = runTrephine(dir, "trainee --connect 127.0.0.1:9 --headless --screenshot '" +
                                           dir / "x.png" + "'");
    EXPECT_NE(r.exitCode, 0);
    EXPECT_NE(r.err.find("--screenshot"), std::string::npos) << r.err;
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
}

// Options only a --headless trainee uses are refused by the trainee window, in one line naming
// the option, before any window opens: the window ran without them (no report written, no script
// run, no end after --duration, the default view instead of --camera).
TEST(WindowCli, TheTraineeWindowRefusesOptionsOnlyAHeadlessTraineeUses) {
    TempDir dir;
    for (const std::string& option :
         {"--report " + shellQuote(dir / "r.json"), std::string("--script burrhole"),
          std::string("--camera top"), std::string("--duration 5"),
          "--save-dbi " + shellQuote(dir / "d.exr"), std::string("--tool-rate 50")}) {
        SCOPED_TRACE(option);
        // --frames 1: were the option ignored with a display, the window would end after a frame.
        CommandResult r =
            runTrephine(dir, "trainee --connect 127.0.0.1:9 --size 64 --frames 1 " + option);
        EXPECT_NE(r.exitCode, 0);
        const std::string flag = option.substr(0, option.find(' '));
        EXPECT_NE(r.err.find(flag + ": only a --headless trainee uses it"), std::string::npos)
            << r.err;
        EXPECT_EQ(r.err.find('\n'), r.err.size() - 1) << "one line: " << r.err;
    }
}

// The demo falls back to its headless run without a display; with --screenshot it exited 0
// without writing the picture asked for. Now one line says why there is none.
TEST(WindowCli, TheDemoRefusesAScreenshotItCannotTake) {
    TempDir dir;
    const std::string shot = dir / "demo.png";
    CommandResult r =
        runTrephine(dir, "demo --headless --frames 1 --screenshot " + shellQuote(shot));
    EXPECT_EQ(r.exitCode, 1);
    EXPECT_EQ(r.err.rfind("trephine: --screenshot: ", 0), 0u) << r.err;
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
    EXPECT_FALSE(std::filesystem::exists(shot));

    // No display at all (DISPLAY unset for this run): the same, where the demo used to drill
    // headless and exit 0.
    {
        const trephine::testing::ScopedEnv noDisplay("DISPLAY", std::nullopt);
        r = runTrephine(dir, "demo --frames 1 --screenshot " + shellQuote(shot));
    }
    EXPECT_EQ(r.exitCode, 1);
    EXPECT_NE(r.err.find("trephine: --screenshot: no window to take it from: no DISPLAY is set"),
              std::string::npos)
        << r.err;
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
    EXPECT_FALSE(std::filesystem::exists(shot));
}

// An unknown --view was met only once the volume had arrived: the window then ran on without a
// picture (with --screenshot, until --timeout said only "without a settled view").
TEST(WindowCli, AnUnknownViewIsRefusedWithTheChoices) {
    TempDir dir;
    for (const char* mode : {"instructor --connect 127.0.0.1:9", "demo"}) {
        SCOPED_TRACE(mode);
        CommandResult r = runTrephine(dir, std::string(mode) + " --view nowhere --frames 1");
        EXPECT_NE(r.exitCode, 0);
        EXPECT_NE(r.err.find("--view: nowhere not in {site,paper,working,"), std::string::npos)
            << r.err;
        EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
    }
}

// --frames without a screenshot counts frames showing the picture: with no server there is none,
// and by --timeout the window says so in one line and exits 1 (it exited 0 after N frames of
// "connecting", which a scripted run took for success). Without a display there is no window to
// run at all, which is a failure too.
TEST(WindowCli, FramesWithoutAnyPictureFailByTheTimeout) {
    TempDir dir;
    CommandResult r =
        runTrephine(dir, "trainee --connect 127.0.0.1:9 --size 64 --frames 3 --timeout 1");
    EXPECT_EQ(r.exitCode, 1) << r.err;
    if (std::getenv("DISPLAY")) {
        EXPECT_NE(r.err.find("no picture from 127.0.0.1:9 after"), std::string::npos) << r.err;
        EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
    }
}

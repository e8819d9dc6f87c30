// Windowed-mode flags checked before anything connects: one line naming what is wrong.
#include "test_support.h"

#include <gtest/gtest.h>

#include <algorithm>
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

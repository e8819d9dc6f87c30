// Windowed-mode flags checked before anything connects: one line naming what is wrong.
#include "test_support.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <string>

using trephine::testing::CommandResult;
using trephine::testing::runTrephine;
using trephine::testing::TempDir;

TEST(WindowCli, AHeadlessTraineeHasNoScreenshot) {
    TempDir dir;
    CommandResult r = runTrephine(dir, "trainee --connect 127.0.0.1:9 --headless --screenshot '" +
                                           dir / "x.png" + "'");
    EXPECT_NE(r.exitCode, 0);
    EXPECT_NE(r.err.find("--screenshot"), std::string::npos) << r.err;
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
}

// `trephine trainee` without --headless opens the trainee window and keeps it open: with no
// --screenshot and no --frames it runs until it is closed (here: until `timeout` stops it), even
// while the server it names cannot be reached. Needs a display (xvfb-run).
#include "gl_window_test.h"
#include "ui/window.h"

#include "test_support.h"

#include <gtest/gtest.h>

#include <cstdlib>
#include <string>
#include <sys/wait.h>

TEST(TraineeWindow, StaysOpenWithoutAScreenshot) {
    TREPHINE_NEED_DISPLAY("the trainee window");
    // Port 9 (discard): nothing answers, so the window keeps retrying.
    const std::string cmd = "timeout 4 '" + std::string(TREPHINE_BIN) +
                            "' trainee --connect 127.0.0.1:9 --size 128 > /dev/null 2>&1";
    const int rc = std::system(cmd.c_str());
    ASSERT_TRUE(WIFEXITED(rc)) << cmd;
    EXPECT_EQ(WEXITSTATUS(rc), 124) << "the window closed by itself before `timeout` stopped it";
}

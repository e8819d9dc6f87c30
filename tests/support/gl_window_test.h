// A GoogleTest fixture with a hidden 256 x 256 GLFW window (OpenGL 3.3 core, no ImGui) current on
// the test's thread, or a skip when no display exists (run under xvfb-run, as ctest does).
#pragma once

#include "ui/window.h"

#include <gtest/gtest.h>

#include <cstdlib>
#include <memory>
#include <string>

// For a GUI test: skips it where no display is set at all (a developer's terminal), and fails it
// where one is set but OpenGL cannot start: under xvfb-run (./scripts/test, CI) a GUI test must
// run, never pass by skipping. `what` names the display's use in the message.
#define TREPHINE_NEED_DISPLAY(what)                                                                \
    do {                                                                                           \
        std::string whyNoDisplay_;                                                                 \
        if (!::trephine::ui::displayAvailable(&whyNoDisplay_)) {                                   \
            const char* display_ = std::getenv("DISPLAY");                                         \
            if (display_ && *display_)                                                             \
                FAIL() << "DISPLAY is set but " << (what) << " cannot start: " << whyNoDisplay_;   \
            GTEST_SKIP() << "no display for " << (what) << " (" << whyNoDisplay_                   \
                         << "); run under xvfb-run";                                               \
        }                                                                                          \
    } while (0)

namespace trephine::testing {

class GlWindowTest : public ::testing::Test {
protected:
    void SetUp() override {
        TREPHINE_NEED_DISPLAY("OpenGL");
        ui::WindowConfig wc;
        wc.width = wc.height = 256;
        wc.visible = false;
        wc.imgui = false;
        window = std::make_unique<ui::Window>(wc);
    }
    void TearDown() override { window.reset(); }
    std::unique_ptr<ui::Window> window;
};

} // namespace trephine::testing

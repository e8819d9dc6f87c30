// A GoogleTest fixture with a hidden 256 x 256 GLFW window (OpenGL 3.3 core, no ImGui) current on
// the test's thread, or a skip when no display exists (run under xvfb-run, as ctest does). And
// whilePumping: a window (or a child) that blocks, run while the test's thread pumps the server.
#pragma once

#include "ui/window.h"

#include "loopback.h"

#include <gtest/gtest.h>

#include <chrono>
#include <cstdlib>
#include <future>
#include <memory>
#include <string>
#include <type_traits>

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

// Runs `blocking` (runTrainerWindow, a trephine child, a wait on a client thread) on a thread of
// its own while this thread pumps the servers it pumps (Pumped), and gives what it returned or
// throws what it threw: a window that blocks its caller still talks to a pumped server.
template <class F>
std::invoke_result_t<F&> whilePumping(F blocking) {
    std::future<std::invoke_result_t<F&>> done =
        std::async(std::launch::async, std::move(blocking));
    while (done.wait_for(std::chrono::microseconds(500)) != std::future_status::ready)
        Pumped::pumpAll();
    return done.get();
}

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

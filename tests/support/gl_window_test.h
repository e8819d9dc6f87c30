// A GoogleTest fixture with a hidden 256 x 256 GLFW window (OpenGL 3.3 core, no ImGui) current on
// the test's thread, or a skip when no display exists (run under xvfb-run, as ctest does).
#pragma once

#include "ui/window.h"

#include <gtest/gtest.h>

#include <memory>
#include <string>

namespace trephine::testing {

class GlWindowTest : public ::testing::Test {
protected:
    void SetUp() override {
        std::string why;
        if (!ui::displayAvailable(&why))
            GTEST_SKIP() << "no display for OpenGL (" << why << "); run under xvfb-run";
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

// The GPU tests' fixture: one EGL context (no display) for the whole binary, or a skip that says
// why there is none. With TREPHINE_NEED_EGL set (scripts/gpu-check) a missing context fails.
#pragma once

#include "libsim_gpu/egl_context.h"

#include <gtest/gtest.h>

#include <cstdlib>
#include <memory>
#include <string>

namespace trephine::testing {

class GpuTest : public ::testing::Test {
protected:
    void SetUp() override {
        std::string why;
        egl = gpu::EglContext::shared(&why);
        if (egl)
            return;
        if (std::getenv("TREPHINE_NEED_EGL"))
            FAIL() << "TREPHINE_NEED_EGL is set but EGL gives no context: " << why;
        GTEST_SKIP() << "no OpenGL through EGL here (" << why << ")";
    }
    std::shared_ptr<gpu::EglContext> egl;
};

} // namespace trephine::testing

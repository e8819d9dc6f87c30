// `trephine study display`'s measurement on llvmpipe (needs a display: xvfb-run), with a small
// window and few frames: both designs measured, positive rates, the GL renderer named. Speeds are
// the benchmark's business (benchmark_ui), never asserted here. A suite of its own (built with
// the GUI only), so that test_study starts without GL and OpenImageIO.
#include "study/display_study.h"

#include "gl_window_test.h"
#include "libsim/error.h"
#include "test_support.h"

#include <gtest/gtest.h>

#include <cstdlib>
#include <string>

using namespace trephine;
using namespace trephine::study;

TEST(DisplayStudy, MeasuresBothDesignsInOneRun) {
    TREPHINE_NEED_DISPLAY("OpenGL");
    DisplayStudyConfig c;
    c.windowPx = 160;
    c.volumeSizes = {64, 96};
    c.dbiFrames = 8;
    c.volumeFrames = 3;
    c.warmupFrames = 1;
    DisplayStudyResult r = measureDisplayRates(c);
    EXPECT_FALSE(r.glRenderer.empty());
    EXPECT_FALSE(r.glVersion.empty());
    EXPECT_NE(r.cameraDescription.find("160x160"), std::string::npos) << r.cameraDescription;
    EXPECT_EQ(r.dbi.method, "dbi");
    EXPECT_EQ(r.dbi.frames, 8);
    EXPECT_GT(r.dbi.medianMs, 0.0);
    EXPECT_GE(r.dbi.p99Ms, r.dbi.medianMs);
    EXPECT_GT(r.dbi.fps, 0.0);
    ASSERT_EQ(r.volume.size(), 2u);
    for (size_t i = 0; i < r.volume.size(); ++i) {
        EXPECT_EQ(r.volume[i].method, "volume");
        EXPECT_EQ(r.volume[i].volumeSize, c.volumeSizes[i]);
        EXPECT_EQ(r.volume[i].frames, 3);
        EXPECT_GT(r.volume[i].fps, 0.0);
        EXPECT_GE(r.volume[i].p99Ms, r.volume[i].medianMs);
        EXPECT_GT(r.ratio(i), 0.0);
    }
}

TEST(DisplayStudy, BadConfigurationIsOneLineError) {
    DisplayStudyConfig c;
    c.volumeSizes.clear();
    try {
        measureDisplayRates(c);
        FAIL() << "no volume size must be refused";
    } catch (const Error& e) {
        std::string m = e.what();
        EXPECT_EQ(m.find('\n'), std::string::npos);
        EXPECT_NE(m.find("volume size"), std::string::npos) << m;
    }
}

TEST(DisplayStudy, WithoutADisplayItSaysToUseXvfb) {
    const trephine::testing::ScopedEnv display("DISPLAY", std::nullopt);
    const trephine::testing::ScopedEnv wayland("WAYLAND_DISPLAY", std::nullopt);
    DisplayStudyConfig c;
    std::string message;
    try {
        measureDisplayRates(c);
    } catch (const Error& e) {
        message = e.what();
    }
    EXPECT_NE(message.find("xvfb-run"), std::string::npos) << message;
    EXPECT_EQ(message.find('\n'), std::string::npos);
}

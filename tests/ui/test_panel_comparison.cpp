// The Comparison panel's model (ComparisonHistory, without GL) and the panel itself drawn under
// Xvfb: the toggle flips the design when clicked, and the panel shows text and plots.
#include "gl_window_test.h"
#include "ui/panel_data.h"
#include "ui/panels.h"
#include "ui/window.h"

#include <gtest/gtest.h>
#include <imgui/imgui.h>

#include <memory>

using namespace trephine;
using namespace trephine::ui;

namespace {
ComparisonFigures figures(double k) {
    ComparisonFigures f;
    f.updatesPerS = 10 * k;
    f.bytesPerUpdate = 1000 * k;
    f.rawBytesPerUpdate = 4000 * k;
    f.latencyP50Ms = 2 * k;
    f.latencyP99Ms = 5 * k;
    f.frameMs = 7 * k;
    f.hapticHz = 1000 * k;
    return f;
}
} // namespace

TEST(ComparisonHistory, KeepsEachDesignsFiguresWhileTheOtherRuns) {
    ComparisonHistory h;
    h.seriesLength = 4;
    EXPECT_FALSE(h.measured(SyncDesign::Dbi));
    EXPECT_EQ(h.ageS(SyncDesign::Volume, 1.0), -1.0);
    EXPECT_EQ(h.ratio(&ComparisonFigures::updatesPerS), 0.0);
    for (int i = 1; i <= 6; ++i)
        h.record(SyncDesign::Dbi, double(i), figures(i));
    EXPECT_EQ(h.active, SyncDesign::Dbi);
    const auto& dbi = h.series(SyncDesign::Dbi);
    ASSERT_EQ(dbi.updatesPerS.size(), 4u); // capped, oldest dropped
    EXPECT_FLOAT_EQ(dbi.updatesPerS.front(), 30.0f);
    EXPECT_FLOAT_EQ(dbi.updatesPerS.back(), 60.0f);
    EXPECT_FLOAT_EQ(dbi.rawBytesPerUpdate.back(), 24000.0f);
    EXPECT_EQ(dbi.points, 6u);
    // Switch: the volume design runs, DBI's last figures stay as they were.
    h.record(SyncDesign::Volume, 7.0, figures(0.5));
    h.record(SyncDesign::Volume, 8.0, figures(0.25));
    EXPECT_EQ(h.active, SyncDesign::Volume);
    EXPECT_EQ(h.series(SyncDesign::Volume).updatesPerS.size(), 2u);
    EXPECT_EQ(h.series(SyncDesign::Dbi).last.frameMs, 42.0);
    EXPECT_EQ(h.series(SyncDesign::Dbi).updatesPerS.size(), 4u);
    EXPECT_DOUBLE_EQ(h.ageS(SyncDesign::Dbi, 9.5), 3.5);
    EXPECT_DOUBLE_EQ(h.ageS(SyncDesign::Volume, 9.5), 1.5);
    EXPECT_DOUBLE_EQ(h.ratio(&ComparisonFigures::updatesPerS), 60.0 / 2.5);
    // A second without updates (-1 bytes and latencies) keeps the last second that had updates,
    // in the table and in the plots (a 0 there read "0.0 ms" beside the table's figure). A
    // design whose first second had none stays unknown (plotted as 0, captioned "-").
    ComparisonFigures none = figures(1);
    none.latencyP50Ms = none.latencyP99Ms = none.bytesPerUpdate = none.rawBytesPerUpdate = -1;
    h.record(SyncDesign::Dbi, 10.0, none);
    const auto& d = h.series(SyncDesign::Dbi);
    EXPECT_FLOAT_EQ(d.latencyP50Ms.back(), float(figures(6).latencyP50Ms));
    EXPECT_FLOAT_EQ(d.latencyP99Ms.back(), float(figures(6).latencyP99Ms));
    EXPECT_FLOAT_EQ(d.bytesPerUpdate.back(), float(figures(6).bytesPerUpdate));
    EXPECT_FLOAT_EQ(d.updatesPerS.back(), float(figures(1).updatesPerS)) << "the second's rate";
    EXPECT_EQ(d.last.latencyP50Ms, figures(6).latencyP50Ms);
    EXPECT_EQ(d.last.bytesPerUpdate, figures(6).bytesPerUpdate);
    EXPECT_EQ(d.last.rawBytesPerUpdate, figures(6).rawBytesPerUpdate);
    EXPECT_EQ(d.last.frameMs, figures(1).frameMs) << "the other figures are the second's";
    ComparisonHistory fresh;
    fresh.record(SyncDesign::Volume, 1.0, none);
    EXPECT_EQ(fresh.series(SyncDesign::Volume).last.latencyP50Ms, -1.0);
    EXPECT_EQ(fresh.series(SyncDesign::Volume).last.bytesPerUpdate, -1.0);
    EXPECT_FLOAT_EQ(fresh.series(SyncDesign::Volume).latencyP50Ms.back(), 0.0f);
    EXPECT_STREQ(syncDesignName(SyncDesign::Volume), "Volume (local copy)");
}

TEST(ComparisonPanel, DrawsBothDesignsAndTheToggleFlips) {
    TREPHINE_NEED_DISPLAY("the panel");
    WindowConfig wc;
    wc.width = 520;
    wc.height = 560;
    wc.visible = false;
    auto window = std::make_unique<Window>(wc);
    ComparisonHistory h;
    for (int i = 1; i <= 30; ++i)
        h.record(SyncDesign::Volume, i, figures(1.0 + 0.1 * (i % 5)));
    for (int i = 31; i <= 60; ++i)
        h.record(SyncDesign::Dbi, i, figures(3.0 + 0.2 * (i % 7)));
    SyncDesign design = SyncDesign::Dbi, live = SyncDesign::Dbi;

    auto frame = [&](bool manualInput, ImVec2 mouse, bool down, Dbi* capture) {
        if (manualInput) {
            // Input set by hand (the hidden window has no cursor): the GLFW backend would
            // overwrite it, so this frame starts ImGui directly.
            ImGuiIO& io = ImGui::GetIO();
            io.MousePos = mouse;
            io.MouseDown[0] = down;
            ImGui::NewFrame();
        } else {
            window->beginFrame();
        }
        ImGui::SetNextWindowPos(ImVec2(0, 0));
        ImGui::SetNextWindowSize(ImVec2(float(wc.width), float(wc.height)));
        bool flipped = drawComparisonPanel(design, live, h, 61.0);
        window->endFrame(capture);
        return flipped;
    };

    Dbi shot;
    EXPECT_FALSE(frame(false, {}, false, &shot));
    // Text and plot lines: bright pixels over the dark window background, in the upper half
    // (figures) and the lower half (plots).
    int brightTop = 0, brightBottom = 0;
    for (int y = 0; y < shot.height(); ++y)
        for (int x = 0; x < shot.width(); ++x) {
            const uint8_t* p = shot.color(x, y);
            bool bright = p[0] + p[1] + p[2] > 450;
            (y >= shot.height() / 2 ? brightTop : brightBottom) += bright; // row 0 at the bottom
        }
    EXPECT_GT(brightTop, 300);
    EXPECT_GT(brightBottom, 100);

    // Click the toggle: the first item, just under the title bar.
    const ImGuiStyle& st = ImGui::GetStyle();
    ImVec2 button(st.WindowPadding.x + 20.0f,
                  ImGui::GetFontSize() + 2 * st.FramePadding.y + st.WindowPadding.y +
                      0.5f * (ImGui::GetFontSize() + 2 * st.FramePadding.y));
    EXPECT_FALSE(frame(true, button, false, nullptr)); // hover
    EXPECT_FALSE(frame(true, button, true, nullptr));  // press
    EXPECT_TRUE(frame(true, button, false, nullptr));  // release over it: a click
    EXPECT_EQ(design, SyncDesign::Volume);
    EXPECT_FALSE(frame(true, {400, 500}, false, nullptr));
    EXPECT_EQ(design, SyncDesign::Volume);

    // While the switch waits for its first full update the picture is still the DBI's: its
    // column stays bright and the volume's greyed; once the volume feeds the picture, they swap.
    // Bright pixels in the upper half's right third (the Volume column) tell which.
    auto volumeColumnBright = [&] {
        Dbi s;
        frame(false, {}, false, &s);
        int n = 0;
        for (int y = s.height() / 2; y < s.height(); ++y)
            for (int x = 2 * s.width() / 3; x < s.width(); ++x) {
                const uint8_t* p = s.color(x, y);
                n += p[0] + p[1] + p[2] > 450;
            }
        return n;
    };
    const int switching = volumeColumnBright();
    live = SyncDesign::Volume;
    const int switched = volumeColumnBright();
    EXPECT_GT(switched, 2 * switching + 50) << switching << " -> " << switched;
}

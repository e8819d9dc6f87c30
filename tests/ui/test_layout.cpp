// The window's layout: at any window size every panel lies inside the window, beside or under the
// view and apart from the others (tall enough for its title and a row, scrolling the rest); a
// large window is filled; the full-window view hides the panels. And the window itself, at
// 900 x 650, draws every panel where the layout puts it (needs a display: xvfb-run).
#include "gl_window_test.h"
#include "ui/layout.h"
#include "ui/trainer_app.h"

#include "libsim/skull.h"
#include "net/session_server.h"

#include "loopback.h"

#include <gtest/gtest.h>

#include <string>
#include <vector>

using namespace trephine;
using namespace trephine::ui;

namespace {

std::vector<std::pair<std::string, UiRect>> boxesOf(const PanelLayout& b) {
    return {{"Session", b.session},        {"View", b.view},
            {"Network", b.network},        {"Comparison", b.comparison},
            {"Dirty boxes", b.dirtyBoxes}, {"Assessment", b.assessment},
            {"Forces", b.forces}};
}

bool overlap(const UiRect& a, const UiRect& b) {
    return a.x < b.x + b.w && b.x < a.x + a.w && a.y < b.y + b.h && b.y < a.y + a.h;
}

// Every panel inside the window, at least `minH` tall, overlapping no other panel nor (unless the
// layout says it lies over it) the view.
void expectReachable(const WindowLayout& l, int w, int h, float minH, const std::string& who) {
    ASSERT_TRUE(l.panels) << who;
    const auto boxes = boxesOf(l.boxes);
    for (size_t i = 0; i < boxes.size(); ++i) {
        const auto& [name, r] = boxes[i];
        SCOPED_TRACE(who + ": " + name);
        EXPECT_GE(r.x, 0.0f);
        EXPECT_GE(r.y, 0.0f);
        EXPECT_LE(r.x + r.w, float(w));
        EXPECT_LE(r.y + r.h, float(h));
        EXPECT_GE(r.h, minH) << "its title and a row show; the rest scrolls";
        EXPECT_GE(r.w, std::min(float(w), kPanelColumnMinWidth) - 1.0f);
        if (!l.overlay) {
            EXPECT_FALSE(overlap(r, l.view)) << "beside or under the view";
        }
        for (size_t j = 0; j < i; ++j)
            EXPECT_FALSE(overlap(r, boxes[j].second)) << "apart from " << boxes[j].first;
    }
}

float area(const UiRect& r) {
    return r.w * r.h;
}

} // namespace

TEST(Layout, TheDefaultWindowKeepsItsLayout) {
    const WindowLayout l = windowLayout(1280, 900, 500, 500, false);
    EXPECT_EQ(l.boxes.session, (UiRect{500, 0, 380, 279}));
    EXPECT_EQ(l.boxes.comparison, (UiRect{880, 0, 400, 481}));
    EXPECT_EQ(l.boxes.forces, (UiRect{0, 500, 500, 400})) << "Forces under the view";
    expectReachable(l, 1280, 900, 100.0f, "1280 x 900");
    EXPECT_FLOAT_EQ(panelsWidth(1280, false), 780.0f);
}

TEST(Layout, EveryPanelIsReachableAtAnySize) {
    for (auto [w, h, view] : std::vector<std::tuple<int, int, int>>{{900, 650, 500},
                                                                    {900, 650, 300},
                                                                    {1080, 760, 300},
                                                                    {1800, 1050, 500},
                                                                    {1800, 1050, 1000},
                                                                    {640, 900, 500},
                                                                    {520, 520, 500}}) {
        const std::string who =
            std::to_string(w) + " x " + std::to_string(h) + ", view " + std::to_string(view);
        expectReachable(windowLayout(w, h, view, view, false), w, h, 60.0f, who);
    }
}

TEST(Layout, ALargeWindowIsFilledAndTheFullViewHidesThePanels) {
    for (auto [w, h] : std::vector<std::pair<int, int>>{{1800, 1050}, {1280, 900}, {900, 650}}) {
        // The view takes the area the panels leave; the view and the panels then cover the
        // window but for the corner a square view leaves.
        const UiRect area0 = viewArea(w, h, false);
        const int view = int(std::min(area0.w, area0.h));
        const WindowLayout l = windowLayout(w, h, view, view, false);
        float covered = area(l.view);
        for (const auto& [name, r] : boxesOf(l.boxes))
            covered += area(r);
        const float unused = area0.w * area0.h - float(view) * float(view);
        EXPECT_GE(covered + unused, 0.99f * float(w) * float(h)) << w << " x " << h;
        EXPECT_GE(area(l.view), 0.2f * float(w) * float(h)) << "the view keeps its share";
    }
    const WindowLayout full = windowLayout(1280, 900, 500, 500, true);
    EXPECT_FALSE(full.panels);
    EXPECT_EQ(viewArea(1280, 900, true), (UiRect{0, 0, 1280, 900}));
}

TEST(Layout, AWindowOf900By650DrawsEveryPanelInsideIt) {
    TREPHINE_NEED_DISPLAY("the trainee window");
    const Volume skull = makeSkull(64);
    net::SessionServer server(skull, trephine::testing::loopbackServerConfig("skull:64"));
    trephine::testing::Pumped pumped(server);
    TrainerReport report;
    TrainerOptions o;
    o.address = "127.0.0.1:" + std::to_string(server.port());
    o.camera = "working";
    o.size = 500;
    o.windowWidth = 900;
    o.windowHeight = 650;
    o.frames = 3;
    o.timeoutS = 60.0;
    o.visible = false;
    o.report = &report;
    ASSERT_EQ(trephine::testing::whilePumping([&] { return runTrainerWindow(o); }), 0);
    server.stop();
    const WindowLayout want = windowLayout(900, 650, 500, 500, false);
    ASSERT_EQ(report.panels.size(), 7u) << "every panel drawn";
    for (const auto& [name, r] : boxesOf(want.boxes)) {
        SCOPED_TRACE(name);
        ASSERT_TRUE(report.panels.count(name));
        const auto& got = report.panels.at(name);
        EXPECT_EQ(got[0], r.x);
        EXPECT_EQ(got[1], r.y);
        EXPECT_LE(got[0] + got[2], 900.0f);
        EXPECT_LE(got[1] + got[3], 650.0f) << "not cut off at the window's foot";
    }
}

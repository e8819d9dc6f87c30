// The trainee window drilled with the mouse, end to end: an in-process server on skull:128, the
// window's pointer driven in place of the mouse (TrainerOptions::pointer): held still over the
// burr site, then released. Bone goes, the DBI shows the hole, and the window's screenshot shows
// it uncovered (the lifted handpiece is not over it). Needs a display (xvfb-run).
#include "gl_window_test.h"
#include "ui/layout.h"
#include "ui/mouse_tool.h"
#include "ui/trainer_app.h"

#include "libsim/skull.h"
#include "net/session_server.h"

#include "loopback.h"
#include "screenshot.h"
#include "test_support.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <thread>
#include <unistd.h>

using namespace trephine;
using namespace trephine::ui;
using trephine::testing::boneVoxels;

TEST(FeedWindow, HoldingTheButtonOverBoneDrillsAHoleTheScreenshotShowsUncovered) {
    TREPHINE_NEED_DISPLAY("the trainee window");
    const Volume skull = makeSkull(128);
    const int64_t before = boneVoxels(skull);
    net::SessionServer server(skull, trephine::testing::loopbackServerConfig("skull:128", 2));
    trephine::testing::Pumped pumped(server);
    trephine::testing::TempDir dir;
    const std::string shot = dir / "held.png";
    constexpr int kSize = 256;
    constexpr double kHoldS = 3.0;
    TrainerReport report;
    TrainerOptions o;
    o.address = "127.0.0.1:" + std::to_string(server.port());
    o.size = kSize;
    o.tiltDeg = 30.0f; // the window's default working angle
    o.screenshot = shot;
    o.frames = 2;
    o.timeoutS = 100.0;
    o.visible = false;
    o.report = &report;
    // The view looks at the burr site: its centre. Pressed at 0.5 s, held still for kHoldS,
    // released, then left there.
    o.input = [](double t) {
        InjectedInput p;
        if (t < 0.0)
            return p;
        p.x = p.y = kSize / 2 + 0.5f;
        p.left = t > 0.5 && t < 0.5 + kHoldS;
        p.done = t > 1.0 + kHoldS;
        return p;
    };
    ASSERT_EQ(trephine::testing::whilePumping([&] { return runTrainerWindow(o); }), 0);
    const int64_t removed = before - boneVoxels(server.volumeSnapshot());
    server.stop();
    std::printf("feed window: %.0f s held still at the site, skull:128: %lld bone voxels "
                "removed\n",
                kHoldS, (long long)removed);
    EXPECT_GT(removed, 15) << "more than the burr's own sphere (17 voxels of 1.56 mm)";

    // The picture (pass 1, the DBI) shows a hole at the centre: deeper than the bone around it.
    ASSERT_EQ(report.view.width(), kSize);
    const glm::ivec2 centre(kSize / 2, kSize / 2 - 1);
    const auto normal = surfaceNormal(report.view, report.camera, centre.x, centre.y + 20, 8);
    ASSERT_TRUE(normal.has_value());
    const auto hole = readHole(report.view, report.camera, centre, *normal, 5.0f);
    ASSERT_TRUE(hole.has_value());
    EXPECT_GT(hole->depthMm, 2.5f) << "the hole under the pointer";

    // The window's screenshot shows the hole's floor as the DBI does: no tool over it.
    const trephine::testing::Image img = trephine::testing::readPng(shot);
    ASSERT_GE(img.w, kSize);
    int inHole = 0, same = 0;
    for (int y = centre.y - 3; y <= centre.y + 3; ++y)
        for (int x = centre.x - 3; x <= centre.x + 3; ++x) {
            if (std::hypot(x - centre.x, y - centre.y) > 3.0)
                continue;
            ++inHole;
            const uint8_t* a = report.view.color(x, y);
            const uint8_t* b = img.at(x, kSize - 1 - y); // the view is blitted at the top left
            int d = 0;
            for (int c = 0; c < 3; ++c)
                d = std::max(d, std::abs(int(a[c]) - int(b[c])));
            same += d <= 12;
        }
    EXPECT_GE(same, inHole * 9 / 10) << "pixels of the hole drawn as the DBI has them";
}

// Resized, the window's view takes the area the panels leave (the window less the panels'
// columns on the right, ui/layout.h, and Forces below), the DBI follows at the new size, and every
// pixel of that area shows the picture: close to the site the bone fills the view, so an unfilled
// strip (the window's clear colour, or the old view's size) shows as pixels that are not bone.
TEST(FeedWindow, AResizedWindowsViewFillsTheFreeAreaAtItsNewSize) {
    TREPHINE_NEED_DISPLAY("the trainee window");
    net::SessionServer server(makeSkull(128),
                              trephine::testing::loopbackServerConfig("skull:128", 2));
    trephine::testing::Pumped pumped(server);
    trephine::testing::TempDir dir;
    const std::string shot = dir / "resized.png";
    constexpr int kWidth = 1120, kHeight = 830; // from 980 x 760 at --size 200
    TrainerReport report;
    TrainerOptions o;
    o.address = "127.0.0.1:" + std::to_string(server.port());
    o.size = 200;
    o.distanceMm = 50.0f; // the bone fills the view, one column of panels beside it
    o.screenshot = shot;
    o.frames = 2;
    o.timeoutS = 100.0;
    o.visible = false;
    o.report = &report;
    o.input = [](double t) {
        InjectedInput in;
        if (t >= 0.2) {
            in.windowWidth = kWidth;
            in.windowHeight = kHeight;
        }
        in.done = t > 1.0;
        return in;
    };
    ASSERT_EQ(trephine::testing::whilePumping([&] { return runTrainerWindow(o); }), 0);
    server.stop();
    const glm::ivec2 want(kWidth - int(panelsWidth(kWidth, false)), kHeight - 400);
    EXPECT_EQ(report.view.width(), want.x);
    EXPECT_EQ(report.view.height(), want.y);
    EXPECT_EQ(report.camera.width, want.x);
    EXPECT_EQ(report.camera.height, want.y);
    const trephine::testing::Image img = trephine::testing::readPng(shot);
    ASSERT_EQ(img.w, kWidth);
    ASSERT_EQ(img.h, kHeight);
    // The view's pixels, away from the overlays' text at its top: the picture's, bone-coloured.
    int area = 0, bone = 0;
    for (int y = 40; y < want.y; y += 2)
        for (int x = 0; x < want.x; x += 2) {
            ++area;
            const uint8_t* p = img.at(x, y);
            bone += p[0] > 60 && p[0] > p[2] + 15; // lit bone: warm, not the blue-grey clear
        }
    EXPECT_GT(bone, area * 95 / 100) << "the view fills the free area";
}

// Gestures in the view: a right drag of 100 pixels to the left orbits the view 30 degrees, two
// notches of the wheel with Ctrl zoom in to 0.81 of the distance; the window's camera is then
// the orbit of the opening view the View panel's sliders would give.
TEST(FeedWindow, ARightDragOrbitsAndCtrlWheelZooms) {
    TREPHINE_NEED_DISPLAY("the trainee window");
    const Volume skull = makeSkull(128);
    net::SessionServer server(skull, trephine::testing::loopbackServerConfig("skull:128", 2));
    trephine::testing::Pumped pumped(server);
    trephine::testing::TempDir dir;
    TrainerReport report;
    TrainerOptions o;
    o.address = "127.0.0.1:" + std::to_string(server.port());
    o.size = 200;
    o.tiltDeg = 20.0f;
    o.screenshot = dir / "orbited.png";
    o.frames = 2;
    o.timeoutS = 100.0;
    o.visible = false;
    o.report = &report;
    bool zoomed = false;
    // Pressed and still at x 150 first (some frame sees the press there), then dragged to 50.
    o.input = [&zoomed](double t) {
        InjectedInput in;
        if (t < 0.2)
            return in;
        const float u = float(std::clamp((t - 0.6) / 0.5, 0.0, 1.0));
        in.x = 150.0f - 100.0f * u;
        in.y = 100.0f;
        in.right = t < 1.2;
        if (t > 1.3 && !zoomed) {
            in.wheel = 2.0f;
            in.zoomKey = true;
            zoomed = true;
        }
        in.done = t > 1.6;
        return in;
    };
    ASSERT_EQ(trephine::testing::whilePumping([&] { return runTrainerWindow(o); }), 0);
    server.stop();
    ASSERT_TRUE(zoomed);
    const SurfaceSite site = defaultBurrSite(skull);
    const float radius = 0.5f * glm::length(skull.extentMm());
    const Camera opened =
        cameraLookingAt(site.position, site.normal, o.distanceMm, 45.0f, {200, 200}, radius);
    const Camera want = orbitCamera(opened, 30.0f, 20.0f, o.distanceMm * 0.81f, {200, 200}, radius);
    EXPECT_LT(glm::distance(report.camera.eye, want.eye), 0.5f)
        << describe(report.camera) << " vs " << describe(want);
    EXPECT_LT(glm::distance(report.camera.target, want.target), 0.01f);
}

// The mouse device's geometry without GL: picking the bone under the cursor from DBI depth, and
// the tool pose placed there.
#include "net/scripts.h"
#include "ui/mouse_tool.h"

#include <glm/geometric.hpp>
#include <gtest/gtest.h>

using namespace trephine;
using namespace trephine::ui;
using trephine::net::burrholePose;
using trephine::net::ScriptPose;

namespace {
// A bone plane z = 0 seen from +z: every pixel's depth is the window depth of its plane point.
struct PlaneView {
    Camera cam;
    Dbi dbi;
    PlaneView() {
        cam.eye = {10, -20, 250};
        cam.target = {0, 0, 0};
        cam.nearMm = 100;
        cam.farMm = 400;
        cam.width = cam.height = 120;
        dbi = Dbi(cam.width, cam.height);
        glm::dmat4 vp = viewProjection(cam), inv = glm::inverse(vp);
        for (int y = 0; y < 120; ++y)
            for (int x = 0; x < 120; ++x) {
                if (x < 10) // a strip of background on the left
                    continue;
                glm::dvec2 ndc(2.0 * (x + 0.5) / 120 - 1.0, 2.0 * (y + 0.5) / 120 - 1.0);
                glm::dvec4 a = inv * glm::dvec4(ndc, -1, 1), b = inv * glm::dvec4(ndc, 1, 1);
                glm::dvec3 p0 = glm::dvec3(a) / a.w, p1 = glm::dvec3(b) / b.w;
                glm::dvec3 p = p0 + (p1 - p0) * (-p0.z / (p1.z - p0.z));
                dbi.depth()[dbi.index(x, y)] = windowDepth(vp, p);
            }
    }
};
} // namespace

TEST(MouseTool, PicksThePointOfBoneUnderTheCursor) {
    PlaneView v;
    for (auto [x, y] : {std::pair{60, 60}, {20, 100}, {119, 5}}) {
        auto p = pickSurface(v.dbi, v.cam, x, y);
        ASSERT_TRUE(p.has_value());
        EXPECT_NEAR(p->z, 0.0f, 0.05f);
        // It projects back to the same pixel.
        WindowPoint w = projectToWindow(viewProjection(v.cam), v.cam, glm::dvec3(*p));
        EXPECT_NEAR(w.window.x, x + 0.5, 0.01);
        EXPECT_NEAR(w.window.y, y + 0.5, 0.01);
    }
    EXPECT_FALSE(pickSurface(v.dbi, v.cam, 5, 60).has_value()) << "background: no bone";
    EXPECT_FALSE(pickSurface(v.dbi, v.cam, 200, 60).has_value()) << "outside the image";
}

TEST(MouseTool, BurrTouchesThePointAndPushesAlongTheLineOfSight) {
    PlaneView v;
    glm::vec3 s = *pickSurface(v.dbi, v.cam, 60, 60);
    ToolShape burr = ToolShape::burr(4.0f);
    ToolPose touch = toolPoseAt(s, v.cam, burr, 0.0f);
    EXPECT_NEAR(glm::length(touch.position - s), 2.0f, 1e-4f);
    EXPECT_GT(glm::dot(touch.axis(), glm::normalize(v.cam.eye - s)), 0.9999f);
    EXPECT_NEAR(burr.signedDistance(touch.toLocal(s)), 0.0f, 1e-4f);
    ToolPose pushed = toolPoseAt(s, v.cam, burr, 1.5f);
    EXPECT_NEAR(burr.signedDistance(pushed.toLocal(s)), -1.5f, 1e-3f);
    ToolPose perf = toolPoseAt(s, v.cam, ToolShape::perforator(), 0.0f);
    EXPECT_NEAR(glm::length(perf.position - s), 0.0f, 1e-4f);
}

// The scripted burr hole moves as a hand would: no jump between 1 ms ticks (the haptic loop's
// rate), drilling only while in the bone, and at rest beside the hole when done. It used to jump
// 18 mm from the hole's floor to the rest pose in one tick, which threw the force extrapolated
// from the last in-hole model to the limit.
TEST(BurrholeScript, MovesContinuouslyAndEndsAtRestBesideTheHole) {
    const SurfaceSite site{glm::vec3(10.0f, -5.0f, 60.0f),
                           glm::normalize(glm::vec3(0.2f, 0.1f, 1.0f))};
    ScriptPose prev = burrholePose(site, 0.0);
    double maxStepMm = 0.0, lastDrilling = -1.0, doneAt = -1.0;
    for (int i = 1; i <= 6000; ++i) {
        const double t = i * 1e-3;
        const ScriptPose p = burrholePose(site, t);
        maxStepMm = std::max(maxStepMm, double(glm::distance(p.position, prev.position)));
        EXPECT_LT(glm::distance(p.axis, prev.axis), 0.01f) << "t " << t;
        if (p.drilling)
            lastDrilling = t;
        if (p.done && doneAt < 0.0)
            doneAt = t;
        prev = p;
    }
    EXPECT_LE(maxStepMm, 0.05); // 50 mm/s at most
    EXPECT_GT(lastDrilling, 3.9);
    EXPECT_LT(lastDrilling, 4.0);
    ASSERT_GT(doneAt, 4.0);
    // At rest: 4 mm above the surface, well beside the hole (6 mm radius), not drilling.
    EXPECT_NEAR(glm::dot(prev.position - site.position, site.normal), 4.0f, 1e-4f);
    const glm::vec3 lateral = prev.position - site.position -
                              site.normal * glm::dot(prev.position - site.position, site.normal);
    EXPECT_GT(glm::length(lateral), 12.0f);
    EXPECT_FALSE(prev.drilling);
}

// The window's pose changes once a frame: the local drilling resistance took its velocity from the
// haptic loop's 1 kHz ticks, 0 for ~15 ticks and 16 times the true speed on the one after a frame.
// The device gives the frame's velocity, the same at every tick between frames.
TEST(WindowDevice, VelocityIsTheFramesNotTheTicks) {
    WindowDevice device;
    DeviceState s;
    s.valid = true;
    const double frame = 1.0 / 60.0;
    for (int i = 0; i < 30; ++i) {
        s.pose.position = glm::vec3(0.0f, 0.0f, -0.2f * float(i)); // 12 mm/s down
        device.set(s, {}, 5.0 + i * frame);
        if (i == 0) {
            EXPECT_EQ(device.velocity(), glm::vec3(0.0f)) << "no earlier frame";
            continue;
        }
        for (int tick = 0; tick < 16; ++tick) { // what the loop reads between frames
            EXPECT_NEAR(device.velocity().z, -12.0f, 0.01f) << "frame " << i << " tick " << tick;
            EXPECT_EQ(device.read(0.0).pose.position, s.pose.position);
        }
    }
    // The mouse left the bone (no pose): no velocity; back on after a pause: none from the jump.
    s.valid = false;
    device.set(s, {}, 5.6);
    EXPECT_EQ(device.velocity(), glm::vec3(0.0f));
    s.valid = true;
    s.pose.position = glm::vec3(30.0f, 0.0f, 0.0f);
    device.set(s, {}, 6.0);
    EXPECT_EQ(device.velocity(), glm::vec3(0.0f));
}

// The handpiece's feed without GL or a network: the mouse's stroke against the server's own
// drilling (Driller, swept as the simulation step sweeps) and force model, compared with the
// burrhole scripts on the server's default volume (skull:128).
#include "net/scripts.h"
#include "ui/mouse_tool.h"

#include "libsim/drill.h"
#include "libsim/force_model.h"
#include "libsim/renderer.h"
#include "libsim/skull.h"

#include <algorithm>
#include <cstdio>
#include <functional>
#include <glm/geometric.hpp>
#include <gtest/gtest.h>

using namespace trephine;
using namespace trephine::ui;
using trephine::net::burrholePose;
using trephine::net::ScriptPose;

namespace {

// The server's drilling of a stream of tool states (net/sim_step.cpp's applyTool): each drilling
// state sweeps from the last drilling pose in quarter-voxel sub-steps over the time between them.
struct ServerCut {
    Volume& volume;
    Driller driller{ToolShape::burr(5.0f)};
    bool lastDrilling = false;
    ToolPose last{};
    int64_t removed = 0; // voxels eroded to air

    void state(const ToolPose& pose, bool drilling, float dt) {
        const glm::vec3 s = volume.spacing();
        const ToolPose from = last;
        const bool sweep = lastDrilling;
        last = pose;
        lastDrilling = drilling;
        if (!drilling) {
            driller.observe(volume, pose);
            return;
        }
        const std::vector<ToolPose> path =
            sweep ? sweepPoses(from, pose, 0.25f * std::min({s.x, s.y, s.z}), 10.0f)
                  : std::vector<ToolPose>{pose};
        for (const ToolPose& p : path)
            removed += driller.drill(volume, p, 1.0f, dt / float(path.size())).voxelsRemoved;
    }
};

constexpr double kTickS = 0.01; // tool states at 100 Hz, as the haptic loop sends them

// Voxels removed in `seconds` by tool states from `poseAt(t, volume)` (pose, drilling).
int64_t removedBy(double seconds,
                  const std::function<std::pair<ToolPose, bool>(double, const Volume&)>& poseAt) {
    Volume skull = makeSkull(128);
    ServerCut cut{skull};
    for (int i = 0; i * kTickS <= seconds + 1e-9; ++i) {
        const auto [pose, drilling] = poseAt(i * kTickS, skull);
        cut.state(pose, drilling, float(kTickS));
    }
    return cut.removed;
}

// The mouse held still over the site: the feed advanced each frame by the force the server
// answers at the current pose (ForceModel, with the feed's velocity), as the window does.
struct MouseStroke {
    SurfaceSite site;
    ForceModel model{ToolShape::burr(5.0f)};
    Feed feed;
    std::vector<float> depths;
    MouseStroke(const SurfaceSite& s) : site(s) { feed.press(site.position, site.normal, 0.0f); }
    std::pair<ToolPose, bool> operator()(double, const Volume& v) {
        const ToolShape shape = ToolShape::burr(5.0f);
        ToolPose pose = toolPoseAlong(feed.surface(), feed.axis(), shape, feed.depthMm());
        const float vmax = maxFeedMmPerS(ToolKind::Burr, 1.0f, v.spacing());
        const glm::vec3 f = model.compute(v, pose, 1.0f, -feed.axis() * vmax).force;
        feed.advance(float(kTickS), f, vmax);
        depths.push_back(feed.depthMm());
        return {toolPoseAlong(feed.surface(), feed.axis(), shape, feed.depthMm()), true};
    }
};

} // namespace

TEST(Feed, AdvancesAtTheErosionLimitInAirAndStallsAgainstTheHandsPush) {
    Feed feed;
    const float vmax = maxFeedMmPerS(ToolKind::Burr, 1.0f, glm::vec3(0.78125f));
    EXPECT_NEAR(vmax, 0.78125f * 1700.0f / 255.0f, 1e-4f);
    EXPECT_FLOAT_EQ(maxFeedMmPerS(ToolKind::Burr, 0.5f, glm::vec3(0.78125f)), vmax * 0.5f);
    EXPECT_EQ(feed.advance(0.1f, glm::vec3(0), vmax), 0.0f) << "not pressed: no feed";
    feed.press(glm::vec3(0), glm::vec3(0, 0, 1), 0.5f);
    EXPECT_NEAR(feed.advance(0.1f, glm::vec3(0), vmax), vmax, 1e-5f);
    EXPECT_NEAR(feed.depthMm(), 0.5f + vmax * 0.1f, 1e-5f);
    const float half = feed.advance(0.1f, glm::vec3(0, 0, feed.config().pushForceN * 0.5f), vmax);
    EXPECT_NEAR(half, vmax * 0.5f, 1e-5f) << "the bone pushing back at half the hand's push";
    const float before = feed.depthMm();
    EXPECT_EQ(feed.advance(0.1f, glm::vec3(0, 0, feed.config().pushForceN * 2.0f), vmax), 0.0f);
    EXPECT_EQ(feed.depthMm(), before) << "stalled: the bone pushes back harder than the hand";
    EXPECT_NEAR(feed.advance(0.1f, glm::vec3(5, 0, 0), vmax), vmax, 1e-5f)
        << "a sideways force does not resist the feed";
    feed.release();
    EXPECT_FALSE(feed.held());
    EXPECT_EQ(feed.advance(0.1f, glm::vec3(0), vmax), 0.0f);
}

TEST(Feed, SlidingFollowsThePointerAtTheStrokesDepth) {
    Feed feed;
    feed.press(glm::vec3(1, 2, 3), glm::vec3(0, 0, 1), 1.0f);
    feed.slideTo(glm::vec3(4, 5, -2)); // picked at the hole's floor, 5 mm below the first contact
    EXPECT_EQ(feed.surface(), glm::vec3(4, 5, 3));
    EXPECT_EQ(feed.depthMm(), 1.0f);
}

// The target: holding the button for 3 s over the bone with the default burr removes at
// least as much bone as a steady 1 mm/s feed (the headless burrhole script when the target was
// set) in 3 s. Both run against the server's drilling on its default volume; the figures are
// printed beside the target, with the burrhole script's (a plunge and a widening spiral).
TEST(Feed, HoldingStillThreeSecondsRemovesAtLeastTheBurrholeScriptsBone) {
    const SurfaceSite site = defaultBurrSite(makeSkull(128));
    MouseStroke stroke(site);
    const int64_t mouse = removedBy(3.0, std::ref(stroke));
    // 1 mm above the site, in at 1 mm/s.
    const int64_t script = removedBy(3.0, [&](double t, const Volume&) {
        return std::pair{
            ToolPose::fromAxis(site.position - site.normal * float(t - 1.0), site.normal), true};
    });
    // --script burrhole, in every shell: plunge, then a widening spiral (net/scripts.h).
    const int64_t spiral = removedBy(3.0, [&](double t, const Volume&) {
        const ScriptPose p = burrholePose(site, t);
        return std::pair{ToolPose::fromAxis(p.position, p.axis), p.drilling};
    });
    std::printf("feed: 3 s held still, default burr 5 mm, skull:128: %lld voxels removed "
                "(target >= %lld, a 1 mm/s feed's; the burrhole script's plunge and spiral: "
                "%lld); stroke depth %.1f mm\n",
                (long long)mouse, (long long)script, (long long)spiral,
                double(stroke.feed.depthMm()));
    EXPECT_GT(script, 0);
    EXPECT_GE(mouse, script);
    // It went in and then stopped: the inner table's dura does not erode and pushes back.
    EXPECT_GT(stroke.feed.depthMm(), 4.0f);
    EXPECT_LT(stroke.feed.depthMm(), 12.0f);
    EXPECT_NEAR(stroke.depths.back(), stroke.depths[stroke.depths.size() - 20], 0.05f)
        << "still feeding after 3 s: nothing stopped it at the dura";
}

// The window's burrhole script on skull:128, seen as the window sees it (the site at the default
// 30 degree working angle): the hole's floor, in the diploe below the outer table, shows diploe,
// not a lattice of the inner table's cortical bone a voxel below. Some pixels where the voxel
// nearest the hit is the inner table's (1.56 mm voxels, the floor a millimetre above it) stay.
TEST(Feed, TheBurrholesFloorShowsDiploeNotALatticeOfCorticalBone) {
    Volume skull = makeSkull(128);
    const SurfaceSite site = defaultBurrSite(skull);
    ServerCut cut{skull};
    for (int i = 0; i * kTickS <= 4.0; ++i) {
        const ScriptPose p = burrholePose(site, i * kTickS);
        cut.state(ToolPose::fromAxis(p.position, p.axis), p.drilling, float(kTickS));
    }
    const float radius = 0.5f * glm::length(skull.extentMm());
    const Camera opened =
        cameraLookingAt(site.position, site.normal, 170.0f, 45.0f, {500, 500}, radius);
    const Camera c = orbitCamera(opened, 0.0f, 30.0f, 170.0f, {500, 500}, radius);
    Renderer renderer(skull);
    const Dbi d = renderer.render(c);
    int floor = 0, ivory = 0;
    for (int y = 0; y < c.height; ++y)
        for (int x = 0; x < c.width; ++x) {
            const RayHit h = renderer.castRay(c, x, y);
            const glm::vec3 p = glm::vec3(h.position) - site.position;
            const float below = -glm::dot(p, site.normal);
            // Below the outer table (1.8 mm), inside the spiral's reach.
            if (!h.hit || below < 2.6f || glm::length(p + below * site.normal) > 7.0f)
                continue;
            ++floor;
            const uint8_t* rgb = d.color(x, y);
            ivory += float(rgb[1]) > 0.85f * float(rgb[0]);
        }
    std::printf("burrhole floor: %d pixels, %d of them cortical-coloured\n", floor, ivory);
    EXPECT_GT(floor, 500);
    EXPECT_LE(ivory, floor / 10);
}

// The floor readout names each label by its shaded colour: every material's colour at full light
// and at a grazing third of it.
TEST(Feed, TheFloorReadoutNamesEveryLabelByItsColour) {
    const std::pair<Material, HoleFloor> labels[] = {{Material::Cortical, HoleFloor::Cortical},
                                                     {Material::Diploe, HoleFloor::Diploe},
                                                     {Material::Dura, HoleFloor::Dura},
                                                     {Material::Sinus, HoleFloor::Sinus},
                                                     {Material::Artery, HoleFloor::Artery}};
    for (const auto& [material, floor] : labels)
        for (float light : {1.0f, 0.35f}) {
            const glm::vec3 c = materialColor(material) * light;
            EXPECT_EQ(floorOfColor(uint8_t(c.r), uint8_t(c.g), uint8_t(c.b)), floor)
                << materialName(material) << " at " << light;
        }
}

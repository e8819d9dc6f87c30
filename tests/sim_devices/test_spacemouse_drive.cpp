// A SpaceMouse driving the tool: reports built to 3Dconnexion's documented HID format (ID 1
// translation, ID 2 rotation, ID 3 buttons; little-endian int16 axes) fed through a source into
// the real SpaceMouseDevice, read at 1 kHz, move and turn the tool the expected distance and angle;
// spacenavd's events become the same reports; the anchor, the clutch and button presses.
#include "libsim_devices/anchored_device.h"
#include "libsim_devices/spacemouse.h"

#include <cmath>
#include <deque>
#include <glm/geometric.hpp>
#include <glm/gtc/quaternion.hpp>
#include <gtest/gtest.h>
#include <memory>
#include <vector>

using namespace trephine;

namespace {

std::vector<uint8_t> axes(uint8_t id, int16_t a, int16_t b, int16_t c) {
    auto le = [](int16_t v) {
        return std::pair<uint8_t, uint8_t>(uint8_t(v & 0xff), uint8_t(uint16_t(v) >> 8));
    };
    return {id, le(a).first, le(a).second, le(b).first, le(b).second, le(c).first, le(c).second};
}

// Reports queued by the test, delivered on the next poll; `gone` makes the next poll fail.
struct FakeSource : SpaceMouseSource {
    std::deque<std::vector<uint8_t>>* queue;
    bool* gone;
    FakeSource(std::deque<std::vector<uint8_t>>* q, bool* g) : queue(q), gone(g) {}
    std::string name() const override { return "fake SpaceMouse"; }
    bool poll(SpaceMouseParser& parser) override {
        if (*gone)
            return false;
        for (; !queue->empty(); queue->pop_front())
            parser.feed(queue->front());
        return true;
    }
};

struct Rig {
    std::deque<std::vector<uint8_t>> queue;
    bool gone = false;
    SpaceMouseConfig config;
    std::unique_ptr<SpaceMouseDevice> device() {
        return std::make_unique<SpaceMouseDevice>(std::make_unique<FakeSource>(&queue, &gone),
                                                  config);
    }
};

// Reads `device` every millisecond from t0 for `seconds`; returns the last state.
DeviceState runFor(Device& device, double t0, double seconds) {
    DeviceState s;
    const int ticks = int(std::lround(seconds * 1000.0));
    for (int i = 0; i <= ticks; ++i)
        s = device.read(t0 + i * 0.001);
    return s;
}

float angleAbout(glm::quat q, glm::vec3 axis) {
    return 2.0f * std::atan2(glm::dot(glm::vec3(q.x, q.y, q.z), axis), q.w);
}

} // namespace

TEST(SpaceMouseDrive, FullPushRightForTwoSecondsMovesTheToolGainTimesTime) {
    Rig rig;
    rig.config.translationGainMmPerS = 40.0;
    auto d = rig.device();
    rig.queue.push_back(axes(1, kSpaceMouseFullScale, 0, 0)); // full push right
    const DeviceState s = runFor(*d, 5.0, 2.0);
    ASSERT_TRUE(s.valid);
    EXPECT_NEAR(s.pose.position.x, 80.0f, 0.05f); // 40 mm/s for 2 s
    EXPECT_NEAR(s.pose.position.y, 0.0f, 1e-5f);
    EXPECT_NEAR(s.pose.position.z, 0.0f, 1e-5f);
}

TEST(SpaceMouseDrive, HalfDeflectionPastTheDeadZoneAndATwistTurnTheToolAtTheirRates) {
    Rig rig;
    rig.config.translationGainMmPerS = 60.0;
    rig.config.rotationGainRadPerS = 1.0;
    rig.config.deadZone = 50;
    auto d = rig.device();
    // Lifted half way past the dead zone (device z is down: -200 lifts), twisted fully about z.
    rig.queue.push_back(axes(1, 0, 0, -200));
    rig.queue.push_back(axes(2, 0, 0, -kSpaceMouseFullScale));
    const DeviceState s = runFor(*d, 0.0, 1.5);
    const float frac = float(200 - 50) / float(kSpaceMouseFullScale - 50);
    EXPECT_NEAR(s.pose.position.z, 60.0f * frac * 1.5f, 0.02f);
    EXPECT_NEAR(angleAbout(s.pose.orientation, {0, 0, 1}), 1.5f, 1e-3f); // 1 rad/s for 1.5 s
    // Released (a report of zeros): the tool stays.
    rig.queue.push_back(axes(1, 0, 0, 0));
    rig.queue.push_back(axes(2, 0, 0, 0));
    const DeviceState after = runFor(*d, 1.6, 1.0);
    EXPECT_NEAR(glm::length(after.pose.position - s.pose.position), 0.0f, 0.01f);
}

TEST(SpaceMouseDrive, TheNewModelsCombinedReportMovesAndTurnsAtOnce) {
    Rig rig;
    rig.config.translationGainMmPerS = 50.0;
    rig.config.rotationGainRadPerS = 2.0;
    auto d = rig.device();
    std::vector<uint8_t> r = axes(1, 0, -kSpaceMouseFullScale, 0); // pushed away: +y
    const std::vector<uint8_t> rot = axes(2, kSpaceMouseFullScale, 0, 0);
    r.insert(r.end(), rot.begin() + 1, rot.end()); // 13 bytes: ID, tx ty tz, rx ry rz
    ASSERT_EQ(r.size(), 13u);
    rig.queue.push_back(r);
    const DeviceState s = runFor(*d, 0.0, 0.5);
    EXPECT_NEAR(s.pose.position.y, 25.0f, 0.02f);
    EXPECT_NEAR(angleAbout(s.pose.orientation, {1, 0, 0}), 1.0f, 1e-3f);
}

TEST(SpaceMouseDrive, ButtonsReportAndPressesAreCountedOnceEach) {
    Rig rig;
    AnchoredDevice a(rig.device());
    a.read(0.0);
    rig.queue.push_back({3, 0x01});
    a.read(0.001);
    EXPECT_EQ(a.last().buttons, 1u);
    rig.queue.push_back({3, 0x03}); // second button down too, first still held
    a.read(0.002);
    EXPECT_EQ(a.takePresses(), 3u) << "each button went down once";
    a.read(0.003);
    EXPECT_EQ(a.takePresses(), 0u) << "held is not pressed again";
    rig.queue.push_back({3, 0x00});
    a.read(0.004);
    rig.queue.push_back({3, 0x01});
    a.read(0.005);
    rig.queue.push_back({3, 0x00}); // a press shorter than a frame
    a.read(0.006);
    EXPECT_EQ(a.takePresses(), 1u);
}

TEST(SpaceMouseDrive, AnAnchoredSpaceMouseStartsAtTheAnchorAndMovesInTheViewsFrame) {
    Rig rig;
    rig.config.translationGainMmPerS = 10.0;
    auto owned = rig.device();
    SpaceMouseDevice* sm = owned.get();
    AnchoredDevice a(std::move(owned));
    ToolPose site;
    site.position = {5, 6, 70};
    site.orientation = glm::angleAxis(0.3f, glm::vec3(1, 0, 0));
    a.setAnchor(site);
    DeviceState s = a.read(0.0);
    EXPECT_EQ(s.pose.position, site.position);
    EXPECT_NEAR(glm::dot(s.pose.orientation, site.orientation), 1.0f, 1e-6f);
    // A viewer looking down -x (right = +y, up = +z, back = +x): pushing the cap away moves the
    // tool into the view, along -x.
    sm->setFrame(spaceMouseViewFrame({0, 1, 0}, {0, 0, 1}, {1, 0, 0}));
    rig.queue.push_back(axes(1, 0, -kSpaceMouseFullScale, 0));
    s = runFor(a, 0.001, 1.0);
    EXPECT_NEAR(s.pose.position.x, 5.0f - 10.0f, 0.02f);
    EXPECT_NEAR(s.pose.position.y, 6.0f, 1e-4f);
    EXPECT_NEAR(s.pose.position.z, 70.0f, 1e-4f);
}

TEST(SpaceMouseDrive, WhileTheClutchIsHeldTheToolStaysAndThenGoesOnFromThere) {
    Rig rig;
    rig.config.translationGainMmPerS = 20.0;
    AnchoredDevice a(rig.device());
    a.setAnchor(ToolPose{});
    rig.queue.push_back(axes(1, kSpaceMouseFullScale, 0, 0));
    DeviceState s = runFor(a, 0.0, 1.0);
    EXPECT_NEAR(s.pose.position.x, 20.0f, 0.02f);
    a.setClutch(true);
    s = runFor(a, 1.001, 1.0);
    EXPECT_NEAR(s.pose.position.x, 20.0f, 0.05f) << "clutched: the hand moves, the tool not";
    a.setClutch(false);
    s = runFor(a, 2.002, 0.5);
    EXPECT_NEAR(s.pose.position.x, 30.0f, 0.1f);
}

TEST(SpaceMouseDrive, MoveToRecentresWhereverTheDeviceHasGone) {
    Rig rig;
    AnchoredDevice a(rig.device());
    EXPECT_FALSE(a.read(0.0).valid) << "not placed: nothing to send";
    rig.queue.push_back(axes(1, kSpaceMouseFullScale, 0, kSpaceMouseFullScale));
    runFor(a, 0.001, 0.5);
    ToolPose p;
    p.position = {1, 2, 3};
    a.moveTo(p);
    rig.queue.push_back(axes(1, 0, 0, 0));
    const DeviceState s = a.read(0.502);
    EXPECT_TRUE(s.valid);
    EXPECT_NEAR(glm::length(s.pose.position - p.position), 0.0f, 0.2f);
}

TEST(SpaceMouseDrive, AnUnpluggedSourceReportsInvalidAndTheToolStaysPut) {
    Rig rig;
    AnchoredDevice a(rig.device());
    a.setAnchor(ToolPose{});
    rig.queue.push_back(axes(1, kSpaceMouseFullScale, 0, 0));
    const DeviceState before = runFor(a, 0.0, 0.2);
    EXPECT_TRUE(before.valid);
    rig.gone = true;
    testing::internal::CaptureStderr();
    const DeviceState after = runFor(a, 0.201, 0.5);
    const std::string said = testing::internal::GetCapturedStderr();
    EXPECT_FALSE(after.valid);
    EXPECT_EQ(after.buttons, 0u);
    EXPECT_NEAR(after.pose.position.x, before.pose.position.x, 0.01f);
    EXPECT_NE(said.find("stopped answering"), std::string::npos);
    EXPECT_EQ(std::count(said.begin(), said.end(), '\n'), 1) << "said once, in one line";
}

// spacenavd reports x right, y up, z away from the user (its default swap-yz and inversions);
// the reports made from its events drive the tool as the HID device's own would.
TEST(SpaceMouseDrive, SpacenavdEventsBecomeTheDevicesOwnReports) {
    SpaceMouseParser p;
    ASSERT_TRUE(p.feed(spnavTranslationReport(10, 200, -30)));  // right, up, towards the user
    EXPECT_EQ(p.state().translation, glm::ivec3(10, 30, -200)); // device: y towards, z down
    ASSERT_TRUE(p.feed(spnavRotationReport(5, 7, 9)));
    EXPECT_EQ(p.state().rotation, glm::ivec3(5, -9, -7));
    ASSERT_TRUE(p.feed(spaceMouseButtonReport(0x80000002u)));
    EXPECT_EQ(p.state().buttons, 0x80000002u);
    // Lifted through spacenavd: the tool goes up (+z), as lifting the HID device's cap does.
    SpaceMouseConfig c;
    const ToolPose up = integrateSpaceMouse(
        ToolPose{},
        [] {
            SpaceMouseParser q;
            q.feed(spnavTranslationReport(0, kSpaceMouseFullScale, 0));
            return q.state();
        }(),
        1.0, c);
    EXPECT_NEAR(up.position.z, float(c.translationGainMmPerS), 1e-3f);
    // Out-of-range values are clamped to int16, not wrapped.
    p.feed(spnavTranslationReport(40000, 0, 0));
    EXPECT_EQ(p.state().translation.x, 32767);
}

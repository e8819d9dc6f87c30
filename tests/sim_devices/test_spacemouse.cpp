// SpaceMouse HID reports (recorded bytes, one test per format), malformed reports, integration
// into a pose with gain and dead zone, and the vendor/product table.
#include "libsim_devices/spacemouse.h"

#include <cmath>
#include <glm/geometric.hpp>
#include <gtest/gtest.h>
#include <vector>

using namespace trephine;

namespace {
bool feed(SpaceMouseParser& p, std::vector<uint8_t> bytes) {
    return p.feed(bytes);
}
} // namespace

TEST(SpaceMouse, OldStyleSeparateTranslationRotationAndButtons) {
    SpaceMouseParser p;
    // SpaceNavigator: pushed right (x = 100), towards the user (y = -2), down (z = 350).
    EXPECT_TRUE(feed(p, {0x01, 0x64, 0x00, 0xfe, 0xff, 0x5e, 0x01}));
    EXPECT_EQ(p.state().translation, glm::ivec3(100, -2, 350));
    EXPECT_EQ(p.state().rotation, glm::ivec3(0));
    // Twisted: rz = -350 (0xfea2), rx = 1, ry = 0.
    EXPECT_TRUE(feed(p, {0x02, 0x01, 0x00, 0x00, 0x00, 0xa2, 0xfe}));
    EXPECT_EQ(p.state().rotation, glm::ivec3(1, 0, -350));
    EXPECT_EQ(p.state().translation, glm::ivec3(100, -2, 350)); // kept
    EXPECT_TRUE(feed(p, {0x03, 0x02}));                         // right button
    EXPECT_EQ(p.state().buttons, 2u);
    EXPECT_TRUE(feed(p, {0x03, 0x00}));
    EXPECT_EQ(p.state().buttons, 0u);
    EXPECT_EQ(p.state().reports, 4u);
}

TEST(SpaceMouse, NewStyleCombinedReport) {
    SpaceMouseParser p;
    // SpaceMouse Compact / Wireless: 12 bytes after ID 1 (tx ty tz rx ry rz).
    EXPECT_TRUE(
        feed(p, {0x01, 0x0a, 0x00, 0xf6, 0xff, 0x00, 0x00, 0x2c, 0x01, 0x00, 0x00, 0xd4, 0xfe}));
    EXPECT_EQ(p.state().translation, glm::ivec3(10, -10, 0));
    EXPECT_EQ(p.state().rotation, glm::ivec3(300, 0, -300));
    // SpaceMouse Pro: 32-bit button report.
    EXPECT_TRUE(feed(p, {0x03, 0x01, 0x00, 0x00, 0x80}));
    EXPECT_EQ(p.state().buttons, 0x80000001u);
}

TEST(SpaceMouse, MalformedReportsAreIgnored) {
    SpaceMouseParser p;
    feed(p, {0x01, 0x0a, 0x00, 0x0b, 0x00, 0x0c, 0x00});
    const SpaceMouseState before = p.state();
    EXPECT_FALSE(feed(p, {}));
    EXPECT_FALSE(feed(p, {0x01, 0x05, 0x00}));             // short translation
    EXPECT_FALSE(feed(p, {0x02, 0x05, 0x00, 0x06, 0x00})); // short rotation
    EXPECT_FALSE(feed(p, {0x03}));                         // buttons without bytes
    EXPECT_FALSE(feed(p, {0x17, 0x01, 0x02, 0x03, 0x04})); // unknown report ID
    EXPECT_EQ(p.state().translation, before.translation);
    EXPECT_EQ(p.state().rotation, before.rotation);
    EXPECT_EQ(p.state().buttons, before.buttons);
    EXPECT_EQ(p.state().ignored, 5u);
    EXPECT_EQ(p.state().reports, 1u);
}

TEST(SpaceMouse, IntegratesWithGainAndDeadZone) {
    SpaceMouseConfig c;
    c.translationGainMmPerS = 50.0;
    c.rotationGainRadPerS = 1.0;
    c.deadZone = 10;
    SpaceMouseState s;
    s.translation = {kSpaceMouseFullScale, 5, -kSpaceMouseFullScale}; // y inside the dead zone
    ToolPose pose = integrateSpaceMouse(ToolPose{}, s, 0.1, c);
    EXPECT_NEAR(pose.position.x, 5.0f, 1e-4f);
    EXPECT_NEAR(pose.position.y, 0.0f, 1e-6f);
    EXPECT_NEAR(pose.position.z, 5.0f, 1e-4f); // pulled up (device z negative): +z
    EXPECT_EQ(integrateSpaceMouse(pose, s, 0.0, c).position, pose.position);

    SpaceMouseState twist;
    twist.rotation = {0, 0, -kSpaceMouseFullScale}; // object +z at full scale
    ToolPose turned = integrateSpaceMouse(ToolPose{}, twist, 0.5, c);
    glm::vec3 x = turned.orientation * glm::vec3(1, 0, 0);
    EXPECT_NEAR(std::atan2(x.y, x.x), 0.5f, 1e-4f);
    // Leaving the dead zone starts from zero speed: no jump.
    SpaceMouseState edge;
    edge.translation = {11, 0, 0};
    EXPECT_LT(integrateSpaceMouse(ToolPose{}, edge, 1.0, c).position.x, 0.2f);
}

// A read after a stall integrates at most kSpaceMouseMaxStepS of the deflection; a lost device
// (unplugged mid-push) reports invalid with no button held and the tool stays where it was,
// instead of drifting on the last deflection.
TEST(SpaceMouse, AStallMovesTheToolABoundedStepAndALostDeviceHoldsStill) {
    SpaceMouseConfig c;
    c.translationGainMmPerS = 60.0;
    SpaceMouseParser parser;
    const uint8_t push[] = {1, 94, 1, 0, 0, 0, 0}; // x = 350: full push to the right
    const uint8_t button[] = {3, 1};
    ASSERT_TRUE(parser.feed(push));
    ASSERT_TRUE(parser.feed(button));
    ToolPose pose;
    double last = -1.0;
    DeviceState s = spaceMouseStep(pose, last, 1.0, parser.state(), false, c);
    EXPECT_TRUE(s.valid);
    EXPECT_EQ(s.pose.position.x, 0.0f) << "the first read only starts the clock";
    s = spaceMouseStep(pose, last, 1.01, parser.state(), false, c);
    EXPECT_NEAR(s.pose.position.x, 0.6f, 1e-4f); // 60 mm/s for 10 ms
    EXPECT_EQ(s.buttons, 1u);
    s = spaceMouseStep(pose, last, 31.01, parser.state(), false, c); // 30 s later
    EXPECT_NEAR(s.pose.position.x, 0.6f + 60.0f * float(kSpaceMouseMaxStepS), 1e-3f)
        << "not 1800 mm";

    parser.release();
    EXPECT_EQ(parser.state().translation, glm::ivec3(0));
    EXPECT_EQ(parser.state().buttons, 0u);
    const glm::vec3 held = pose.position;
    for (double now : {31.02, 32.0, 40.0}) {
        s = spaceMouseStep(pose, last, now, parser.state(), true, c);
        EXPECT_FALSE(s.valid);
        EXPECT_EQ(s.buttons, 0u);
        EXPECT_EQ(s.pose.position, held);
    }
}

TEST(SpaceMouse, KnowsTheVendorsAndProducts) {
    EXPECT_TRUE(isSpaceMouse(0x046d, 0xc626));  // SpaceNavigator
    EXPECT_TRUE(isSpaceMouse(0x256f, 0xc635));  // SpaceMouse Compact
    EXPECT_FALSE(isSpaceMouse(0x046d, 0xc52b)); // a Logitech receiver
    EXPECT_FALSE(isSpaceMouse(0x1234, 0xc626));
}

// 3Dconnexion's own vendor ID also covers mice and keyboards: the CadMouse is no 6-DOF device.
TEST(SpaceMouse, RefusesThe3DconnexionProductsThatAreNotSpaceMice) {
    EXPECT_FALSE(isSpaceMouse(0x256f, 0xc650));             // CadMouse
    EXPECT_FALSE(isSpaceMouse(0x256f, 0xc651));             // CadMouse Wireless
    EXPECT_FALSE(isSpaceMouse(0x256f, 0xc650, 0x01, 0x08)); // refused even if it said so
    EXPECT_FALSE(isSpaceMouse(0x256f, 0xc6ff));             // unknown, no usage
    EXPECT_TRUE(isSpaceMouse(0x256f, 0xc6ff, 0x01, 0x08));  // unknown, multi-axis controller
    EXPECT_TRUE(isSpaceMouse(0x256f, 0xc62e));              // SpaceMouse Wireless (cable)
    EXPECT_TRUE(isSpaceMouse(0x256f, 0xc633, 0x01, 0x08));  // SpaceMouse Enterprise
    // The Universal Receiver's interfaces: the SpaceMouse's is taken, a paired CadMouse's
    // (Generic Desktop, Mouse) is not.
    EXPECT_TRUE(isSpaceMouse(0x256f, 0xc652, 0x01, 0x08));
    EXPECT_FALSE(isSpaceMouse(0x256f, 0xc652, 0x01, 0x02));
    // Under Logitech's vendor ID the product IDs are 3Dconnexion's alone: the usage is not asked.
    EXPECT_TRUE(isSpaceMouse(0x046d, 0xc626, 0x01, 0x04));
}

TEST(SpaceMouse, EnumerationWithoutDevicesIsClean) {
    // No assertion on the count: this machine may have HID devices. It must not crash.
    for (const HidDeviceInfo& d : enumerateHidDevices())
        EXPECT_EQ(d.usable, isSpaceMouse(d.vendorId, d.productId, d.usagePage, d.usage));
}

// The hardware-free devices: null, scripted (interpolation) and mouse.
#include "libsim_devices/devices.h"

#include <glm/geometric.hpp>
#include <glm/gtc/quaternion.hpp>
#include <gtest/gtest.h>

using namespace trephine;

TEST(Devices, NullReportsNothing) {
    NullDevice d;
    EXPECT_FALSE(d.read(0.0).valid);
}

TEST(Devices, ScriptedInterpolatesPositionAndOrientation) {
    ToolPose a, b;
    a.position = {0, 0, 0};
    b.position = {10, 0, 20};
    b.orientation = glm::angleAxis(1.0f, glm::vec3(0, 0, 1));
    ScriptedDevice d({{2.0, b, 1}, {0.0, a, 0}}); // unsorted on purpose
    EXPECT_EQ(d.read(-1.0).pose.position, a.position);
    DeviceState mid = d.read(1.0);
    EXPECT_TRUE(mid.valid);
    EXPECT_NEAR(glm::distance(mid.pose.position, glm::vec3(5, 0, 10)), 0.0f, 1e-5f);
    EXPECT_NEAR(glm::angle(mid.pose.orientation), 0.5f, 1e-4f);
    DeviceState end = d.read(3.0);
    EXPECT_EQ(end.pose.position, b.position);
    EXPECT_EQ(end.buttons, 1u);
    d.setForce({1, 2, 3});
    EXPECT_EQ(d.lastForce(), glm::vec3(1, 2, 3));
}

TEST(Devices, MouseReturnsWhatWasSet) {
    MouseDevice m;
    EXPECT_FALSE(m.read(0.0).valid);
    ToolPose p;
    p.position = {1, 2, 3};
    m.setPose(p, 4);
    DeviceState s = m.read(0.0);
    EXPECT_TRUE(s.valid);
    EXPECT_EQ(s.pose.position, p.position);
    EXPECT_EQ(s.buttons, 4u);
}

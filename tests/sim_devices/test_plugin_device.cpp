// Device plugins through the C ABI: loading and its one-line refusals, the simulated hand's
// physics, cutting off plugins that fail or hang, and the guard every force device goes through.
#include "libsim_devices/plugin_device.h"

#include "libsim/device_guard.h"
#include "libsim_devices/devices.h"

#include <glm/geometric.hpp>
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <string>
#include <vector>

using namespace trephine;

namespace {

const std::string kPlugins = TREPHINE_PLUGIN_DIR;
const std::string kSim = kPlugins + "/trephine_sim_device.so";
const std::string kFaulty = kPlugins + "/trephine_faulty_device.so";

// Opens `spec`, collecting the lines the device reports.
std::unique_ptr<PluginDevice> open(const std::string& spec, std::vector<std::string>& lines,
                                   double deadlineS = 0.001) {
    PluginOptions o;
    o.deadlineS = deadlineS;
    o.report = [&lines](const std::string& line) { lines.push_back(line); };
    std::string error;
    auto d = openPlugin(spec, o, error);
    EXPECT_TRUE(d) << error;
    return d;
}

std::string refusal(const std::string& spec) {
    std::string error;
    EXPECT_EQ(openPluginDevice(spec, error), nullptr);
    EXPECT_EQ(error.find('\n'), std::string::npos);
    return error;
}

// Ticks as the loop does (read, write) until the device is cut off (true) or `seconds` of wall
// time pass (false). The plugin's worker runs on its own thread, so the test waits for it, not
// for a fixed time.
bool readUntilCut(PluginDevice& d, double seconds) {
    const auto until = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds);
    for (double t = 0; std::chrono::steady_clock::now() < until; t += 0.001) {
        d.read(t);
        d.setForce({1, 0, 0});
        if (!d.fault().empty())
            return true;
    }
    return false;
}

} // namespace

TEST(PluginDevice, TheSimulatedDeviceLoadsThroughTheAbi) {
    std::vector<std::string> lines;
    auto d = open(kSim + "?mass=0.2,maxforce=5", lines, 1.0);
    ASSERT_TRUE(d);
    EXPECT_EQ(d->name(), "plugin:simulated hand 0.20 kg");
    EXPECT_TRUE(d->hasForceOutput());
    EXPECT_TRUE(d->acceptsIntent());
    EXPECT_FLOAT_EQ(d->maxForceN(), 5.0f);
    EXPECT_EQ(d->workspace().max, glm::vec3(150.0f));
    EXPECT_TRUE(d->read(0.0).valid);
    EXPECT_EQ(d->fault(), "");
}

TEST(PluginDevice, WhatCannotBeLoadedIsRefusedInOneLine) {
    EXPECT_EQ(refusal(""), "device plugin: no file given (plugin:PATH.so)");
    EXPECT_EQ(refusal("/nowhere/x.so").rfind("device plugin /nowhere/x.so: cannot load it: ", 0),
              0u);
    EXPECT_EQ(refusal("/lib/x86_64-linux-gnu/libz.so.1"),
              "device plugin /lib/x86_64-linux-gnu/libz.so.1: no trephine_device_api entry point "
              "(is it a Trephine device plugin?)");
    EXPECT_EQ(refusal(kPlugins + "/trephine_future_device.so"),
              "device plugin " + kPlugins +
                  "/trephine_future_device.so: it does not serve device ABI version 1");
    EXPECT_EQ(refusal(kSim + "?grip=3"),
              "device plugin " + kSim +
                  ": open failed: unknown argument 'grip' (mass, k, c, maxforce, half)");
    EXPECT_EQ(refusal(kSim + "?mass=-1"), "device plugin " + kSim +
                                              ": open failed: argument mass needs a non-negative "
                                              "number, got '-1'");
}

// A force held on the hand moves it off its intent until the spring balances it: F / k. The
// motors saturate at the device's maximum.
TEST(PluginDevice, TheSimulatedHandFeelsTheForceItIsSent) {
    std::vector<std::string> lines;
    auto d = open(kSim + "?k=1,maxforce=8", lines, 1.0); // generous: this test is about physics
    ASSERT_TRUE(d);
    ToolPose intent;
    intent.position = {10, 20, 30};
    d->setIntent(intent);
    EXPECT_EQ(d->read(0.0).pose.position, intent.position); // the first intent places the hand
    double t = 0.0;
    auto hold = [&](glm::vec3 f, double seconds) {
        for (int i = 0; i < int(seconds * 1000); ++i) {
            d->setForce(f);
            d->read(t += 0.001);
        }
        return d->read(t += 0.001);
    };
    DeviceState s = hold({0, 0, 2}, 2.0);
    EXPECT_NEAR(s.pose.position.z - intent.position.z, 2.0f, 0.02f);
    EXPECT_NEAR(s.pose.position.x, intent.position.x, 1e-3f);
    EXPECT_EQ(d->history().back().applied, glm::vec3(0, 0, 2));
    s = hold({0, 0, -20}, 2.0);
    EXPECT_NEAR(s.pose.position.z - intent.position.z, -8.0f, 0.05f);
    EXPECT_NEAR(d->history().back().applied.z, -8.0f, 1e-4f);
    EXPECT_TRUE(lines.empty());
}

TEST(PluginDevice, AFailingCallCutsTheDeviceOffWithOneLine) {
    std::vector<std::string> lines;
    auto d = open(kFaulty + "?mode=fail,after=3,ms=0", lines, 1.0);
    ASSERT_TRUE(d);
    EXPECT_TRUE(d->read(0.000).valid);
    EXPECT_TRUE(d->read(0.001).valid);
    EXPECT_FALSE(d->read(0.002).valid);
    ASSERT_EQ(lines.size(), 1u);
    EXPECT_EQ(lines[0], "device plugin " + kFaulty +
                            ": read failed (7): the test plugin fails on purpose; force output "
                            "cut off");
    EXPECT_EQ(d->fault(), lines[0]);
    const uint64_t calls = d->calls();
    for (int i = 0; i < 10; ++i) {
        d->setForce({1, 0, 0});
        EXPECT_FALSE(d->read(0.003 + i * 0.001).valid);
    }
    EXPECT_LE(d->calls(), calls + 1); // at most the one last zero force
    EXPECT_EQ(lines.size(), 1u);
}

// A read that hangs costs the tick its deadline, not the hang: that read comes back invalid (the
// loop outputs zero force), and the device is cut off once the call has been inside for hangS.
// (The reads before the hang are not checked: on a loaded machine the worker may wake later than
// the 1 ms deadline, and such a tick reads invalid too.)
TEST(PluginDevice, AHangingReadIsCutOffWithinATick) {
    std::vector<std::string> lines;
    auto d = open(kFaulty + "?mode=hang,after=1,ms=400", lines, 0.001);
    ASSERT_TRUE(d);
    const auto before = std::chrono::steady_clock::now();
    EXPECT_FALSE(d->read(0.0).valid);
    const double tookS =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - before).count();
    EXPECT_LT(tookS, 0.2); // the deadline, not the 0.4 s hang
    ASSERT_TRUE(readUntilCut(*d, 5.0));
    ASSERT_EQ(lines.size(), 1u);
    EXPECT_EQ(lines[0], "device plugin " + kFaulty +
                            ": read did not return within 20.0 ms; force output cut off");
    EXPECT_GE(d->missedTicks(), 1u);
}

TEST(PluginDevice, AHangingForceWriteIsCutOffToo) {
    std::vector<std::string> lines;
    auto d = open(kFaulty + "?mode=hangwrite,after=1,ms=400", lines, 0.001);
    ASSERT_TRUE(d);
    ASSERT_TRUE(readUntilCut(*d, 5.0)); // the first write after the first read hangs
    ASSERT_EQ(lines.size(), 1u);
    EXPECT_NE(lines[0].find("write_force did not return within 20.0 ms"), std::string::npos)
        << lines[0];
}

// One slow call (a preemption, a USB hiccup) costs its ticks' force, not the session's: a read
// that takes 5 ms, under hangS, reads invalid meanwhile and the device then goes on.
TEST(PluginDevice, OneSlowCallIsNotAHang) {
    std::vector<std::string> lines;
    auto d = open(kFaulty + "?mode=hang,after=2,ms=5", lines, 0.001);
    ASSERT_TRUE(d);
    int valid = 0;
    const auto until = std::chrono::steady_clock::now() + std::chrono::milliseconds(300);
    for (double t = 0; std::chrono::steady_clock::now() < until; t += 0.001) {
        valid += d->read(t).valid;
        d->setForce({1, 0, 0});
    }
    EXPECT_EQ(d->fault(), "");
    EXPECT_TRUE(lines.empty());
    EXPECT_GT(valid, 10) << "reads after the slow one come back";
}

// Closing a device whose plugin never comes back does not hang the host.
TEST(PluginDevice, ClosingAStuckPluginReturns) {
    std::vector<std::string> lines;
    auto d = open(kFaulty + "?mode=hang,after=1,ms=3000", lines, 0.001);
    ASSERT_TRUE(d);
    ASSERT_TRUE(readUntilCut(*d, 5.0));
    const auto before = std::chrono::steady_clock::now();
    d.reset();
    EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - before).count(),
              2.0);
    ASSERT_EQ(lines.size(), 2u);
    EXPECT_EQ(lines.back(),
              "device plugin " + kFaulty + ": read still running at close; left loaded");
}

// [SECTION] the guard

TEST(DeviceGuard, ClampsToTheDevicesMaximumAndLimitsEachStep) {
    std::vector<std::string> lines;
    auto plugin = open(kSim + "?maxforce=3", lines, 1.0);
    ASSERT_TRUE(plugin);
    DeviceGuard guard(*plugin, {.maxForceN = 8.5f, .maxStepN = 1.0f});
    EXPECT_FLOAT_EQ(guard.maxForceN(), 3.0f); // the lower of the two
    std::vector<float> out;
    for (int i = 0; i < 6; ++i) {
        ASSERT_TRUE(guard.read(i * 0.001).valid);
        guard.setForce({0, 0, 10});
        out.push_back(guard.lastOutput().z);
    }
    EXPECT_EQ(out, (std::vector<float>{1, 2, 3, 3, 3, 3}));
    EXPECT_EQ(guard.stats().clamped, 6u);
    EXPECT_EQ(guard.stats().limited, 2u);
    guard.read(0.006);
    guard.setForce({0, 0, 0}); // a drop to zero is never spread out
    EXPECT_EQ(guard.lastOutput(), glm::vec3(0.0f));
}

TEST(DeviceGuard, ZeroAtOnceWhenGatedInvalidNotFiniteOrReleased) {
    ScriptedDevice device({{0.0, ToolPose{}, 0}});
    DeviceGuard guard(device, {.maxForceN = 8.5f, .maxStepN = 10.0f});
    bool linkUp = true;
    guard.setGate([&] { return linkUp; });
    guard.read(0.0);
    guard.setForce({0, 4, 0});
    EXPECT_EQ(device.lastForce(), glm::vec3(0, 4, 0));
    linkUp = false;
    guard.read(0.001);
    guard.setForce({0, 4, 0});
    EXPECT_EQ(device.lastForce(), glm::vec3(0.0f)); // the link is down: not driven
    linkUp = true;
    guard.read(0.002);
    guard.setForce({0, NAN, 0});
    EXPECT_EQ(device.lastForce(), glm::vec3(0.0f));
    guard.read(0.003);
    guard.setForce({0, 4, 0});
    EXPECT_EQ(device.lastForce(), glm::vec3(0, 4, 0));
    guard.release();
    EXPECT_EQ(device.lastForce(), glm::vec3(0.0f));
    guard.read(0.004);
    guard.setForce({0, 4, 0});
    EXPECT_EQ(device.lastForce(), glm::vec3(0.0f)); // the session is over: never again
    EXPECT_EQ(guard.stats().gated, 3u);
}

TEST(DeviceGuard, HandsTheIntentToASimulatedHand) {
    std::vector<std::string> lines;
    auto plugin = open(kSim, lines, 1.0);
    ASSERT_TRUE(plugin);
    DeviceGuard guard(*plugin);
    guard.setIntentSource([](double now) {
        ToolPose p;
        p.position = {float(now * 1000.0), 0, 0};
        return std::optional<ToolPose>(p);
    });
    EXPECT_EQ(guard.read(0.005).pose.position, glm::vec3(5, 0, 0)); // placed on the first intent
}

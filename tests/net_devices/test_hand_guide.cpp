// A felt take-over with the simulated force device, through the plugin ABI: a relaxed trainee's
// device (no grip of its own) is guided by the instructor who holds it along the instructor's
// path, settles on it without oscillating, and goes quiet at the hand-back. The pumped server
// and the instructor run on the test's thread; the trainee's core runs its own threads in real
// time, as a window's does.
#include "libsim_devices/plugin_device.h"
#include "net/session_client.h"
#include "net/session_server.h"
#include "net/trainee_core.h"

#include "libsim/skull.h"

#include "loopback.h"

#include <glm/geometric.hpp>
#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cstdio>

using namespace trephine;
using namespace trephine::net;
using trephine::testing::pumpUntil;

namespace {

const std::string kPlugins = TREPHINE_PLUGIN_DIR;

double secondsSince(std::chrono::steady_clock::time_point t0) {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

} // namespace

TEST(FeltTakeOver, TheTraineesDeviceFollowsTheInstructorsPathAndSettles) {
    Volume sphere = makeSphere(32);
    SessionServer server{sphere, trephine::testing::loopbackServerConfig("sphere:32")};
    trephine::testing::Pumped pumped{server};
    // In the air above the sphere: no bone pushes on either tool.
    const glm::vec3 a(0, 0, sphereRadiusMm(32) + 30.0f), b = a + glm::vec3(20, 0, 0);
    constexpr double kMoveS = 1.0, kHoldS = 1.0;

    std::string error;
    std::unique_ptr<PluginDevice> device =
        openPlugin(kPlugins + "/trephine_sim_device.so?k=0,c=0.002", {}, error);
    ASSERT_TRUE(device) << error;
    ScriptSample rest;
    rest.tool.position = a;
    ScriptToolSource tools(*device, {rest}, 1e9);

    TraineeCoreConfig tc;
    tc.client.client = trephine::testing::namedClientConfig(sphere, "Ada", Role::Trainee, 32);
    tc.client.address = "127.0.0.1:" + std::to_string(server.port());
    TraineeCore ada(tc);
    ada.connect();
    SessionClient cho(
        trephine::testing::namedClientConfig(sphere, "Dr. Cho", Role::Instructor, 32));
    cho.connect(trephine::testing::loopback(server.port()));
    ASSERT_TRUE(pumpUntil({&cho}, [&] {
        return cho.welcomed() && ada.client().snapshot()->welcome && cho.participants().size() == 2;
    }));
    ada.startHaptics(tools);
    const uint16_t adaId = ada.client().snapshot()->welcome->clientId;

    // The instructor takes the trainee over, guides its hand, and holds its tool at the start.
    cho.takeOver(adaId);
    cho.send(HandLinks{{{0, 0, true}}});
    uint32_t sequence = 0;
    auto toolAt = [&](glm::vec3 p) {
        ToolState t;
        t.sequence = ++sequence;
        t.diameterMm = 5.0f;
        t.position = p;
        cho.sendToolState(t);
    };
    ASSERT_TRUE(pumpUntil({&cho}, [&] {
        toolAt(a);
        return ada.guidedTicks() > 400; // the pull's ramp done (HandGuideConfig::rampS)
    }));

    // Along the path at 20 mm/s, then held at its end; the device's distance from the
    // instructor's tool is sampled every 10 ms.
    double maxLag = 0, overshoot = 0, settled = 0;
    const auto t0 = std::chrono::steady_clock::now();
    for (double t = 0; t < kMoveS + kHoldS; t = secondsSince(t0)) {
        const glm::vec3 target = glm::mix(a, b, float(std::min(t / kMoveS, 1.0)));
        toolAt(target);
        pumpUntil(
            {&cho}, [] { return false; }, 0.01);
        const std::vector<HapticSample> s = ada.hapticSamples();
        const glm::vec3 p = s.back().position;
        const double lag = glm::length(p - target);
        if (t < kMoveS)
            maxLag = std::max(maxLag, lag);
        else
            overshoot = std::max(overshoot, double(p.x - b.x));
        settled = lag; // the last sample's, once the loop ends
    }
    std::printf("[ figures  ] lag while moving at 20 mm/s: max %.2f mm; overshoot past the end "
                "%.3f mm; distance at the end %.3f mm\n",
                maxLag, overshoot, settled);
    EXPECT_LT(maxLag, 4.0) << "the device follows the instructor's path";
    EXPECT_LT(overshoot, 0.3) << "and settles without oscillating past it";
    EXPECT_LT(settled, 0.5);

    // Handed back: the guide ends, and the device feels nothing in the air.
    cho.takeOver(0);
    ASSERT_TRUE(pumpUntil({&cho}, [&] { return !guideTarget(*ada.client().snapshot()); }));
    // The loop reads that snapshot within a tick, then the pull fades out over its ramp.
    pumpUntil(
        {&cho}, [] { return false; }, 0.05 + HandGuideConfig{}.rampS);
    const uint64_t after = ada.guidedTicks();
    pumpUntil(
        {&cho}, [] { return false; }, 0.1);
    EXPECT_EQ(ada.guidedTicks(), after) << "no guide after the hand-back";
    EXPECT_EQ(ada.hapticSamples().back().force, glm::vec3(0.0f));
    ada.stop();
}

// An instructor feeling a trainee: its device, in the air, gets the trainee's force on the bone
// (the relayed models, relayed for plotting before), and nothing once it stops feeling.
TEST(FeltTakeOver, AnInstructorFeelsTheTraineesDrillOnTheBone) {
    Volume sphere = makeSphere(32);
    SessionServer server{sphere, trephine::testing::loopbackServerConfig("sphere:32")};
    trephine::testing::Pumped pumped{server};
    std::string error;
    std::unique_ptr<PluginDevice> device =
        openPlugin(kPlugins + "/trephine_sim_device.so", {}, error);
    ASSERT_TRUE(device) << error;
    ScriptSample rest;
    rest.tool.position = glm::vec3(0, 0, sphereRadiusMm(32) + 30.0f);
    ScriptToolSource tools(*device, {rest}, 1e9);
    TraineeCoreConfig tc;
    tc.client.client =
        trephine::testing::namedClientConfig(sphere, "Dr. Cho", Role::Instructor, 32);
    tc.client.address = "127.0.0.1:" + std::to_string(server.port());
    TraineeCore cho(tc);
    cho.connect();
    SessionClient ada(trephine::testing::namedClientConfig(sphere, "Ada", Role::Trainee, 32));
    ada.connect(trephine::testing::loopback(server.port()));
    ASSERT_TRUE(pumpUntil({&ada}, [&] {
        return ada.welcomed() && cho.client().snapshot()->welcome && ada.participants().size() == 2;
    }));
    cho.startHaptics(tools);
    ClientThread& thread = cho.client();
    ASSERT_TRUE(thread.send(HandLinks{{{0, ada.welcome().clientId, false}}}));

    // The trainee presses into the top of the sphere, 10 ms a state, until the instructor's
    // device has felt a push for a while.
    const SurfaceSite top{glm::vec3(0, 0, sphereRadiusMm(32)), glm::vec3(0, 0, 1)};
    int i = 0;
    float strongest = 0;
    ASSERT_TRUE(pumpUntil(
        {&ada},
        [&] {
            ToolState t = trephine::testing::burrState(top, std::min(i, 20), 40, 0);
            t.sequence = uint32_t(++i);
            t.drilling = false; // pressing, not cutting: the push stays
            ada.sendToolState(t);
            pumpUntil(
                {&ada}, [] { return false; }, 0.01);
            for (const HapticSample& h : cho.hapticSamples())
                strongest = std::max(strongest, glm::length(h.force));
            return cho.feltTicks() > 300 && strongest > 0.5f;
        },
        20.0))
        << "strongest felt " << strongest << " N in " << cho.feltTicks() << " ticks";

    // Stops feeling: its own tool is in the air, so its force goes to zero.
    ASSERT_TRUE(thread.send(HandLinks{{{0, 0, false}}}));
    ASSERT_TRUE(pumpUntil({&ada}, [&] {
        const std::vector<HapticSample> s = cho.hapticSamples();
        return !s.empty() && glm::length(s.back().force) < 1e-3f;
    }));
    cho.stop();
}

// Multi-rate haptics across the network (issue 5): the haptics study's simulated hand, but every
// force model it feels is a real SessionServer's answer over loopback ENet. The hand is integrated
// on simulated time at 1 kHz; every 50 ms of simulated time (20 Hz) the client sends its tool state
// and the test's thread pumps the server (wall time, deadline-guarded) until the HapticModel
// answering it arrives. Deterministic: the wire only carries the models, and nothing asserts wall
// time.
#include "net/session_client.h"
#include "net/session_server.h"

#include "libsim/skull.h"
#include "net/view.h"
#include "study/haptics_study.h"

#include "loopback.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <functional>

using namespace trephine;
using namespace trephine::net;
using namespace trephine::study;

namespace {

using trephine::testing::loopback;
using trephine::testing::loopbackServerConfig;
using trephine::testing::Pumped;
using trephine::testing::pumpUntil;

// A HapticModelSource that asks the server: sends the sampled pose as a (non-drilling) tool state
// and pumps the client until the model answering that sequence has arrived.
struct ServerModels {
    SessionClient& client;
    ToolShape shape;
    int answered = 0;
    int lost = 0;          // no answer within the guard (the run then gets no force from it)
    int wrongPosition = 0; // answers whose P_N is not the pose sent

    HapticModelData operator()(const ToolPose& pose) {
        HapticModelData d;
        d.position = pose.position;
        if (lost > 0)
            return d; // one hang is enough: do not wait again for each remaining update
        ToolState t;
        t.toolKind = uint8_t(shape.kind);
        t.diameterMm = shape.diameterMm;
        t.position = pose.position;
        t.orientation = pose.orientation;
        t.drilling = false; // the bone must not change under the hand
        const uint32_t seq = client.sendToolState(t);
        auto answer = [&] {
            auto m = client.latestHapticModel();
            return m && m->toolSequence == seq;
        };
        if (!pumpUntil({&client}, answer, 20.0)) {
            ++lost;
            return d;
        }
        const HapticModel m = *client.latestHapticModel();
        ++answered;
        if (m.position != pose.position)
            ++wrongPosition;
        d.force = m.force;
        d.gradient = m.gradient;
        d.contact = m.contact;
        return d;
    }
};

} // namespace

// The paper's claim end to end: with models at 20 Hz from a real server, multi-rate extrapolation
// keeps the hand's contact stable (bounded penetration, no injected energy, no growing
// oscillation); a zero-order hold of the same models does not, and neither does multi-rate with
// the gradient dropped (so the result hinges on the extrapolation itself).
TEST(HapticsLoopback, MultirateStableAt20HzOverLoopbackWhereZeroOrderHoldIsNot) {
    const Volume box = makeBox(48);
    const SurfaceSite site = boxTopSite(box);
    HapticsStudyConfig config; // 2 mm burr, 2 s, hand target 2 mm inside, 1 kHz haptics
    ASSERT_EQ(config.shape.kind, ToolKind::Burr);

    SessionServer server(box, loopbackServerConfig("box:48"));
    Pumped pumped(server);
    ClientConfig cc;
    cc.view = toViewSpec(cameraPreset("top", box, {16, 16}));
    SessionClient client(cc);
    client.connect(loopback(server.port()));
    ASSERT_TRUE(pumpUntil(
        {&client}, [&] { return client.hasFullImage(); }, 60.0));

    auto overLoopback = [&](HapticMethod method, bool gradient, int& models) {
        HapticsStudyConfig c = config;
        c.multirateUsesGradient = gradient;
        ServerModels source{client, c.shape};
        HapticsCaseResult r = runHapticsCase(box, site, c, {method, 20.0, 0.0}, std::ref(source));
        EXPECT_EQ(source.lost, 0) << "the server did not answer a tool state";
        EXPECT_EQ(source.wrongPosition, 0);
        // The warm start plus one model per 50 ms of simulated time, every one from the server.
        EXPECT_EQ(source.answered, r.modelsDelivered + 1);
        EXPECT_EQ(r.modelsDelivered, int(config.durationS * 20.0) - 1);
        models += source.answered;
        std::printf("loopback %s%s: %s\n", hapticMethodName(method), gradient ? "" : " (no grad)",
                    hapticsCsvRow(r).c_str());
        return r;
    };
    int models = 0;
    const HapticsCaseResult mr = overLoopback(HapticMethod::Multirate, true, models);
    const HapticsCaseResult zoh = overLoopback(HapticMethod::ZeroOrderHold, true, models);
    const HapticsCaseResult noGrad = overLoopback(HapticMethod::Multirate, false, models);
    ASSERT_FALSE(HasFailure());
    EXPECT_EQ(server.hapticModelsSent(), uint64_t(models));
    EXPECT_EQ(client.hapticModelsReceived(), uint64_t(models));
    EXPECT_EQ(client.stats().hapticRoundTripUs.totalCount(), uint64_t(models));

    // Multi-rate over the network: stable.
    EXPECT_TRUE(mr.stable) << hapticsCsvRow(mr);
    EXPECT_LE(mr.maxPenetrationMm, config.hand.targetDepthMm + config.maxOvershootMm);
    EXPECT_LT(mr.energyInjectedJ, config.maxEnergyInjectedJ);
    EXPECT_LE(mr.excessOscillationMm, config.maxExcessOscillationMm);
    EXPECT_LE(mr.finalOscillationMm, 1.5 * mr.earlyOscillationMm + 0.01); // not growing
    EXPECT_GT(mr.meanForceN, 0.1) << "the hand is in contact";

    // Zero-order hold of the same server's models: measurably worse, and not stable.
    EXPECT_FALSE(zoh.stable) << hapticsCsvRow(zoh);
    EXPECT_GT(zoh.forceRmsErrorN, 10.0 * mr.forceRmsErrorN);
    EXPECT_GT(zoh.energyInjectedJ, 10.0 * std::max(mr.energyInjectedJ, 1e-6));
    EXPECT_GT(zoh.finalOscillationMm, 2.0 * mr.finalOscillationMm);

    // The ablation: blending the server's f without its gradient is not enough.
    EXPECT_FALSE(noGrad.stable) << hapticsCsvRow(noGrad);

    // The wire carries the models exactly: the same runs in process give the same numbers.
    for (const HapticsCaseResult* r : {&mr, &zoh}) {
        const HapticsCaseResult local = runHapticsCase(box, site, config, r->c);
        EXPECT_EQ(hapticsCsvRow(local), hapticsCsvRow(*r));
    }
    client.disconnect();
    server.stop();
}

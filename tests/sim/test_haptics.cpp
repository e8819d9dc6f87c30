// Multi-rate haptics: extrapolation, blending bounds, stale fading, the haptic loop's throttled
// sends and local mode. The haptics study's stability contrast is in tests/study.
#include "libsim/haptics.h"

#include "libsim/skull.h"

#include <atomic>
#include <cmath>
#include <deque>
#include <glm/geometric.hpp>
#include <gtest/gtest.h>
#include <random>
#include <sstream>
#include <thread>

using namespace trephine;

namespace {

HapticModelData modelAt(glm::vec3 p, glm::vec3 f, float stiffness) {
    HapticModelData m;
    m.position = p;
    m.force = f;
    m.gradient = glm::mat3(-stiffness);
    m.contact = true;
    return m;
}

// A device that stays where the test puts it and remembers the last force.
class TestDevice : public Device {
public:
    std::string name() const override { return "test"; }
    DeviceState read(double) override {
        DeviceState s;
        s.pose.position = position;
        s.valid = !missing;
        return s;
    }
    void setForce(glm::vec3 f) override { force = f; }
    glm::vec3 position{0.0f};
    glm::vec3 force{0.0f};
    bool missing = false; // reads give no pose, as a late or cut-off device's do
};

} // namespace

TEST(Haptics, ExtrapolationReproducesTheModelAtItsPosition) {
    HapticModelData m = modelAt({1.5f, -2.0f, 30.25f}, {0.3f, -0.2f, 2.5f}, 3.0f);
    m.gradient[0][1] = m.gradient[1][0] = 0.7f;
    EXPECT_EQ(extrapolate(m, m.position), m.force);
    glm::vec3 d(0.1f, 0.0f, -0.2f);
    glm::vec3 expect = m.force + m.gradient * d;
    EXPECT_LT(glm::length(extrapolate(m, m.position + d) - expect), 1e-5f);

    // Through the blender once the blend is over: the same force at P_N.
    ModelBlender blender;
    blender.setModel(m, 0.0);
    glm::vec3 f(0.0f);
    for (int i = 0; i <= 200; ++i)
        f = blender.update(m.position, i * 1e-3);
    EXPECT_EQ(blender.blendFraction(), 1.0);
    EXPECT_LT(glm::length(f - m.force), 1e-6f);
}

TEST(Haptics, ClampKeepsDirectionAndDropsNaN) {
    glm::vec3 c = clampForce({30.0f, 40.0f, 0.0f}, 5.0f);
    EXPECT_NEAR(glm::length(c), 5.0f, 1e-5f);
    EXPECT_NEAR(c.x / c.y, 0.75f, 1e-5f);
    EXPECT_EQ(clampForce({NAN, 0.0f, 0.0f}, 5.0f), glm::vec3(0.0f));
    EXPECT_EQ(clampForce({1.0f, 0.0f, 0.0f}, 5.0f), glm::vec3(1.0f, 0.0f, 0.0f));
}

TEST(Haptics, BlendingNeverStepsMoreThanTheBound) {
    BlendConfig config;
    config.maxStepN = 0.1;
    ModelBlender blender(config);
    const glm::vec3 p(0.0f, 0.0f, 10.0f);
    glm::vec3 prev = blender.update(p, 0.0);
    double maxStep = 0.0;
    // Models alternating between far-apart forces at 20 Hz, plus one arriving mid-blend.
    int tick = 0;
    for (int k = 0; k < 10; ++k) {
        glm::vec3 f = (k % 2) ? glm::vec3(0, 0, 6.0f) : glm::vec3(2.0f, 0, -3.0f);
        blender.setModel(modelAt(p + glm::vec3(0.3f, 0, 0), f, 4.0f), tick * 1e-3);
        for (int i = 0; i < (k == 5 ? 7 : 50); ++i, ++tick) {
            glm::vec3 out = blender.update(p, tick * 1e-3);
            maxStep = std::max(maxStep, double(glm::length(out - prev)));
            prev = out;
        }
    }
    EXPECT_LE(maxStep, config.maxStepN + 1e-5);
    EXPECT_GT(maxStep, 0.5 * config.maxStepN); // it did have to limit
}

TEST(Haptics, BlendTakesAboutOneUpdatePeriod) {
    BlendConfig config;
    config.maxStepN = 100.0; // not the limit here
    ModelBlender blender(config);
    const glm::vec3 p(0.0f);
    blender.resetTo(modelAt(p, {0, 0, 1.0f}, 0.0f), 0.0);
    blender.setModel(modelAt(p, {0, 0, 2.0f}, 0.0f), 0.05); // 50 ms after the last: 20 Hz
    blender.update(p, 0.05);
    glm::vec3 mid = blender.update(p, 0.075);
    EXPECT_NEAR(mid.z, 1.5f, 0.02f);
    glm::vec3 end = blender.update(p, 0.1);
    EXPECT_NEAR(end.z, 2.0f, 1e-5f);
}

// The blender finds when the state a model answers was sent from the model's P_N (the device
// position of the sending tick, bit for bit), and blends over delay^2 / delayBlendScaleS when that
// is longer than the interval between models.
TEST(Haptics, TheBlendGrowsWithTheRoundTripTheBlenderMeasures) {
    BlendConfig config;
    config.maxStepN = 100.0;     // not the limit here
    config.staleTimeoutS = 10.0; // nor fading
    ModelBlender blender(config);
    auto at = [](int tick) { return glm::vec3(0.01f * float(tick), 0.0f, 0.0f); };
    blender.resetTo(modelAt(at(0), {0, 0, 1.0f}, 0.0f), 0.0);
    for (int i = 0; i <= 400; ++i) // the device moves 0.01 mm a tick at 1 kHz
        blender.update(at(i), i * 1e-3);
    // Arrives at 400 ms, answering the state sent at 100 ms, 10 ms after the previous model.
    blender.setModel(modelAt(at(90), {0, 0, 1.0f}, 0.0f), 0.39);
    blender.setModel(modelAt(at(100), {0, 0, 2.0f}, 0.0f), 0.4);
    EXPECT_NEAR(blender.delayEstimate(), 0.3, 1e-9);
    // 0.3^2 / 1 s = 90 ms, not the 10 ms between the models.
    EXPECT_NEAR(blender.update(at(401), 0.445).z, 1.5f, 0.02f);
    EXPECT_LT(blender.update(at(402), 0.48).z, 2.0f);
    EXPECT_NEAR(blender.update(at(403), 0.49).z, 2.0f, 1e-5f);

    // Scale 0: the blend is the interval between models again.
    config.delayBlendScaleS = 0.0;
    ModelBlender plain(config);
    plain.resetTo(modelAt(at(0), {0, 0, 1.0f}, 0.0f), 0.0);
    for (int i = 0; i <= 400; ++i)
        plain.update(at(i), i * 1e-3);
    plain.setModel(modelAt(at(90), {0, 0, 1.0f}, 0.0f), 0.39);
    plain.setModel(modelAt(at(100), {0, 0, 2.0f}, 0.0f), 0.4);
    EXPECT_NEAR(plain.delayEstimate(), 0.3, 1e-9);
    EXPECT_NEAR(plain.update(at(401), 0.41).z, 2.0f, 1e-5f);
}

// A still device cannot say which of its ticks sent the state: the estimate stays as it was, and
// a P_N the blender never saw leaves it too.
TEST(Haptics, TheDelayEstimateKeepsWhenTheSendingTickIsUnknown) {
    ModelBlender blender;
    const glm::vec3 moving(1.0f, 0.0f, 0.0f), still(2.0f, 0.0f, 0.0f);
    blender.resetTo(modelAt(moving, {0, 0, 1.0f}, 0.0f), 0.0);
    blender.update(moving, 0.0);
    for (int i = 1; i <= 100; ++i)
        blender.update(still, i * 1e-3);
    blender.setModel(modelAt(moving, {0, 0, 1.0f}, 0.0f), 0.1);
    EXPECT_NEAR(blender.delayEstimate(), 0.1, 1e-9);
    blender.setModel(modelAt(still, {0, 0, 1.0f}, 0.0f), 0.1);
    EXPECT_NEAR(blender.delayEstimate(), 0.1, 1e-9);
    blender.setModel(modelAt({5.0f, 5.0f, 5.0f}, {0, 0, 1.0f}, 0.0f), 0.1);
    EXPECT_NEAR(blender.delayEstimate(), 0.1, 1e-9);
}

TEST(Haptics, StaleModelFadesToZero) {
    BlendConfig config;
    config.staleTimeoutS = 0.25;
    config.fadeTimeS = 0.1;
    config.maxStepN = 0.05;
    ModelBlender blender(config);
    const glm::vec3 p(1.0f, 2.0f, 3.0f);
    blender.resetTo(modelAt(p, {0, 0, 3.0f}, 2.0f), 0.0);
    glm::vec3 prev = blender.update(p, 0.0);
    double maxStep = 0.0;
    glm::vec3 at200(0.0f);
    for (int i = 1; i <= 1000; ++i) {
        glm::vec3 f = blender.update(p, i * 1e-3);
        maxStep = std::max(maxStep, double(glm::length(f - prev)));
        prev = f;
        if (i == 200)
            at200 = f;
    }
    EXPECT_NEAR(at200.z, 3.0f, 1e-5f); // not stale yet
    EXPECT_TRUE(blender.stale());
    EXPECT_EQ(prev, glm::vec3(0.0f));
    EXPECT_LE(maxStep, config.maxStepN + 1e-6);
    // A fresh model brings the force back, blended.
    blender.setModel(modelAt(p, {0, 0, 3.0f}, 2.0f), 1.0);
    EXPECT_FALSE(blender.stale());
    EXPECT_LE(glm::length(blender.update(p, 1.001)), config.maxStepN + 1e-6);
}

// A model with a NaN or an infinity (a bug upstream, a corrupt source) is ignored: the force
// neither drops to zero at once nor stays zero once good models come again.
TEST(Haptics, NonFiniteModelIsIgnored) {
    BlendConfig config;
    config.maxStepN = 0.05;
    ModelBlender blender(config);
    const glm::vec3 p(1.0f, 2.0f, 3.0f);
    blender.resetTo(modelAt(p, {0, 0, 3.0f}, 2.0f), 0.0);
    EXPECT_NEAR(blender.update(p, 0.0).z, 3.0f, 1e-5f);
    HapticModelData bad = modelAt(p, {0, 0, NAN}, 2.0f);
    blender.setModel(bad, 0.01);
    EXPECT_NEAR(blender.update(p, 0.01).z, 3.0f, 1e-5f); // no jump
    bad = modelAt(p, {0, 0, 1.0f}, 2.0f);
    bad.gradient[1][2] = INFINITY;
    blender.setModel(bad, 0.02);
    EXPECT_NEAR(blender.update(p, 0.02).z, 3.0f, 1e-5f);
    blender.setModel(modelAt(p, {0, 0, 1.0f}, 2.0f), 0.03);
    glm::vec3 f(0.0f);
    for (int i = 30; i <= 200; ++i)
        f = blender.update(p, i * 1e-3);
    EXPECT_NEAR(f.z, 1.0f, 1e-5f);
}

// A device position that is not a number (a glitching driver) gives no force and does not move
// the blend on: the step shortening met a NaN distance, made the step NaN, and std::min(1, NaN)
// finished the blend in that one tick, so the next good tick jumped the whole way (5 N here).
TEST(Haptics, ANonFinitePositionDoesNotFinishTheBlend) {
    BlendConfig config;
    config.maxStepN = 0.05;
    for (bool unilateralOn : {true, false}) {
        config.unilateral = unilateralOn;
        ModelBlender blender(config);
        const glm::vec3 p(1.0f, 2.0f, 3.0f);
        blender.resetTo(modelAt(p, {0, 0, 6.0f}, 2.0f), 0.0);
        EXPECT_NEAR(blender.update(p, 0.0).z, 6.0f, 1e-5f);
        blender.setModel(modelAt(p, {0, 0, 1.0f}, 2.0f), 0.001);
        glm::vec3 prev = blender.update(p, 0.001);
        for (float bad : {NAN, INFINITY}) {
            EXPECT_EQ(blender.update(glm::vec3(bad, 2.0f, 3.0f), 0.002), glm::vec3(0.0f));
            EXPECT_LT(blender.blendFraction(), 0.1) << bad;
            const glm::vec3 f = blender.update(p, 0.003);
            EXPECT_LE(glm::length(f - prev), config.maxStepN + 1e-5) << bad;
            prev = f;
        }
    }
}

// Equation 1 is linear: a hand lifting the tool off the bone carries the extrapolation past the
// surface, where it reverses and pulls the tool back in (2 N and -6 N/mm, 1 mm up: -4 N). A
// contact only pushes, so the blender removes the part against the contact's push.
TEST(Haptics, ALiftedToolIsNotPulledIntoTheBone) {
    HapticModelData m = modelAt({0.0f, 0.0f, 10.0f}, {0.0f, 0.0f, 2.0f}, 0.0f);
    m.gradient[2][2] = -6.0f; // a flat face: stiff along its normal only
    ModelBlender blender;
    blender.resetTo(m, 0.0);
    auto at = [&](glm::vec3 d) { return blender.update(m.position + d, 0.0); };
    EXPECT_NEAR(
        glm::length(extrapolate(m, m.position + glm::vec3(0, 0, 1.0f)) - glm::vec3(0, 0, -4.0f)),
        0.0f, 1e-5f); // Equation 1 itself is unchanged
    EXPECT_EQ(at({0, 0, 1.0f}), glm::vec3(0.0f));
    EXPECT_EQ(at({0.7f, -0.2f, 3.0f}), glm::vec3(0.0f));
    // In contact nothing changes: pressed in, and lifted but not past the surface.
    EXPECT_NEAR(at({0, 0, -0.5f}).z, 5.0f, 1e-5f);
    EXPECT_NEAR(at({0, 0, 0.2f}).z, 0.8f, 1e-5f);
    // Only the part against the push goes; the rest of the extrapolation stays.
    m.gradient = glm::mat3(-6.0f);
    blender.resetTo(m, 0.0);
    const glm::vec3 f = at({0.5f, 0.0f, 1.0f}); // Equation 1: (-3, 0, -4)
    EXPECT_NEAR(f.x, -3.0f, 1e-5f);
    EXPECT_NEAR(f.y, 0.0f, 1e-5f);
    EXPECT_NEAR(f.z, 0.0f, 1e-5f);
}

// A huge but finite field is clamped to the limit, not zeroed as if it were a NaN.
TEST(Haptics, AHugeFiniteFieldGivesTheForceLimit) {
    HapticModelData m = modelAt({0.0f, 0.0f, 10.0f}, {0.0f, 0.0f, 2.0f}, 1e37f);
    ModelBlender blender;
    blender.resetTo(m, 0.0);
    const glm::vec3 f = blender.update(m.position - glm::vec3(0.0f, 0.0f, 1.0f), 0.0);
    EXPECT_NEAR(f.z, blender.config().maxForceN, 1e-4f);
    EXPECT_NEAR(glm::length(f), blender.config().maxForceN, 1e-4f);
}

// A model taken just as the tool touches the bone has a tiny push and the full stiffness: lifted
// 1 mm, it too must not pull (with the cut ramped over 0.01 N it pulled 3 N into the bone).
TEST(Haptics, AModelTakenJustAtTouchIsCutToo) {
    HapticModelData m = modelAt({0.0f, 0.0f, 10.0f}, {0.0f, 0.0f, 0.005f}, 0.0f);
    m.gradient[2][2] = -6.0f;
    ModelBlender blender;
    blender.resetTo(m, 0.0);
    EXPECT_GE(blender.update(m.position + glm::vec3(0, 0, 1.0f), 0.0).z, 0.0f);
    EXPECT_NEAR(blender.update(m.position - glm::vec3(0, 0, 0.5f), 0.0).z, 3.005f, 1e-4f);
}

// After a huge but finite field the next model still blends in, within its blend time and the
// per-tick bound: the step was bounded by the unclamped fields' difference (1e37 N), so the blend
// never moved and the device stayed at the force limit.
TEST(Haptics, ABlendAwayFromAHugeFieldCompletes) {
    BlendConfig config;
    config.maxStepN = 0.25;
    ModelBlender blender(config);
    const glm::vec3 p(0.0f, 0.0f, 9.0f);
    blender.resetTo(modelAt({0.0f, 0.0f, 10.0f}, {0.0f, 0.0f, 2.0f}, 1e37f), 0.0);
    glm::vec3 prev = blender.update(p, 0.0);
    EXPECT_NEAR(glm::length(prev), config.maxForceN, 1e-3f);
    blender.setModel(modelAt({0.0f, 0.0f, 9.0f}, {0.0f, 0.0f, 2.0f}, 6.0f), 0.01);
    double maxStep = 0.0;
    for (int i = 1; i <= 200; ++i) {
        const glm::vec3 f = blender.update(p, 0.01 + i * 1e-3);
        maxStep = std::max(maxStep, double(glm::length(f - prev)));
        prev = f;
    }
    EXPECT_EQ(blender.blendFraction(), 1.0);
    EXPECT_NEAR(prev.z, 2.0f, 1e-5f);
    EXPECT_LE(maxStep, config.maxStepN + 1e-5);
}

TEST(Haptics, UnilateralIsContinuousDownToNoPush) {
    const glm::dvec3 f(0.0, 0.0, -4.0);
    EXPECT_EQ(unilateral(f, {0.0, 0.0, 2.0}), glm::dvec3(0.0));
    EXPECT_EQ(unilateral(f, {0.0, 0.0, -2.0}), f); // along the push: kept
    EXPECT_EQ(unilateral(f, glm::dvec3(0.0)), f);  // no contact direction: kept
    // A push weaker than kUnilateralFullN removes in proportion, so nothing jumps as it fades.
    const glm::dvec3 half = unilateral(f, {0.0, 0.0, 0.5 * kUnilateralFullN});
    EXPECT_NEAR(half.z, -2.0, 1e-12);
}

// Models whose extrapolations are cut by the unilateral rule in different directions, switching
// mid-blend: the output at a fixed position still moves at most maxStepN a tick, and every blend
// still completes.
TEST(Haptics, UnilateralBlendingKeepsTheStepBound) {
    BlendConfig config;
    config.maxStepN = 0.1;
    ModelBlender blender(config);
    const glm::vec3 p(0.0f, 0.0f, 10.0f);
    std::mt19937 rng(7);
    std::uniform_real_distribution<float> u(-1.0f, 1.0f);
    glm::vec3 prev = blender.update(p, 0.0);
    double maxStep = 0.0;
    int tick = 0, completed = 0, cut = 0;
    for (int k = 0; k < 300; ++k) {
        const glm::vec3 dir = glm::normalize(glm::vec3(u(rng), u(rng), u(rng)) + 1e-3f);
        // Anchored up to 1.5 mm from p, behind or ahead of it along the push.
        const glm::vec3 anchor = p - dir * (1.5f * u(rng)) + 0.3f * glm::vec3(u(rng), u(rng), 0);
        HapticModelData m = modelAt(anchor, dir * (1.0f + 3.0f * std::abs(u(rng))), 6.0f);
        cut += glm::dot(extrapolate(m, p), dir) < 0.0f;
        blender.setModel(m, tick * 1e-3);
        // Every third model is replaced mid-blend; the others are given up to 2 s to blend in.
        const int ticks = k % 3 == 0 ? 4 : 2000;
        for (int i = 0; i < ticks && !(i > 0 && blender.blendFraction() == 1.0); ++i, ++tick) {
            const glm::vec3 out = blender.update(p, tick * 1e-3);
            maxStep = std::max(maxStep, double(glm::length(out - prev)));
            prev = out;
        }
        completed += blender.blendFraction() == 1.0;
    }
    EXPECT_GT(cut, 50);
    EXPECT_LE(maxStep, config.maxStepN + 1e-5);
    EXPECT_EQ(completed, 200);
}

TEST(Haptics, RecorderKeepsTheNewestSamples) {
    HapticRecorder rec(4);
    for (int i = 0; i < 10; ++i) {
        HapticSample s;
        s.time = i;
        rec.add(s);
    }
    std::vector<HapticSample> got = rec.samples();
    ASSERT_EQ(got.size(), 4u);
    EXPECT_EQ(got.front().time, 6.0);
    EXPECT_EQ(got.back().time, 9.0);
}

TEST(HapticLoop, StepsDeterministicallyAndThrottlesSends) {
    TestDevice device;
    device.position = {0, 0, 5.0f};
    HapticLoopConfig config;
    config.sendRateHz = 100.0;
    int sends = 0;
    HapticLoop loop(device, config, [&](const DeviceState& s, double) {
        EXPECT_EQ(s.pose.position, glm::vec3(0, 0, 5.0f));
        ++sends;
    });
    for (int i = 0; i < 1000; ++i)
        loop.step(i * 1e-3);
    EXPECT_EQ(sends, 100);
    loop.setSendRate(20.0);
    for (int i = 1000; i < 2000; ++i)
        loop.step(i * 1e-3);
    EXPECT_NEAR(sends, 120, 1);
    HapticLoopStats st = loop.stats();
    EXPECT_EQ(st.ticks, 2000u);
    EXPECT_NEAR(st.achievedRateHz, 1000.0, 1e-6);

    // A model arrives (from "another thread"): the device feels it, blended in.
    loop.setModel(modelAt(device.position, {0, 0, 2.0f}, 1.0f), 2.0);
    for (int i = 2000; i < 2200; ++i)
        loop.step(i * 1e-3);
    EXPECT_NEAR(device.force.z, 2.0f, 1e-5f);
    EXPECT_EQ(loop.stats().models, 1u);
    EXPECT_EQ(loop.samples().back().modelForce, glm::vec3(0, 0, 2.0f));
}

// A tick whose read gave no pose (late, cut off) zeroes the force, sends nothing, and records
// the last pose read with `missed`: plots and figures never see the hand jump to the origin.
TEST(HapticLoop, AMissedReadKeepsTheLastPoseInTheRecord) {
    TestDevice device;
    device.position = {3, 4, 5};
    int sends = 0;
    HapticLoop loop(device, {}, [&](const DeviceState&, double) { ++sends; });
    loop.setModel(modelAt(device.position, {0, 0, 2.0f}, 1.0f), 0.0);
    for (int i = 0; i < 200; ++i)
        loop.step(i * 1e-3);
    const int sent = sends;
    device.missing = true;
    device.position = {0, 0, 0};
    loop.step(0.2);
    const HapticSample s = loop.samples().back();
    EXPECT_TRUE(s.missed);
    EXPECT_EQ(s.position, glm::vec3(3, 4, 5));
    EXPECT_EQ(device.force, glm::vec3(0.0f));
    EXPECT_EQ(sends, sent);
    device.missing = false;
    loop.step(0.201);
    EXPECT_FALSE(loop.samples().back().missed);
    EXPECT_EQ(loop.samples().back().position, glm::vec3(0.0f));
}

// A NaN rate (0 / 0 upstream) is clamped like any other out-of-range rate: to the slowest.
TEST(HapticLoop, NaNSendRateStillSends) {
    TestDevice device;
    int sends = 0;
    HapticLoop loop(device, {}, [&](const DeviceState&, double) { ++sends; });
    loop.setSendRate(NAN);
    for (int i = 0; i < 1000; ++i)
        loop.step(i * 1e-3);
    EXPECT_NEAR(sends, 20, 1);
    loop.setSendRate(100.0);
    for (int i = 1000; i < 2000; ++i)
        loop.step(i * 1e-3);
    EXPECT_NEAR(sends, 120, 1);
}

TEST(HapticLoop, DropsModelsThatArriveOutOfOrder) {
    TestDevice device;
    HapticLoop loop(device, {}, nullptr);
    HapticModelData newer = modelAt(device.position, {0, 0, 1.0f}, 0.0f);
    newer.toolSequence = 0xffffffffu; // just before the wrap
    loop.setModel(newer, 0.0);
    loop.step(0.0);
    HapticModelData older = modelAt(device.position, {0, 0, 5.0f}, 0.0f);
    older.toolSequence = 0xfffffff0u;
    loop.setModel(older, 0.001);
    loop.step(0.001);
    HapticModelData wrapped = modelAt(device.position, {0, 0, 2.0f}, 0.0f);
    wrapped.toolSequence = 3; // after the wrap: newer
    loop.setModel(wrapped, 0.002);
    loop.step(0.002);
    EXPECT_EQ(loop.stats().models, 2u);
    EXPECT_EQ(loop.stats().modelsDropped, 1u);
    EXPECT_EQ(loop.samples().back().modelForce, glm::vec3(0, 0, 2.0f));
}

// Two models arriving within one tick in reverse order (the haptic channel is unsequenced): the
// one answering the newer tool state is applied, the older is dropped and counted.
TEST(HapticLoop, KeepsTheNewerOfTwoModelsPendingInOneTick) {
    TestDevice device;
    HapticLoop loop(device, {}, nullptr);
    HapticModelData newer = modelAt(device.position, {0, 0, 2.0f}, 0.0f);
    newer.toolSequence = 10;
    HapticModelData older = modelAt(device.position, {0, 0, 5.0f}, 0.0f);
    older.toolSequence = 9;
    loop.setModel(newer, 0.0);
    loop.setModel(older, 0.0);
    loop.step(0.0);
    EXPECT_EQ(loop.samples().back().modelForce, glm::vec3(0, 0, 2.0f));
    EXPECT_EQ(loop.stats().models, 1u);
    EXPECT_EQ(loop.stats().modelsDropped, 1u);
}

// What HapticLoop and the window's force source share: of models offered reversed the newer
// waits; one older than the last taken is dropped when taken; sequence numbers wrap.
TEST(NewestModel, KeepsTheNewestAcrossOffersAndTakesAndWraps) {
    NewestModel models;
    HapticModelData m;
    auto offer = [&](uint32_t sequence, float fz) {
        m.toolSequence = sequence;
        m.force = {0, 0, fz};
        return models.offer(m, double(sequence));
    };
    EXPECT_TRUE(models.take().model == std::nullopt);
    EXPECT_TRUE(offer(10, 2.0f));
    EXPECT_FALSE(offer(9, 5.0f)) << "older than the one waiting";
    NewestModel::Taken t = models.take();
    ASSERT_TRUE(t.model);
    EXPECT_EQ(t.model->first.force.z, 2.0f);
    EXPECT_EQ(t.model->second, 10.0);
    EXPECT_FALSE(t.dropped);
    EXPECT_TRUE(offer(8, 7.0f)) << "nothing waits: taken in, judged when taken";
    t = models.take();
    EXPECT_FALSE(t.model) << "older than the last taken";
    EXPECT_TRUE(t.dropped);

    NewestModel wrapping;
    m.toolSequence = 0xFFFFFFFEu;
    EXPECT_TRUE(wrapping.offer(m, 0.0));
    ASSERT_TRUE(wrapping.take().model);
    m.toolSequence = 1; // three tool states later
    m.force = {0, 0, 3.0f};
    EXPECT_TRUE(wrapping.offer(m, 0.0));
    t = wrapping.take();
    ASSERT_TRUE(t.model) << "1 follows 0xFFFFFFFE";
    EXPECT_EQ(t.model->first.force.z, 3.0f);
}

TEST(HapticLoop, LocalForceSourceRunsTheForceModelInTheLoop) {
    Volume sphere = makeSphere(40);
    TestDevice device;
    device.position = {0, 0, sphereRadiusMm(40) + 0.5f}; // 2 mm burr, 0.5 mm in
    HapticLoop loop(device, {}, nullptr);
    LocalForceSource local(sphere, ToolShape::burr(2.0f));
    loop.setForceSource(&local);
    loop.step(0.0);
    EXPECT_GT(device.force.z, 0.5f);
}

TEST(HapticLoop, ThreadRunsAndStops) {
    // No wall-clock assertion: only that it ticks and stops cleanly.
    TestDevice device;
    HapticLoop loop(device, {}, nullptr);
    loop.start();
    // Models from this thread while the loop runs (the network thread's role).
    for (uint32_t seq = 1; loop.stats().ticks < 20 || loop.stats().models == 0; ++seq) {
        HapticModelData m = modelAt(device.position, {0, 0, 1.0f}, 1.0f);
        m.toolSequence = seq;
        loop.setModel(m, 0.0);
        std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
    loop.stop();
    EXPECT_GE(loop.stats().models, 1u);
    EXPECT_FALSE(loop.running());
    EXPECT_GE(loop.stats().ticks, 20u);
}

// stop() then start() (to change the force source, say) keeps one clock: sample times never go
// back, so the blender's ticks, the send throttle and the stale timeout carry on where they were.
TEST(HapticLoop, RestartContinuesTheClock) {
    // No wall-clock assertion: ticks are counted, times only compared with each other.
    TestDevice device;
    std::atomic<int> sends{0};
    HapticLoop loop(device, {}, [&](const DeviceState&, double) { ++sends; });
    auto runFor = [&](uint64_t ticks) {
        const uint64_t until = loop.stats().ticks + ticks;
        loop.start();
        while (loop.stats().ticks < until)
            std::this_thread::sleep_for(std::chrono::milliseconds(1));
        loop.stop();
    };
    runFor(300);
    const int sentBefore = sends.load();
    runFor(50);
    std::vector<HapticSample> s = loop.samples();
    ASSERT_GE(s.size(), 350u);
    for (size_t i = 1; i < s.size(); ++i)
        ASSERT_GE(s[i].time, s[i - 1].time) << "tick " << i;
    EXPECT_GT(sends.load(), sentBefore); // the first tick after the restart sends
}

// The real force model on a flat bone face: the hand lifts a pressed-in 2 mm burr off at 50 mm/s
// with 20 Hz models 25 ms late. The contact itself never pulls (truth >= 0 along the normal); plain
// Equation 1 carries the last in-contact model past the surface and pulls the tool back in.
TEST(Haptics, LiftingOffFeelsNoPullIntoTheBone) {
    Volume box = makeBox(48);
    const SurfaceSite site = boxTopSite(box);
    const ToolShape shape = ToolShape::burr(2.0f);
    const ForceModel model(shape);
    const glm::vec3 n = site.normal;
    // The burr's centre 0.6 mm below the point where it touches, then up by 4 mm.
    const glm::vec3 start = site.position + n * (1.0f - 0.6f);
    auto pullWith = [&](bool unilateralOn, float* truthMin) {
        BlendConfig config;
        config.unilateral = unilateralOn;
        ModelBlender blender(config);
        std::deque<std::pair<double, HapticModelData>> inFlight;
        float minAlong = 0.0f;
        *truthMin = 0.0f;
        for (int i = 0; i <= 120; ++i) {
            const double t = i * 1e-3;
            ToolPose pose =
                ToolPose::fromAxis(start + n * float(std::max(0.0, t - 0.02) * 50.0), site.normal);
            const ForceResult truth = model.compute(box, pose);
            if (i % 50 == 0) { // 20 Hz, answered 25 ms later
                HapticModelData m;
                m.position = pose.position;
                m.force = truth.force;
                m.gradient = truth.gradient;
                m.contact = truth.contact;
                if (i == 0)
                    blender.resetTo(m, t);
                else
                    inFlight.emplace_back(t + 0.025, m);
            }
            while (!inFlight.empty() && inFlight.front().first <= t + 1e-9) {
                blender.setModel(inFlight.front().second, t);
                inFlight.pop_front();
            }
            minAlong = std::min(minAlong, glm::dot(blender.update(pose.position, t), n));
            *truthMin = std::min(*truthMin, glm::dot(truth.force, n));
        }
        return minAlong;
    };
    float truthMin = 0.0f;
    const float plain = pullWith(false, &truthMin);
    EXPECT_GE(truthMin, 0.0f);
    EXPECT_LT(plain, -1.0f) << "plain Equation 1 pulls into the bone";
    EXPECT_GE(pullWith(true, &truthMin), 0.0f);
}

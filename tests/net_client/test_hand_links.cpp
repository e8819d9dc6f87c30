// What a force device makes of HandLinks in a snapshot: the guided trainee's target, the
// participant an instructor feels, and the guide's bounded, damped pull.
#include "net/hand_links.h"
#include "net/trainee_core.h"

#include <glm/geometric.hpp>
#include <gtest/gtest.h>

using namespace trephine;
using namespace trephine::net;

namespace {

ClientSnapshot snapshotOf(uint16_t self, uint16_t heldBy, const HandLinks& links) {
    ClientSnapshot s;
    s.welcome = Welcome{};
    s.welcome->clientId = self;
    s.participants[self] = {self, heldBy ? Role::Trainee : Role::Instructor, Sync::Dbi, "me",
                            heldBy};
    s.participants[7] = {7, Role::Instructor, Sync::Dbi, "Dr. Cho", 0};
    ToolState cho;
    cho.position = {1, 2, 3};
    s.others[7] = cho;
    HandLinks copy = links;
    const std::vector<uint8_t> bytes = encodeMessage(copy);
    EXPECT_TRUE(s.newest.put<HandLinks>(bytes));
    return s;
}

} // namespace

TEST(HandLinksForce, AGuidedTraineeIsPulledTowardTheToolOfTheInstructorHoldingIt) {
    const ClientSnapshot guided = snapshotOf(3, 7, HandLinks{{{7, 0, true}}});
    ASSERT_TRUE(guideTarget(guided).has_value());
    EXPECT_EQ(*guideTarget(guided), glm::vec3(1, 2, 3));
    EXPECT_EQ(feltParticipant(guided), 0);

    EXPECT_FALSE(guideTarget(snapshotOf(3, 0, HandLinks{{{7, 0, true}}})))
        << "not held: no guide, whatever the links say";
    EXPECT_FALSE(guideTarget(snapshotOf(3, 7, HandLinks{{{7, 3, false}}}))) << "felt, not guided";
    EXPECT_FALSE(guideTarget(snapshotOf(3, 9, HandLinks{{{7, 0, true}}})))
        << "guided by an instructor that does not hold it";
}

TEST(HandLinksForce, AnInstructorFeelsTheParticipantItsLinkNames) {
    EXPECT_EQ(feltParticipant(snapshotOf(7, 0, HandLinks{{{7, 3, false}}})), 3);
    EXPECT_EQ(feltParticipant(snapshotOf(7, 0, HandLinks{{{5, 3, false}}})), 0) << "another's";
    EXPECT_EQ(feltParticipant(ClientSnapshot{}), 0) << "no welcome, no links";
}

TEST(HandLinksForce, TheGuideIsASpringAndDamperBoundedByItsMaximum) {
    const HandGuideConfig c;
    const glm::vec3 near = guideForce({1, 0, 0}, {0, 0, 0}, {0, 0, 0}, c);
    EXPECT_NEAR(near.x, c.stiffnessNPerMm, 1e-6);
    const glm::vec3 moving = guideForce({0, 0, 0}, {0, 0, 0}, {10, 0, 0}, c);
    EXPECT_NEAR(moving.x, -10 * c.dampingNsPerMm, 1e-6) << "damping opposes motion";
    const glm::vec3 far = guideForce({100, 0, 0}, {0, 0, 0}, {0, 0, 0}, c);
    EXPECT_NEAR(glm::length(far), c.maxForceN, 1e-5) << "bounded: the trainee can resist";
}

// The assessment's zone felt on the device: a buzz up the tool's shaft in the danger zone and
// twice that touching a structure, never toward the bone, nothing in caution or clear.
TEST(ZoneBuzz, DangerAndViolationBuzzAlongTheToolCautionDoesNot) {
    const glm::vec3 axis(0, 0, 1);
    float danger = 0, violation = 0;
    for (int i = 0; i < 1000; ++i) { // one second at 1 kHz
        const double t = i * 1e-3;
        EXPECT_EQ(zoneBuzz(Zone::Clear, t, axis), glm::vec3(0.0f));
        EXPECT_EQ(zoneBuzz(Zone::Caution, t, axis), glm::vec3(0.0f));
        const glm::vec3 d = zoneBuzz(Zone::Danger, t, axis);
        EXPECT_EQ(d.x, 0.0f);
        EXPECT_EQ(d.y, 0.0f);
        EXPECT_GE(d.z, 0.0f) << "one-sided";
        danger = std::max(danger, std::abs(d.z));
        violation = std::max(violation, glm::length(zoneBuzz(Zone::Violation, t, axis)));
    }
    EXPECT_NEAR(danger, 0.3f, 0.01f);
    EXPECT_NEAR(violation, 0.6f, 0.01f);
}

// Taking the hand and handing it back are felt as a pull fading in and out over rampS, not a step.
TEST(HandLinksForce, TheGuidesPullFadesInAndOutOverItsRamp) {
    const HandGuideConfig c; // 100 mm away: the pull is at its maximum
    const glm::vec3 target(100, 0, 0), p(0, 0, 0), still(0, 0, 0);
    GuideRamp ramp;
    double t = 10.0;
    EXPECT_EQ(ramp.force(target, p, still, t, c), glm::vec3(0.0f)) << "nothing on the first tick";
    double previous = 0;
    for (int i = 1; i <= 250; ++i) { // 1 kHz ticks over the ramp
        const double f = glm::length(ramp.force(target, p, still, t + i * 1e-3, c));
        EXPECT_LE(f - previous, c.maxForceN / (c.rampS * 1000) + 1e-5) << "tick " << i;
        previous = f;
    }
    EXPECT_NEAR(previous, c.maxForceN, 1e-4) << "the whole pull once the ramp is done";
    t += 0.25;
    EXPECT_NEAR(ramp.force(target, p, still, t + 0.1, c).x, c.maxForceN, 1e-4);
    t += 0.1;
    // The guide ends: the pull toward its last target fades out, then nothing.
    EXPECT_NEAR(ramp.force(std::nullopt, p, still, t + 0.125, c).x, c.maxForceN / 2, 1e-3);
    EXPECT_EQ(ramp.force(std::nullopt, p, still, t + 0.25, c), glm::vec3(0.0f));
    EXPECT_FALSE(ramp.pulling());
    // A later guide starts from nothing again, however long after.
    EXPECT_EQ(ramp.force(target, p, still, t + 60.0, c), glm::vec3(0.0f));
    EXPECT_NEAR(ramp.force(target, p, still, t + 60.05, c).x, c.maxForceN * 0.2, 1e-3);
}

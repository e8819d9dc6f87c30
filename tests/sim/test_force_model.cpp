// The haptic force model: contact only in bone, direction out of the bone, clamping, and the
// analytic gradient against finite differences at random contact poses.
#include "libsim/force_model.h"
#include "libsim/haptics.h"

#include "libsim/error.h"
#include "libsim/skull.h"

#include <cmath>
#include <glm/geometric.hpp>
#include <glm/gtc/quaternion.hpp>
#include <gtest/gtest.h>
#include <random>

using namespace trephine;

namespace {

// A pose whose cutter is pressed `depthMm` into the sphere volume along a random direction.
ToolPose contactPose(const ToolShape& shape, int n, std::mt19937& rng, float depthMm) {
    std::normal_distribution<float> g;
    glm::vec3 dir = glm::normalize(glm::vec3(g(rng), g(rng), g(rng)));
    const float surface = sphereRadiusMm(n);
    if (shape.kind == ToolKind::Burr) {
        ToolPose pose = ToolPose::fromAxis(dir * (surface + 0.5f * shape.diameterMm - depthMm),
                                           glm::vec3(g(rng), g(rng), g(rng)));
        return pose;
    }
    // Perforator: tip first, shaft along the outward normal, slightly tilted.
    glm::vec3 axis = glm::normalize(dir + 0.2f * glm::vec3(g(rng), g(rng), g(rng)));
    return ToolPose::fromAxis(dir * (surface - depthMm), axis);
}

float frob(const glm::mat3& m) {
    float s = 0.0f;
    for (int c = 0; c < 3; ++c)
        s += glm::dot(m[c], m[c]);
    return std::sqrt(s);
}

void checkGradient(const ToolShape& shape, ForceModelConfig config, int poses) {
    const int n = 48;
    Volume sphere = makeSphere(n);
    ForceModel model(shape, config);
    std::mt19937 rng(7);
    std::uniform_real_distribution<float> depth(0.1f, 1.2f);
    const float h = 2e-3f;
    int checked = 0;
    for (int i = 0; i < poses; ++i) {
        ToolPose pose = contactPose(shape, n, rng, depth(rng));
        ForceResult r = model.compute(sphere, pose);
        ASSERT_TRUE(r.contact) << shape.describe() << " pose " << i;
        glm::mat3 fd(0.0f);
        for (int c = 0; c < 3; ++c) {
            ToolPose plus = pose, minus = pose;
            plus.position[c] += h;
            minus.position[c] -= h;
            fd[c] = (model.compute(sphere, plus).force - model.compute(sphere, minus).force) /
                    (2.0f * h);
        }
        const float scale = std::max(frob(r.jacobian), 0.5f);
        EXPECT_LT(frob(fd - r.jacobian), 0.05f * scale)
            << shape.describe() << " pose " << i << " |J| " << frob(r.jacobian);
        glm::mat3 fdSym = 0.5f * (fd + glm::transpose(fd));
        EXPECT_LT(frob(fdSym - r.gradient), 0.05f * scale);
        EXPECT_LT(frob(r.gradient - glm::transpose(r.gradient)), 1e-5f * scale);
        ++checked;
    }
    EXPECT_EQ(checked, poses);
}

} // namespace

TEST(ForceModel, NoContactInAir) {
    Volume sphere = makeSphere(32);
    ForceModel model(ToolShape::burr(2.0f));
    ToolPose pose;
    pose.position = glm::vec3(0, 0, sphereRadiusMm(32) + 1.5f);
    ForceResult r = model.compute(sphere, pose);
    EXPECT_FALSE(r.contact);
    EXPECT_EQ(r.force, glm::vec3(0.0f));
    EXPECT_EQ(r.gradient, glm::mat3(0.0f));
}

TEST(ForceModel, PushesOutOfTheBoneAndStiffensWithDepth) {
    Volume sphere = makeSphere(48);
    for (ToolShape shape : {ToolShape::burr(2.0f), ToolShape::burr(6.0f)}) {
        ForceModel model(shape);
        float prev = 0.0f;
        for (float depth : {0.3f, 0.6f, 0.9f}) {
            ToolPose pose;
            pose.position = glm::vec3(0, 0, sphereRadiusMm(48) + 0.5f * shape.diameterMm - depth);
            ForceResult r = model.compute(sphere, pose);
            ASSERT_TRUE(r.contact);
            EXPECT_GT(r.force.z, prev) << shape.describe() << " depth " << depth;
            EXPECT_NEAR(r.force.x, 0.0f, 0.05f * r.force.z);
            EXPECT_NEAR(r.force.y, 0.0f, 0.05f * r.force.z);
            EXPECT_LT(r.gradient[2][2], 0.0f); // pressing in (down) raises the upward force
            prev = r.force.z;
        }
    }
}

TEST(ForceModel, ClampsToTheDeviceMaximum) {
    Volume sphere = makeSphere(48);
    ForceModelConfig config;
    config.maxForceN = 1.0f;
    ForceModel model(ToolShape::burr(4.0f), config);
    ToolPose pose;
    pose.position = glm::vec3(0, 0, sphereRadiusMm(48));
    ForceResult r = model.compute(sphere, pose);
    EXPECT_TRUE(r.clamped);
    EXPECT_NEAR(glm::length(r.force), 1.0f, 1e-5f);
}

TEST(ForceModel, DrillingResistsMotionAlongTheShaft) {
    Volume sphere = makeSphere(48);
    ForceModel model(ToolShape::burr(4.0f));
    ToolPose pose = ToolPose::fromAxis(glm::vec3(0, 0, sphereRadiusMm(48) + 1.5f), {0, 0, 1});
    glm::vec3 still = model.compute(sphere, pose).force;
    glm::vec3 drilling = model.compute(sphere, pose, 1.0f, glm::vec3(0, 0, -10.0f)).force;
    EXPECT_GT(drilling.z, still.z); // moving in along -z while drilling: more push back
    EXPECT_EQ(model.compute(sphere, pose, 0.0f, glm::vec3(0, 0, -10.0f)).force, still);
}

// A fast pull-out in light contact: the resistance pointed into the bone, larger than the contact
// force, so the model's force (the direction the client's one-way extrapolation protects) pulled
// the tool in: here -0.03 N at the model, and the blender's extrapolation -0.13 N at +0.5 mm and
// -0.24 N at +1 mm, where the true force is 0 (-0.6 and -1.2 N on a flat plate). Only a feed into
// the bone is resisted now.
TEST(ForceModel, AFastPullOutIsNotDraggedIntoTheBone) {
    Volume sphere = makeSphere(48);
    ForceModel model(ToolShape::burr(2.0f));
    const glm::vec3 n(0, 0, 1);
    // The ball's bottom 0.05 mm into the top of the sphere.
    const ToolPose pose = ToolPose::fromAxis(n * (sphereRadiusMm(48) + 1.0f - 0.05f), n);
    const ForceResult still = model.compute(sphere, pose, 1.0f);
    ASSERT_TRUE(still.contact);
    const ForceResult out = model.compute(sphere, pose, 1.0f, 200.0f * n); // pulled out
    EXPECT_EQ(out.force, still.force) << "a withdrawal is not resisted";
    EXPECT_GE(glm::dot(out.force, n), 0.0f);
    const ForceResult in = model.compute(sphere, pose, 1.0f, -200.0f * n); // fed in
    EXPECT_GT(glm::dot(in.force, n), glm::dot(still.force, n));

    // The client's blend of that model, felt 0.5 and 1 mm further out: not into the bone (a few
    // micronewtons at most: the one-way cut is partial for so weak a push).
    HapticModelData m;
    m.position = pose.position;
    m.force = out.force;
    m.gradient = out.gradient;
    m.contact = true;
    ModelBlender blender;
    blender.resetTo(m, 0.0);
    for (float lift : {0.5f, 1.0f})
        EXPECT_GT(glm::dot(blender.update(pose.position + lift * n, 0.001 * lift), n), -1e-3f)
            << lift << " mm out";
}

TEST(ForceModel, ShellSizeDoesNotGrowWithTheBurr) {
    size_t small = makeShell(ToolShape::burr(2.0f)).size();
    size_t large = makeShell(ToolShape::burr(6.0f)).size();
    EXPECT_EQ(small, large);
    EXPECT_GT(small, 200u);
    EXPECT_LT(makeShell(ToolShape::perforator()).size(), 2000u);
    // Weights: a sphere's total area is 4 cross-sections.
    float sum = 0.0f;
    for (const ShellPoint& p : makeShell(ToolShape::burr(3.0f)))
        sum += p.weight;
    EXPECT_NEAR(sum, 4.0f, 1e-3f);
}

TEST(ForceModel, CacheBuildsOneModelPerShape) {
    ForceModelCache cache;
    const ForceModel& a = cache.get(ToolShape::burr(2.0f));
    const ForceModel& b = cache.get(ToolShape::perforator());
    EXPECT_EQ(&cache.get(ToolShape::burr(2.0f)), &a);
    EXPECT_EQ(&cache.get(ToolShape::perforator()), &b);
    EXPECT_EQ(cache.size(), 2u);
    EXPECT_EQ(a.shape().diameterMm, 2.0f);
    EXPECT_THROW(cache.get(ToolShape{ToolKind::Burr, 40.0f}), Error);
}

// A peer may send a new valid diameter with every tool state: the cache keeps the shapes in use
// and drops the least recently used, instead of growing with every diameter ever seen.
TEST(ForceModel, CacheKeepsAtMostItsCapacityAndTheShapesInUse) {
    ForceModelCache cache({}, 4);
    const ForceModel* perforator = &cache.get(ToolShape::perforator());
    for (int i = 0; i < 1000; ++i) {
        const float d = 1.0f + 5.0f * float(i) / 1000.0f;
        EXPECT_EQ(cache.get(ToolShape::burr(d)).shape().diameterMm, d);
        EXPECT_LE(cache.size(), 4u);
        // Used all along: never dropped, never rebuilt.
        EXPECT_EQ(&cache.get(ToolShape::perforator()), perforator) << "after diameter " << d;
    }
    EXPECT_EQ(cache.size(), 4u);
    EXPECT_EQ(ForceModelCache().capacity(), ForceModelCache::kDefaultCapacity);
}

// The tool's velocity from its positions over time: none at first, after a long gap, for a jump,
// or for a position not later than the last (which is not kept).
TEST(ForceModel, VelocityEstimateFromSuccessivePositions) {
    VelocityEstimate e;
    EXPECT_EQ(e.update({0, 0, 10}, 1.0), glm::vec3(0.0f)) << "the first";
    const glm::vec3 v = e.update({0, 0, 9.5f}, 1.01);
    EXPECT_NEAR(v.z, -50.0f, 1e-3f);
    EXPECT_EQ(e.update({0, 0, 0}, 1.005), glm::vec3(0.0f)) << "reordered: older than the last";
    EXPECT_NEAR(e.update({0, 0, 9.0f}, 1.02).z, -50.0f, 1e-3f) << "from the last kept";
    EXPECT_EQ(e.update({0, 0, 8.0f}, 1.5), glm::vec3(0.0f)) << "after a gap";
    EXPECT_EQ(e.update({50, 0, 8.0f}, 1.51), glm::vec3(0.0f)) << "a jump (5 m/s)";
    EXPECT_EQ(e.update({50, 0, NAN}, 1.52), glm::vec3(0.0f));
}

TEST(ForceModel, GradientMatchesFiniteDifferencesBurr2) {
    checkGradient(ToolShape::burr(2.0f), {}, 20);
}
TEST(ForceModel, GradientMatchesFiniteDifferencesBurr6) {
    checkGradient(ToolShape::burr(6.0f), {}, 20);
}
TEST(ForceModel, GradientMatchesFiniteDifferencesPerforator) {
    checkGradient(ToolShape::perforator(), {}, 20);
}
TEST(ForceModel, GradientOfTheClampedForceMatchesFiniteDifferences) {
    ForceModelConfig config;
    config.maxForceN = 0.5f;
    checkGradient(ToolShape::burr(4.0f), config, 10);
}

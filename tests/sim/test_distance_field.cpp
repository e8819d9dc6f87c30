#include "libsim/distance_field.h"

#include "libsim/drill.h"
#include "libsim/error.h"
#include "libsim/skull.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>

using namespace trephine;

namespace {

// An anisotropic volume with a few scattered sinus voxels and a dura slab.
Volume scattered() {
    Volume v({17, 13, 15}, {0.5f, 0.7f, 0.6f});
    std::mt19937 rng(7);
    std::uniform_int_distribution<int> x(0, 16), y(0, 12), z(0, 6);
    for (int i = 0; i < 6; ++i)
        v.set(x(rng), y(rng), z(rng), 255, Material::Sinus);
    v.fill({{0, 0, 11}, {17, 13, 15}}, 255, Material::Dura);
    v.fill({{0, 0, 13}, {17, 13, 15}}, 255, Material::Brain);
    return v;
}

float bruteForce(const Volume& v, uint32_t materials, glm::ivec3 at) {
    float best = std::numeric_limits<float>::max();
    const glm::ivec3 d = v.dims();
    for (int z = 0; z < d.z; ++z)
        for (int y = 0; y < d.y; ++y)
            for (int x = 0; x < d.x; ++x)
                if ((materials >> uint8_t(v.material(x, y, z))) & 1u)
                    best =
                        std::min(best, glm::length(v.voxelCenter({x, y, z}) - v.voxelCenter(at)));
    return best;
}

} // namespace

TEST(DistanceField, StructuresAreEverySoftTissueLabelWithBrainUnderDura) {
    const auto s = criticalStructures();
    ASSERT_EQ(s.size(), 3u);
    EXPECT_EQ(s[0].name, "dura");
    EXPECT_TRUE(s[0].has(Material::Dura) && s[0].has(Material::Brain));
    EXPECT_EQ(s[1].name, "sinus");
    EXPECT_EQ(s[2].name, "artery");
    for (const CriticalStructure& c : s)
        EXPECT_FALSE(c.has(Material::Cortical) || c.has(Material::Diploe) || c.has(Material::Air));
}

TEST(DistanceField, EqualsBruteForceAtEveryVoxelCentre) {
    const Volume v = scattered();
    ThreadPool pool(2);
    for (const CriticalStructure& s : criticalStructures()) {
        if (s.name == "artery")
            continue; // none in this volume
        const DistanceField f(v, s.materials, 30.0f, &pool);
        ASSERT_FALSE(f.empty());
        const glm::ivec3 d = v.dims();
        for (int z = 0; z < d.z; ++z)
            for (int y = 0; y < d.y; ++y)
                for (int x = 0; x < d.x; ++x) {
                    const float exact = std::min(30.0f, bruteForce(v, s.materials, {x, y, z}));
                    ASSERT_NEAR(f.atVoxel({x, y, z}), exact, 0.5f / 256.0f + 1e-4f)
                        << s.name << " at " << x << "," << y << "," << z;
                }
    }
}

TEST(DistanceField, ClampsAndIsUniformFarAway) {
    Volume v({64, 64, 64}, glm::vec3(1.0f));
    v.fill({{0, 0, 0}, {64, 64, 2}}, 255, Material::Dura);
    const DistanceField f(v, 1u << unsigned(Material::Dura), 5.0f);
    EXPECT_FLOAT_EQ(f.atVoxel({10, 10, 0}), 0.0f);
    EXPECT_FLOAT_EQ(f.atVoxel({10, 10, 4}), 3.0f);
    EXPECT_FLOAT_EQ(f.atVoxel({10, 10, 40}), 5.0f);
    // Only the bricks within the clamp of the slab are stored densely.
    EXPECT_LT(f.denseBricks(), f.brickCount() / 4);
    EXPECT_THROW(DistanceField(v, 1u << unsigned(Material::Dura), 0.0f), Error);
    EXPECT_THROW(DistanceField(v, 1u << unsigned(Material::Dura), 300.0f), Error);
}

TEST(DistanceField, InterpolatesBetweenCentresAndBoundsOutside) {
    Volume v({32, 32, 32}, glm::vec3(1.0f));
    v.fill({{0, 0, 0}, {32, 32, 1}}, 255, Material::Sinus); // the plane z = -15.5 mm
    const DistanceField f(v, 1u << unsigned(Material::Sinus), 20.0f);
    // Distance to a plane is linear in z: interpolation is exact.
    EXPECT_NEAR(f.at({0.3f, -2.1f, -10.25f}), 5.25f, 0.01f);
    // Below the volume: at least the distance to the volume's edge, never more than exact.
    const float below = f.at({0.0f, 0.0f, -20.0f});
    EXPECT_GE(below, 4.0f);
    EXPECT_LE(below, 4.5f + 0.01f);
    EXPECT_FLOAT_EQ(f.at({0.0f, 0.0f, 1e30f}), 20.0f);
}

TEST(DistanceField, AbsentStructuresAreLeftOut) {
    Volume v({16, 16, 16}, glm::vec3(1.0f));
    v.fill({{0, 0, 0}, {16, 16, 3}}, 255, Material::Brain);
    const StructureFields fields(v, 10.0f);
    ASSERT_EQ(fields.size(), 1u);
    EXPECT_EQ(fields.structure(0).name, "dura");
    EXPECT_EQ(fields.structureOf(Material::Brain), 0);
    EXPECT_EQ(fields.structureOf(Material::Sinus), -1);
}

TEST(DistanceField, ClosestApproachIsZeroExactlyWhenTheDrillTouches) {
    // A sinus slab; a burr moving down toward it touches (the drill's contact) only once its
    // closest approach is within a voxel diagonal of zero, and never before the approach is <= 0
    // by more than the interpolation's error.
    Volume v({40, 40, 40}, glm::vec3(0.5f));
    v.fill({{0, 0, 0}, {40, 40, 10}}, 255, Material::Sinus);
    const StructureFields fields(v, 10.0f);
    ASSERT_EQ(fields.size(), 1u);
    const ToolShape burr = ToolShape::burr(3.0f);
    Driller driller(burr);
    for (float z = 5.0f; z > -8.0f; z -= 0.05f) {
        const ToolPose pose{{0.1f, 0.2f, z}, {1, 0, 0, 0}};
        const float closest = fields.closestApproach(0, burr, pose);
        Volume scratch = v;
        const DrillResult r = driller.drill(scratch, pose, 1.0f, 0.001f);
        if (r.contactBy[uint8_t(Material::Sinus)] > 0)
            EXPECT_LE(closest, 0.0f + 1e-3f) << z;
        else
            EXPECT_GT(closest, -1e-3f) << z;
    }
}

TEST(DistanceField, PerforatorApproachIsALowerBound) {
    Volume v({48, 48, 48}, glm::vec3(0.5f));
    v.fill({{0, 0, 0}, {48, 48, 8}}, 255, Material::Dura);
    const StructureFields fields(v, 20.0f);
    const ToolShape perf = ToolShape::perforator();
    auto exactApproach = [&](const ToolPose& pose) {
        float exact = std::numeric_limits<float>::max();
        for (int z = 0; z < 8; ++z)
            for (int y = 0; y < 48; ++y)
                for (int x = 0; x < 48; ++x)
                    exact = std::min(exact,
                                     perf.signedDistance(pose.toLocal(v.voxelCenter({x, y, z}))));
        return exact;
    };
    // Upright over the slab, as it drills: never above the exact approach (it warns early, never
    // late), and at most the tip's radius a millimetre up (1.75 mm) plus the samples' half
    // millimetre below it.
    for (float z : {-4.0f, -2.5f, 0.0f}) {
        const ToolPose upright = ToolPose::fromAxis({0.3f, 0.1f, z}, {0, 0, 1});
        const float exact = exactApproach(upright),
                    bound = fields.closestApproach(0, perf, upright);
        EXPECT_LE(bound, exact + 0.01f) << z;
        EXPECT_GT(bound, exact - 3.5f) << z;
    }
    // Tilted, the rim nearest: still a lower bound.
    const ToolPose tilted = ToolPose::fromAxis({0.0f, 0.0f, -4.0f}, {0.6f, 0.0f, 0.8f});
    EXPECT_LE(fields.closestApproach(0, perf, tilted), exactApproach(tilted) + 0.01f);
}

TEST(DistanceField, SkullHasDura) {
    const Volume skull = makeSkull(64, 1);
    const StructureFields fields(skull, 20.0f);
    ASSERT_GE(fields.size(), 1u);
    EXPECT_EQ(fields.structure(0).name, "dura");
    EXPECT_GT(fields.bytes(), 0u);
    EXPECT_LT(fields.bytes(), skull.voxelCount() * 2 * fields.size());
}

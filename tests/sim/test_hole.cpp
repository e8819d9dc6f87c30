// A burr hole drilled offline along a ray, and the voxels a drilling removed by material.
#include "libsim/hole.h"

#include "libsim/skull.h"

#include <gtest/gtest.h>

using namespace trephine;

// Straight down into the top of a sphere: the hole is as deep as asked (within a voxel), the bone
// under it is gone and bone below its bottom is not.
TEST(Hole, DrillsDownToItsDepthAlongTheRay) {
    Volume sphere = makeSphere(48);
    const float top = sphereRadiusMm(48);
    const HoleResult hole = drillHoleAlong(sphere, {0, 0, top}, {0, 0, -1}, 6.0f, 4.0f);
    EXPECT_FALSE(hole.changed.empty());
    EXPECT_FALSE(hole.touchedDura);
    auto materialAt = [&](float z) {
        const glm::ivec3 v = glm::ivec3(glm::round(sphere.toVoxel({0, 0, z})));
        return sphere.material(v.x, v.y, v.z);
    };
    EXPECT_EQ(materialAt(top - 2.0f), Material::Air);
    EXPECT_EQ(materialAt(top - 4.5f), Material::Air);
    EXPECT_NE(materialAt(top - 7.5f), Material::Air);
}

TEST(Hole, RemovedCountsOnlyVoxelsThatBecameAirByTheirOldMaterial) {
    Volume before = makeSphere(32);
    Volume after = before;
    const HoleResult hole =
        drillHoleAlong(after, {0, 0, sphereRadiusMm(32)}, {0, 0, -1}, 4.0f, 4.0f);
    const std::vector<int64_t> removed = removedByMaterial(before, after);
    ASSERT_EQ(removed.size(), size_t(kMaterialCount));
    EXPECT_EQ(removed[size_t(Material::Air)], 0);
    int64_t total = 0;
    for (int64_t n : removed)
        total += n;
    EXPECT_GT(total, 0);
    EXPECT_LE(total, hole.changed.count());
    EXPECT_EQ(removedByMaterial(before, before), std::vector<int64_t>(kMaterialCount, 0));
}

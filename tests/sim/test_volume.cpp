// Box3i and Volume basics: the types every other layer leans on.
#include "libsim/box.h"
#include "libsim/skull.h"
#include "libsim/volume.h"

#include <gtest/gtest.h>

#include <algorithm>

using namespace trephine;

TEST(Box3i, DefaultIsEmptyAndExtendGrowsToHoldVoxels) {
    Box3i b;
    EXPECT_TRUE(b.empty());
    EXPECT_EQ(b.count(), 0);
    EXPECT_EQ(b.size(), glm::ivec3(0));
    b.extend({2, 3, 4});
    EXPECT_FALSE(b.empty());
    EXPECT_EQ(b.lo, glm::ivec3(2, 3, 4));
    EXPECT_EQ(b.hi, glm::ivec3(3, 4, 5)); // half-open
    EXPECT_EQ(b.count(), 1);
    b.extend({0, 5, 4});
    EXPECT_EQ(b.lo, glm::ivec3(0, 3, 4));
    EXPECT_EQ(b.hi, glm::ivec3(3, 6, 5));
    EXPECT_EQ(b.count(), 3 * 3 * 1);
    EXPECT_TRUE(b.contains({0, 3, 4}));
    EXPECT_TRUE(b.contains({2, 5, 4}));
    EXPECT_FALSE(b.contains({3, 5, 4}));
    EXPECT_FALSE(b.contains({2, 6, 4}));
}

TEST(Box3i, MergeIgnoresEmptyBoxesAndIntersectCanBeEmpty) {
    Box3i a = Box3i::fromMinMax({0, 0, 0}, {4, 4, 4});
    Box3i b = Box3i::fromMinMax({2, 2, 2}, {6, 5, 8});
    Box3i m = a;
    m.merge(Box3i{});
    EXPECT_EQ(m, a);
    Box3i e;
    e.merge(b);
    EXPECT_EQ(e, b);
    m.merge(b);
    EXPECT_EQ(m, Box3i::fromMinMax({0, 0, 0}, {6, 5, 8}));
    EXPECT_EQ(a.intersect(b), Box3i::fromMinMax({2, 2, 2}, {4, 4, 4}));
    Box3i far = Box3i::fromMinMax({10, 10, 10}, {12, 12, 12});
    EXPECT_TRUE(a.intersect(far).empty());
    // All empty boxes compare equal whatever their corners.
    EXPECT_EQ(a.intersect(far), Box3i{});
}

TEST(Volume, StartsAsAirAndIndexesXFastest) {
    Volume v({4, 3, 2}, {0.5f, 0.5f, 1.0f});
    EXPECT_EQ(v.voxelCount(), 24u);
    EXPECT_EQ(v.index(1, 0, 0), 1u);
    EXPECT_EQ(v.index(0, 1, 0), 4u);
    EXPECT_EQ(v.index(0, 0, 1), 12u);
    EXPECT_EQ(v.bounds(), Box3i::fromMinMax({0, 0, 0}, {4, 3, 2}));
    EXPECT_EQ(v.extentMm(), glm::vec3(2.0f, 1.5f, 2.0f));
    auto counts = v.materialCounts();
    EXPECT_EQ(counts[int(Material::Air)], 24);
    v.set(3, 2, 1, 200, Material::Diploe);
    EXPECT_EQ(v.density(3, 2, 1), 200);
    EXPECT_EQ(v.material(3, 2, 1), Material::Diploe);
    EXPECT_EQ(v.densityData()[23], 200);
    counts = v.materialCounts();
    EXPECT_EQ(counts[int(Material::Diploe)], 1);
    EXPECT_EQ(counts[int(Material::Air)], 23);
}

TEST(Volume, VoxelCentresAreCentredOnTheOriginAndRoundTrip) {
    Volume v({4, 4, 4}, glm::vec3(2.0f));
    // Voxel 0 spans [-4, -2) mm: its centre is -3 mm.
    EXPECT_EQ(v.voxelCenter({0, 0, 0}), glm::vec3(-3.0f));
    EXPECT_EQ(v.voxelCenter({3, 3, 3}), glm::vec3(3.0f));
    EXPECT_EQ(v.voxelCenter({1, 2, 3}) + v.voxelCenter({2, 1, 0}), glm::vec3(0.0f));
    for (glm::ivec3 q : {glm::ivec3(0, 1, 2), glm::ivec3(3, 0, 1)})
        EXPECT_EQ(v.toVoxel(v.voxelCenter(q)), glm::vec3(q));
}

TEST(Volume, EqualityComparesEveryByteAndTheGeometry) {
    Volume a({3, 3, 3}, glm::vec3(1.0f));
    Volume b = a;
    EXPECT_EQ(a, b);
    b.set(1, 1, 1, 1, Material::Air);
    EXPECT_FALSE(a == b);
    b = a;
    b.setSpacing(glm::vec3(2.0f));
    EXPECT_FALSE(a == b);
}

TEST(Volume, MaterialNamesAndBoneLabels) {
    EXPECT_EQ(materialName(Material::Cortical), "cortical");
    EXPECT_EQ(materialName(Material::Dura), "dura");
    EXPECT_TRUE(isBone(Material::Cortical));
    EXPECT_TRUE(isBone(Material::Diploe));
    EXPECT_FALSE(isBone(Material::Dura));
    EXPECT_FALSE(isBone(Material::Air));
}

TEST(Volume, FillSetsExactlyTheBoxClippedToTheVolume) {
    Volume v({6, 5, 4}, glm::vec3(1.0f));
    v.fill(Box3i::fromMinMax({-2, 1, 1}, {3, 3, 9}), 200, Material::Cortical); // clipped
    int set = 0;
    for (int z = 0; z < 4; ++z)
        for (int y = 0; y < 5; ++y)
            for (int x = 0; x < 6; ++x) {
                const bool inside = x < 3 && y >= 1 && y < 3 && z >= 1;
                EXPECT_EQ(v.density(x, y, z), inside ? 200 : 0) << x << y << z;
                EXPECT_EQ(v.material(x, y, z), inside ? Material::Cortical : Material::Air);
                set += inside;
            }
    EXPECT_EQ(set, 3 * 2 * 3);
    v.fill(Box3i::fromMinMax({10, 10, 10}, {12, 12, 12}), 99, Material::Dura); // outside: nothing
    v.fill(Box3i{}, 99, Material::Dura);                                       // empty: nothing
    EXPECT_EQ(v.density(0, 1, 1), 200);
}

// copyBox gives a box's bytes x fastest, as putting the box back takes them: filled back in after
// a cut, the volume is as it was.
TEST(Volume, CopyBoxGivesTheBytesThatPutTheBoxBack) {
    Volume v = makeSphere(16);
    const Volume before = v;
    const Box3i box{{3, 4, 5}, {9, 7, 12}};
    std::vector<uint8_t> density, material;
    v.copyBox(box, density, material);
    ASSERT_EQ(density.size(), size_t(box.count()));
    ASSERT_EQ(material.size(), size_t(box.count()));
    EXPECT_EQ(density[1], v.density(4, 4, 5)) << "x fastest";
    EXPECT_EQ(density[6], v.density(3, 5, 5)) << "then y";
    EXPECT_EQ(density.back(), v.density(8, 6, 11));
    v.fill(box, 0, Material::Air);
    size_t i = 0;
    for (int z = box.lo.z; z < box.hi.z; ++z)
        for (int y = box.lo.y; y < box.hi.y; ++y)
            for (int x = box.lo.x; x < box.hi.x; ++x, ++i)
                v.set(x, y, z, density[i], Material(material[i]));
    EXPECT_TRUE(std::equal(v.densityData(), v.densityData() + 16 * 16 * 16, before.densityData()));
    EXPECT_TRUE(
        std::equal(v.materialData(), v.materialData() + 16 * 16 * 16, before.materialData()));
}

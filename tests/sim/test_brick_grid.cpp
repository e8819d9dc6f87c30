// BrickGrid on its own: brick maxima and distances against their definitions (brute force) after
// build() and after update(), for random sparse bone, cuts that reach the volume's faces and
// corners, cuts of every size into the procedural skull, and many cuts in a row.
#include "libsim/brick_grid.h"

#include "libsim/skull.h"
#include "libsim/volume.h"

#include <algorithm>
#include <gtest/gtest.h>
#include <random>
#include <vector>

namespace trephine {
namespace {

// The largest density of voxels [4b, 4b + 5) per axis (clipped to the volume).
uint8_t bruteMax(const Volume& v, glm::ivec3 b) {
    uint8_t m = 0;
    const glm::ivec3 n = v.dims();
    for (int z = 4 * b.z; z < std::min(n.z, 4 * b.z + 5); ++z)
        for (int y = 4 * b.y; y < std::min(n.y, 4 * b.y + 5); ++y)
            for (int x = 4 * b.x; x < std::min(n.x, 4 * b.x + 5); ++x)
                m = std::max(m, v.density(x, y, z));
    return m;
}

// Chebyshev distance, in bricks, to the nearest brick whose maximum reaches the iso-value.
std::vector<int> bruteDistances(const BrickGrid& g) {
    const glm::ivec3 nb = g.dims();
    std::vector<glm::ivec3> occupied;
    for (int z = 0; z < nb.z; ++z)
        for (int y = 0; y < nb.y; ++y)
            for (int x = 0; x < nb.x; ++x)
                if (g.maxDensity({x, y, z}) >= kSurfaceDensity)
                    occupied.push_back({x, y, z});
    std::vector<int> out;
    for (int z = 0; z < nb.z; ++z)
        for (int y = 0; y < nb.y; ++y)
            for (int x = 0; x < nb.x; ++x) {
                int best = BrickGrid::kMaxDistance;
                for (glm::ivec3 o : occupied) {
                    glm::ivec3 d = glm::abs(o - glm::ivec3(x, y, z));
                    best = std::min(best, std::max({d.x, d.y, d.z}));
                }
                out.push_back(best);
            }
    return out;
}

void fill(Volume& v, const Box3i& box, uint8_t density, Material m) {
    for (int z = box.lo.z; z < box.hi.z; ++z)
        for (int y = box.lo.y; y < box.hi.y; ++y)
            for (int x = box.lo.x; x < box.hi.x; ++x)
                v.set(x, y, z, density, m);
}

// Every distance exact (exact = true) or a lower bound of the definition; maxima always exact.
void expectGrid(const Volume& v, const BrickGrid& g, bool exact) {
    const glm::ivec3 nb = g.dims();
    const std::vector<int> want = bruteDistances(g);
    size_t i = 0;
    for (int z = 0; z < nb.z; ++z)
        for (int y = 0; y < nb.y; ++y)
            for (int x = 0; x < nb.x; ++x, ++i) {
                ASSERT_EQ(g.maxDensity({x, y, z}), bruteMax(v, {x, y, z}))
                    << x << "," << y << "," << z;
                if (exact) {
                    ASSERT_EQ(g.distance({x, y, z}), want[i]) << x << "," << y << "," << z;
                } else {
                    ASSERT_LE(g.distance({x, y, z}), want[i]) << x << "," << y << "," << z;
                    ASSERT_EQ(g.distance({x, y, z}) == 0, want[i] == 0);
                }
            }
}

// Volume dimensions that are not multiples of 4 give partial bricks at the high faces.
TEST(BrickGrid, BuildMatchesTheDefinitionOnRandomSparseBone) {
    for (uint32_t seed : {1u, 2u, 3u}) {
        SCOPED_TRACE(seed);
        std::mt19937 rng(seed);
        Volume v({37 + int(seed), 30, 45 - int(seed)}, glm::vec3(1.0f));
        std::uniform_int_distribution<int> x(0, v.dims().x - 1), y(0, v.dims().y - 1),
            z(0, v.dims().z - 1), density(100, 255);
        for (int i = 0; i < 6; ++i)
            v.set(x(rng), y(rng), z(rng), uint8_t(density(rng)), Material::Cortical);
        expectGrid(v, BrickGrid(v), true);
    }
}

TEST(BrickGrid, AnEmptyVolumeHasNoSurfaceAnywhere) {
    Volume v({20, 24, 28}, glm::vec3(1.0f));
    BrickGrid g(v);
    for (int i = 0; i < int(g.maxData().size()); ++i)
        ASSERT_EQ(g.distanceData()[i], BrickGrid::kMaxDistance);
}

// A slab of bone cut at the volume's faces and corners (where the recomputed box has no ring on
// some sides): one cut into an exact grid leaves it exact.
TEST(BrickGrid, CutsAtTheVolumesFacesAndCornersStayExact) {
    const Box3i cuts[] = {
        Box3i::fromMinMax({0, 0, 8}, {12, 12, 20}),    // a corner column
        Box3i::fromMinMax({30, 0, 0}, {42, 41, 40}),   // the whole high-x end
        Box3i::fromMinMax({10, 10, 10}, {11, 11, 11}), // one voxel
        Box3i::fromMinMax({0, 0, 0}, {42, 41, 40}),    // everything
    };
    for (const Box3i& cut : cuts) {
        SCOPED_TRACE(cut.lo.x * 10000 + cut.lo.z);
        Volume v({42, 41, 40}, glm::vec3(1.0f));
        fill(v, Box3i::fromMinMax({0, 0, 8}, {42, 41, 20}), 220, Material::Cortical);
        fill(v, Box3i::fromMinMax({20, 20, 30}, {24, 24, 34}), 200, Material::Cortical);
        BrickGrid g(v);
        fill(v, cut, 0, Material::Air);
        EXPECT_FALSE(g.update(v, cut));
        expectGrid(v, g, true);
        EXPECT_EQ(g.fullDistancePasses(), 1);
    }
}

// The update study's cut at every size into skull:64 from above, one at a time into a fresh grid:
// exact everywhere, and the cell masks those of a fresh build.
TEST(BrickGrid, SurfaceCutsIntoTheSkullStayExact) {
    const Volume skull = makeSkull(64);
    const BrickGrid built(skull);
    for (int n : {2, 5, 9, 16, 33, 64}) {
        SCOPED_TRACE(n);
        Volume v = skull;
        const glm::ivec3 d = v.dims();
        int top = d.z - 1;
        while (top > 0 && v.density(d.x / 2, d.y / 2, top) < kSurfaceDensity)
            --top;
        const glm::ivec3 lo(d.x / 2 - n / 2, d.y / 2 - n / 2, top + 1 - n);
        const Box3i cut = Box3i::fromMinMax(lo, lo + glm::ivec3(n)).intersect(v.bounds());
        fill(v, cut, 0, Material::Air);
        BrickGrid g = built;
        EXPECT_FALSE(g.update(v, cut));
        expectGrid(v, g, true);
        BrickGrid fresh(v);
        for (size_t i = 0; i < fresh.maxData().size(); ++i)
            ASSERT_EQ(g.cellData()[i], fresh.cellData()[i]);
    }
}

// Random cuts one after another: maxima exact, distances never claim too much, occupancy exact.
TEST(BrickGrid, ManyRandomCutsKeepLowerBounds) {
    Volume v = makeSkull(48);
    BrickGrid g(v);
    std::mt19937 rng(9);
    std::uniform_int_distribution<int> at(0, 47), size(1, 14);
    for (int i = 0; i < 25; ++i) {
        const glm::ivec3 lo(at(rng), at(rng), at(rng));
        const Box3i cut = Box3i::fromMinMax(lo, lo + glm::ivec3(size(rng), size(rng), size(rng)))
                              .intersect(v.bounds());
        fill(v, cut, 0, Material::Air);
        EXPECT_FALSE(g.update(v, cut));
        expectGrid(v, g, false);
    }
    EXPECT_EQ(g.fullDistancePasses(), 1);
}

// update() against a fresh build() over random erosions (partial and to air) and restores of the
// original voxels, in a volume whose sides are not multiples of 4: maxima, cell masks and runs
// equal a fresh build's after every update; distances equal where the update says bone appeared
// (a full pass) and otherwise lower bounds with the same occupancy.
TEST(BrickGrid, UpdateMatchesAFreshBuildOverRandomErosionsAndRestores) {
    for (uint32_t seed : {1u, 2u, 3u, 4u}) {
        SCOPED_TRACE(seed);
        std::mt19937 rng(seed);
        Volume original({45, 38, 41}, glm::vec3(1.0f));
        std::uniform_int_distribution<int> x(0, 44), y(0, 37), z(0, 40), size(1, 12),
            density(60, 255);
        for (int i = 0; i < 30; ++i) {
            const glm::ivec3 lo(x(rng), y(rng), z(rng));
            fill(original,
                 Box3i::fromMinMax(lo, lo + glm::ivec3(size(rng), size(rng), size(rng)))
                     .intersect(original.bounds()),
                 uint8_t(density(rng)), Material::Cortical);
        }
        Volume v = original;
        BrickGrid g(v);
        for (int i = 0; i < 150; ++i) {
            SCOPED_TRACE(i);
            const glm::ivec3 lo(x(rng) - 2, y(rng) - 2, z(rng) - 2);
            const Box3i box =
                Box3i::fromMinMax(lo, lo + glm::ivec3(size(rng), size(rng), size(rng)))
                    .intersect(v.bounds());
            const int kind = std::uniform_int_distribution<int>(0, 3)(rng);
            const int dec = std::uniform_int_distribution<int>(1, 255)(rng);
            for (int vz = box.lo.z; vz < box.hi.z; ++vz)
                for (int vy = box.lo.y; vy < box.hi.y; ++vy)
                    for (int vx = box.lo.x; vx < box.hi.x; ++vx) {
                        if (kind == 0) { // restore
                            v.set(vx, vy, vz, original.density(vx, vy, vz),
                                  original.material(vx, vy, vz));
                        } else {
                            const int d = std::max(0, v.density(vx, vy, vz) - dec);
                            v.set(vx, vy, vz, uint8_t(d), d ? Material::Cortical : Material::Air);
                        }
                    }
            const bool gained = g.update(v, box);
            const BrickGrid fresh(v);
            ASSERT_EQ(g.dims(), fresh.dims());
            ASSERT_EQ(g.maxData(), fresh.maxData());
            for (size_t j = 0; j < fresh.maxData().size(); ++j) {
                ASSERT_EQ(g.cellData()[j], fresh.cellData()[j]) << j;
                ASSERT_EQ(g.distanceData()[j] == 0, fresh.distanceData()[j] == 0) << j;
                if (gained)
                    ASSERT_EQ(g.distanceData()[j], fresh.distanceData()[j]) << j;
                else
                    ASSERT_LE(g.distanceData()[j], fresh.distanceData()[j]) << j;
                for (int axis = 0; axis < 3; ++axis)
                    for (int positive = 0; positive < 2; ++positive)
                        ASSERT_EQ(g.runData(axis, positive)[j], fresh.runData(axis, positive)[j])
                            << j << " axis " << axis << " positive " << positive;
            }
        }
    }
}

} // namespace
} // namespace trephine

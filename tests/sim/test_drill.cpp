// Tools and drilling: cutter shapes, erosion of exactly the voxels inside the cutter, the tight
// changed box, determinism, rates by material, dura contact and the perforator's clutch.
#include "libsim/drill.h"

#include "libsim/error.h"
#include "libsim/skull.h"
#include "libsim/tool_catalogue.h"

#include <algorithm>
#include <cmath>
#include <glm/geometric.hpp>
#include <glm/gtc/quaternion.hpp>
#include <glm/gtx/quaternion.hpp>
#include <gtest/gtest.h>
#include <limits>
#include <set>
#include <string>

using namespace trephine;

namespace {

// The box of voxels whose density or material differ between a and b.
Box3i diffBox(const Volume& a, const Volume& b) {
    Box3i box;
    const glm::ivec3 n = a.dims();
    for (int z = 0; z < n.z; ++z)
        for (int y = 0; y < n.y; ++y)
            for (int x = 0; x < n.x; ++x)
                if (a.density(x, y, z) != b.density(x, y, z) ||
                    a.material(x, y, z) != b.material(x, y, z))
                    box.extend({x, y, z});
    return box;
}

int64_t countMaterial(const Volume& v, Material m) {
    return v.materialCounts()[int(m)];
}

// Every dura and brain voxel has the same density and label in both volumes.
bool sameDuraAndBrain(const Volume& a, const Volume& b) {
    for (size_t i = 0; i < a.voxelCount(); ++i) {
        Material m = Material(a.materialData()[i]);
        if ((m == Material::Dura || m == Material::Brain) &&
            (b.materialData()[i] != a.materialData()[i] ||
             b.densityData()[i] != a.densityData()[i]))
            return false;
    }
    return true;
}

glm::quat tilted() {
    return glm::normalize(glm::angleAxis(0.7f, glm::normalize(glm::vec3(0.3f, -0.8f, 0.5f))));
}

} // namespace

// [SECTION] Tools

TEST(Tool, BurrDiametersAreDiametersAndOutOfRangeIsRefused) {
    ToolShape b = ToolShape::burr(4.0f);
    EXPECT_EQ(b.kind, ToolKind::Burr);
    EXPECT_FLOAT_EQ(b.boundingRadius(), 2.0f);
    EXPECT_FLOAT_EQ(b.signedDistance({0, 0, 0}), -2.0f);
    EXPECT_FLOAT_EQ(b.signedDistance({0, 3, 4}), 3.0f);
    EXPECT_TRUE(b.contains({1.9f, 0, 0}));
    EXPECT_FALSE(b.contains({0, 0, 2.1f}));
    EXPECT_EQ(b.describe(), "burr 4 mm");
    EXPECT_EQ(ToolShape::burr(2.5f).describe(), "burr 2.5 mm");
    EXPECT_NO_THROW(ToolShape::burr(1.0f));
    EXPECT_NO_THROW(ToolShape::burr(6.0f));
    EXPECT_THROW(ToolShape::burr(0.5f), Error);
    EXPECT_THROW(ToolShape::burr(6.5f), Error);
    EXPECT_THROW(ToolShape::burr(-4.0f), Error);
    EXPECT_THROW(ToolShape::burr(std::numeric_limits<float>::quiet_NaN()), Error);
    ToolShape bad;
    bad.diameterMm = 9.0f;
    EXPECT_THROW(bad.validate(), Error);
}

TEST(Tool, PerforatorIsACylinderOnAConicalTip) {
    ToolShape p = ToolShape::perforator();
    EXPECT_EQ(p.kind, ToolKind::Perforator);
    EXPECT_FLOAT_EQ(p.diameterMm, 14.0f);
    EXPECT_EQ(p.describe(), "perforator 14 mm");
    const float r = 7.0f, t = p.tipLengthMm, h = p.tipLengthMm + p.cutLengthMm;
    EXPECT_GT(t, 0.0f);
    EXPECT_NEAR(p.signedDistance({0, 0, 0}), 0.0f, 1e-6f); // apex at the origin
    EXPECT_NEAR(p.signedDistance({0, 0, -1.5f}), 1.5f, 1e-5f);
    EXPECT_NEAR(p.signedDistance({0, 0, h + 2.0f}), 2.0f, 1e-5f);
    EXPECT_NEAR(p.signedDistance({r + 1.0f, 0, t + 3.0f}), 1.0f, 1e-5f);
    EXPECT_NEAR(p.signedDistance({0, -(r - 0.5f), t + 3.0f}), -0.5f, 1e-5f);
    EXPECT_TRUE(p.contains({0, 0, 0.5f}));
    EXPECT_FALSE(p.contains({r - 0.1f, 0, 0.5f})); // beside the tip, below the cone
    EXPECT_FLOAT_EQ(p.boundingRadius(), std::sqrt(r * r + h * h));
    EXPECT_THROW(ToolShape::perforator(3.0f), Error);
    EXPECT_THROW(ToolShape::perforator(20.0f), Error);
}

TEST(Tool, PerforatorDistanceMatchesBruteForceOverItsSurface) {
    // Exact distance: compare with the nearest of many points sampled on the surface.
    ToolShape p = ToolShape::perforator(10.0f);
    const float r = 5.0f, t = p.tipLengthMm, h = t + p.cutLengthMm;
    std::vector<glm::vec2> profile; // (rho, z) on the meridian outline
    for (int i = 0; i <= 400; ++i) {
        float u = i / 400.0f;
        profile.push_back({u * r, u * t});       // cone
        profile.push_back({r, t + u * (h - t)}); // side
        profile.push_back({u * r, h});           // top
    }
    uint32_t s = 12345;
    auto rnd = [&] {
        s = s * 1664525u + 1013904223u;
        return float(s >> 8) / 16777216.0f;
    };
    for (int k = 0; k < 300; ++k) {
        glm::vec3 q(rnd() * 16 - 8, rnd() * 16 - 8, rnd() * 24 - 4);
        glm::vec2 m(std::sqrt(q.x * q.x + q.y * q.y), q.z);
        float best = 1e9f;
        for (glm::vec2 b : profile)
            best = std::min(best, glm::length(m - b));
        EXPECT_NEAR(std::fabs(p.signedDistance(q)), best, 0.03f);
    }
}

// The catalogue: one entry per id, in order; names and keys tell them apart; every size in range
// makes a tool and none outside does; the clutch rule is the tipped cylinder's.
TEST(ToolCatalogue, EachKindHasOneEntryWhoseSizesMakeItsTool) {
    ASSERT_EQ(toolTypes().size(), size_t(kToolKindCount));
    std::set<std::string> names, keys;
    for (size_t i = 0; i < toolTypes().size(); ++i) {
        const ToolType& t = *toolTypes()[i];
        SCOPED_TRACE(t.name);
        EXPECT_EQ(size_t(t.kind), i);
        EXPECT_EQ(&toolType(t.kind), &t);
        EXPECT_EQ(toolKindNamed(t.name), t.kind);
        EXPECT_TRUE(names.insert(t.name).second);
        EXPECT_TRUE(keys.insert(t.key).second);
        ASSERT_EQ(std::string(t.key).size(), 1u);
        EXPECT_TRUE(t.key[0] >= 'A' && t.key[0] <= 'Z');
        EXPECT_LE(t.minDiameterMm, t.defaultDiameterMm);
        EXPECT_LE(t.defaultDiameterMm, t.maxDiameterMm);
        EXPECT_GT(t.erosionRate, 0.0);
        EXPECT_TRUE(!t.clutch || t.cutter == Cutter::TippedCylinder);
        for (float d : {t.minDiameterMm, t.defaultDiameterMm, t.maxDiameterMm}) {
            const ToolShape s = ToolShape::of(t.kind, d);
            EXPECT_EQ(s.sphere(), t.cutter == Cutter::Sphere);
            EXPECT_EQ(s.describe().rfind(t.name, 0), 0u);
        }
        EXPECT_THROW(ToolShape::of(t.kind, t.minDiameterMm - 0.1f), Error);
        EXPECT_THROW(ToolShape::of(t.kind, t.maxDiameterMm + 0.1f), Error);
    }
    EXPECT_FALSE(toolKindNamed("drill"));
    EXPECT_THROW(ToolShape::of(ToolKind(kToolKindCount), 4.0f), Error);
}

// The diamond burr: a 2 mm sphere by default that removes a third of what a fluted burr of its
// size removes in the same time.
TEST(ToolCatalogue, TheDiamondBurrCutsAThirdAsFastAsABurrOfItsSize) {
    const ToolShape diamond = ToolShape::of(ToolKind::DiamondBurr, 2.0f);
    EXPECT_TRUE(diamond.sphere());
    EXPECT_EQ(toolType(ToolKind::DiamondBurr).defaultDiameterMm, 2.0f);
    EXPECT_EQ(diamond.describe(), "diamond 2 mm");
    const Volume original = makeBox(32);
    Volume byBurr = original, byDiamond = original;
    Driller burr(ToolShape::burr(2.0f)), fine(diamond);
    const DrillResult b = burr.drill(byBurr, ToolPose{}, 1.0f, 0.03f);
    const DrillResult d = fine.drill(byDiamond, ToolPose{}, 1.0f, 0.03f);
    EXPECT_EQ(d.voxelsTouched, b.voxelsTouched) << "the same sphere";
    EXPECT_GT(d.densityRemoved, 0);
    EXPECT_NEAR(double(d.densityRemoved) / double(b.densityRemoved), 1.0 / 3.0, 0.02);
}

TEST(Tool, PoseFromAxisPointsTheShaftAlongTheAxis) {
    glm::vec3 axis = glm::normalize(glm::vec3(-0.5f, 0.4f, 0.77f));
    ToolPose pose = ToolPose::fromAxis({1, 2, 3}, 3.0f * axis);
    EXPECT_LT(glm::length(pose.axis() - axis), 1e-5f);
    EXPECT_LT(glm::length(pose.toObject(pose.toLocal({4, 5, 6})) - glm::vec3(4, 5, 6)), 1e-5f);
    EXPECT_LT(glm::length(pose.toLocal({1, 2, 3})), 1e-6f);
}

// [SECTION] Erosion

TEST(Drill, BurrHeldLongEnoughRemovesExactlyTheVoxelsInsideIt) {
    const Volume original = makeBox(64);
    Volume v = original;
    ToolPose pose;
    pose.position = glm::vec3(1.23f, -0.71f, 2.37f);
    pose.orientation = tilted();
    Driller driller(ToolShape::burr(5.0f));
    DrillResult res = driller.drill(v, pose, 1.0f, 1.0f);
    int64_t inside = 0;
    Box3i expectedBox;
    for (int z = 0; z < 64; ++z)
        for (int y = 0; y < 64; ++y)
            for (int x = 0; x < 64; ++x) {
                double d =
                    glm::length(glm::dvec3(v.voxelCenter({x, y, z})) - glm::dvec3(pose.position));
                ASSERT_GT(std::fabs(d - 2.5), 1e-3) << "pose leaves a voxel centre ambiguous";
                bool in = d < 2.5;
                inside += in;
                if (in)
                    expectedBox.extend({x, y, z});
                ASSERT_EQ(v.density(x, y, z), in ? 0 : original.density(x, y, z));
                ASSERT_EQ(v.material(x, y, z), in ? Material::Air : original.material(x, y, z));
            }
    EXPECT_GT(inside, 40);
    EXPECT_EQ(res.voxelsTouched, inside);
    EXPECT_EQ(res.voxelsChanged, inside);
    EXPECT_EQ(res.voxelsRemoved, inside);
    EXPECT_EQ(res.densityRemoved, inside * 255);
    EXPECT_EQ(res.changed, expectedBox);
    EXPECT_FALSE(res.duraContact);
}

TEST(Drill, PerforatorHeldLongEnoughRemovesExactlyTheVoxelsInsideIt) {
    const Volume original = makeBox(64);
    Volume v = original;
    ToolPose pose;
    pose.position = glm::vec3(0.37f, 1.11f, -4.83f);
    pose.orientation = tilted();
    ToolShape shape = ToolShape::perforator(9.0f);
    Driller driller(shape);
    DrillResult res = driller.drill(v, pose, 1.0f, 1.0f);
    EXPECT_FALSE(res.clutchDisengaged);
    int64_t inside = 0, ambiguous = 0;
    for (int z = 0; z < 64; ++z)
        for (int y = 0; y < 64; ++y)
            for (int x = 0; x < 64; ++x) {
                float sd = shape.signedDistance(pose.toLocal(v.voxelCenter({x, y, z})));
                if (std::fabs(sd) < 1e-4f) {
                    ambiguous++;
                    continue;
                }
                bool in = sd < 0.0f;
                inside += in;
                ASSERT_EQ(v.density(x, y, z), in ? 0 : original.density(x, y, z));
            }
    EXPECT_EQ(ambiguous, 0);
    EXPECT_GT(inside, 500);
    EXPECT_EQ(res.voxelsChanged, inside);
    EXPECT_EQ(res.changed, diffBox(original, v));
}

TEST(Drill, ChangedBoxIsTightAlongAPath) {
    Volume v = makeSkull(96);
    Driller burr(ToolShape::burr(3.0f));
    SurfaceSite site = defaultBurrSite(v);
    Volume before = v;
    int nonEmpty = 0;
    for (int i = 0; i < 60; ++i) {
        glm::vec3 p = site.position - 0.02f * float(i) * site.normal +
                      glm::vec3(0.05f * float(i), 0.0f, 0.0f);
        DrillResult res = burr.drill(v, ToolPose::fromAxis(p, site.normal), 0.8f, 0.004f);
        ASSERT_EQ(res.changed, diffBox(before, v)) << "step " << i;
        nonEmpty += !res.changed.empty();
        before = v;
    }
    EXPECT_GT(nonEmpty, 30);
}

TEST(Drill, SameSequenceGivesTheSameBytes) {
    Volume a = makeSkull(80, 3), b = a;
    SurfaceSite site = defaultBurrSite(a);
    for (Volume* v : {&a, &b}) {
        Driller burr(ToolShape::burr(6.0f));
        Driller perf(ToolShape::perforator());
        for (int i = 0; i < 80; ++i) {
            float dt = 0.0005f + 0.0003f * float(i % 7);
            float speed = 0.3f + 0.1f * float(i % 5);
            glm::vec3 p = site.position - 0.05f * float(i) * site.normal;
            burr.drill(*v, ToolPose::fromAxis(p + glm::vec3(5, 0, 0), site.normal), speed, dt);
            perf.drill(*v, ToolPose::fromAxis(p - glm::vec3(5, 0, 0), site.normal), speed, dt);
        }
    }
    EXPECT_TRUE(a == b);
}

TEST(Drill, SplittingDtGivesTheSameResult) {
    for (float speed : {1.0f, 0.37f}) {
        SCOPED_TRACE(speed);
        const Volume original = makeBox(32);
        Volume once = original, split = original;
        ToolPose pose;
        pose.position = glm::vec3(0.3f, 0.1f, 0.2f);
        Driller d1(ToolShape::burr(4.0f)), d10(ToolShape::burr(4.0f));
        DrillResult r1 = d1.drill(once, pose, speed, 0.010f);
        int64_t removed = 0;
        Box3i box;
        for (int i = 0; i < 10; ++i) {
            DrillResult r = d10.drill(split, pose, speed, 0.001f);
            removed += r.densityRemoved;
            box.merge(r.changed);
        }
        EXPECT_TRUE(once == split);
        EXPECT_EQ(removed, r1.densityRemoved);
        EXPECT_EQ(box, r1.changed);
        // The whole units removed are the floor of rate x speed x time.
        EXPECT_EQ(r1.densityRemoved,
                  r1.voxelsTouched *
                      int64_t(std::floor(erosionRate(ToolKind::Burr) * speed * 0.010 + 1e-4)));
    }
}

TEST(Drill, SpeedZeroRemovesNothing) {
    const Volume original = makeBox(32);
    Volume v = original;
    Driller d(ToolShape::burr(6.0f));
    DrillResult res = d.drill(v, ToolPose{}, 0.0f, 5.0f);
    EXPECT_TRUE(v == original);
    EXPECT_TRUE(res.changed.empty());
    EXPECT_EQ(res.voxelsChanged, 0);
    EXPECT_GT(res.voxelsTouched, 50);
    // The carry did not grow either: a later step removes only its own share.
    DrillResult next = d.drill(v, ToolPose{}, 1.0f, 0.001f);
    EXPECT_EQ(next.densityRemoved, next.voxelsTouched * 1); // floor(1.7)
}

TEST(Drill, CorticalErodesSlowerThanDiploe) {
    // Left half cortical, right half diploe, same density; a burr straddling both.
    Volume v({16, 16, 16}, glm::vec3(1.0f));
    for (int z = 0; z < 16; ++z)
        for (int y = 0; y < 16; ++y)
            for (int x = 0; x < 16; ++x)
                v.set(x, y, z, 200, x < 8 ? Material::Cortical : Material::Diploe);
    const Volume original = v;
    Driller d(ToolShape::burr(6.0f));
    DrillResult res = d.drill(v, ToolPose{}, 1.0f, 0.010f); // 17 cortical units
    ASSERT_GT(res.voxelsChanged, 0);
    int cortical = 0, diploe = 0;
    for (int z = 0; z < 16; ++z)
        for (int y = 0; y < 16; ++y)
            for (int x = 0; x < 16; ++x) {
                int lost = original.density(x, y, z) - v.density(x, y, z);
                if (lost == 0)
                    continue;
                if (x < 8) {
                    EXPECT_EQ(lost, 17);
                    cortical++;
                } else {
                    EXPECT_EQ(lost, 17 * kDiploeErosionFactor);
                    diploe++;
                }
            }
    EXPECT_GT(cortical, 0);
    EXPECT_GT(diploe, 0);
    // Full-speed burr: solid cortical (255) in about 0.15 s.
    EXPECT_NEAR(255.0 / erosionRate(ToolKind::Burr), 0.15, 0.01);
}

TEST(Drill, DuraContactIsReportedAndDuraIsNeverRemoved) {
    const Volume original = makeSkull(128);
    Volume v = original;
    SurfaceSite site = defaultBurrSite(v);
    Driller burr(ToolShape::burr(4.0f));
    bool contact = false;
    int64_t boneRemoved = 0;
    for (int i = 0; i < 200 && !contact; ++i) {
        glm::vec3 p = site.position + (1.0f - 0.1f * float(i)) * site.normal;
        DrillResult res = burr.drill(v, ToolPose::fromAxis(p, site.normal), 1.0f, 0.2f);
        boneRemoved += res.voxelsRemoved;
        if (res.duraContact) {
            contact = true;
            EXPECT_GT(res.duraVoxels, 0);
            // Bone around the dura still erodes; the dura itself does not.
        }
    }
    EXPECT_TRUE(contact);
    EXPECT_GT(boneRemoved, 20);
    EXPECT_TRUE(sameDuraAndBrain(original, v));
    // Pushing on into the brain reports contact and still removes no dura or brain.
    glm::vec3 deep = site.position - 12.0f * site.normal;
    DrillResult res = burr.drill(v, ToolPose::fromAxis(deep, site.normal), 1.0f, 1.0f);
    EXPECT_TRUE(res.duraContact);
    EXPECT_TRUE(sameDuraAndBrain(original, v));
}

// [SECTION] Perforator clutch

TEST(Drill, PerforatorStopsAtTheInnerTable) {
    const Volume original = makeSkull(256);
    Volume v = original;
    SurfaceSite site = defaultBurrSite(v);
    Driller perf(ToolShape::perforator());
    const glm::vec3 n = site.normal;
    float depth = -1.0f; // apex depth below the outer surface along the normal (mm)
    bool stopped = false;
    for (; depth < 12.0f; depth += 0.1f) {
        ToolPose pose = ToolPose::fromAxis(site.position - depth * n, n);
        // Held long enough at each depth to clear everything inside the cutter.
        DrillResult res = perf.drill(v, pose, 1.0f, 0.7f);
        ASSERT_FALSE(res.duraContact) << "depth " << depth;
        if (res.clutchDisengaged) {
            stopped = true;
            EXPECT_EQ(res.voxelsChanged, 0);
            break;
        }
    }
    ASSERT_TRUE(stopped);
    EXPECT_TRUE(perf.clutchDisengaged());
    // Through the outer table and the diploe, not past the bone (about 6-8 mm here).
    EXPECT_GT(depth, 5.0f);
    EXPECT_LT(depth, 8.5f);
    EXPECT_TRUE(sameDuraAndBrain(original, v));
    // A lip of inner table remains around and below the tip.
    const glm::vec3 apex = site.position - depth * n;
    int lip = 0;
    for (int z = 0; z < 256; ++z)
        for (int y = 0; y < 256; ++y)
            for (int x = 0; x < 256; ++x) {
                glm::vec3 d = v.voxelCenter({x, y, z}) - apex;
                float along = glm::dot(d, n), across = glm::length(d - along * n);
                if (across < 6.0f && along > -2.0f && along < 1.5f &&
                    v.material(x, y, z) == Material::Cortical)
                    lip++;
            }
    EXPECT_GT(lip, 20);
    // Pushing further cuts nothing; lifting clear of the hole re-engages the clutch.
    DrillResult deeper =
        perf.drill(v, ToolPose::fromAxis(site.position - (depth + 0.3f) * n, n), 1.0f, 1.0f);
    EXPECT_TRUE(deeper.clutchDisengaged);
    EXPECT_EQ(deeper.voxelsChanged, 0);
    DrillResult lifted = perf.drill(v, ToolPose::fromAxis(site.position + 3.0f * n, n), 1.0f, 0.1f);
    EXPECT_FALSE(lifted.clutchDisengaged);
    EXPECT_FALSE(perf.clutchDisengaged());
}

// Dura voxels that face a voxel which was bone in `original` and is air in `v`: where the inner
// table was cut through.
int64_t duraBared(const Volume& original, const Volume& v) {
    int64_t bared = 0;
    const glm::ivec3 d = v.dims();
    const glm::ivec3 faces[6] = {{1, 0, 0},  {-1, 0, 0}, {0, 1, 0},
                                 {0, -1, 0}, {0, 0, 1},  {0, 0, -1}};
    for (int z = 1; z < d.z - 1; ++z)
        for (int y = 1; y < d.y - 1; ++y)
            for (int x = 1; x < d.x - 1; ++x) {
                if (v.material(x, y, z) != Material::Dura)
                    continue;
                for (const glm::ivec3& f : faces) {
                    const glm::ivec3 q = glm::ivec3(x, y, z) + f;
                    if (v.material(q.x, q.y, q.z) == Material::Air &&
                        isBone(original.material(q.x, q.y, q.z))) {
                        ++bared;
                        break;
                    }
                }
            }
    return bared;
}

// On the server's default skull:128 the inner table is one 1.56 mm voxel thick: with a fixed
// 0.5 mm look-ahead at voxel centres the perforator cut that voxel before any dura came within
// the margin, and bared the dura. The margin is at least a voxel, so a lip remains at any size.
TEST(Drill, PerforatorLeavesTheInnerTableOfACoarseSkull) {
    for (int n : {64, 128}) {
        SCOPED_TRACE(n);
        const Volume original = makeSkull(n);
        Volume v = original;
        const SurfaceSite site = defaultBurrSite(v);
        Driller perf(ToolShape::perforator());
        bool stopped = false;
        for (float depth = -1.0f; depth < 14.0f && !stopped; depth += 0.1f)
            stopped =
                perf.drill(v, ToolPose::fromAxis(site.position - depth * site.normal, site.normal),
                           1.0f, 0.7f)
                    .clutchDisengaged;
        EXPECT_TRUE(stopped);
        EXPECT_EQ(duraBared(original, v), 0);
        EXPECT_TRUE(sameDuraAndBrain(original, v));
    }
}

// A peck: fed into the diploe, lifted 2 mm back up its own hole and fed again. The tip then has
// air ahead and bone around, which rule (b) took for a breakthrough: the clutch stopped ~2 mm of
// bone short for good. It now goes on to the inner table, as without the peck.
TEST(Drill, APerforatorPeckDoesNotStopItShortOfTheInnerTable) {
    const Volume original = makeSkull(256);
    auto stopDepth = [&](bool peck) {
        Volume v = original;
        const SurfaceSite site = defaultBurrSite(v);
        Driller perf(ToolShape::perforator());
        auto at = [&](float depth) {
            return ToolPose::fromAxis(site.position - depth * site.normal, site.normal);
        };
        float depth = -1.0f;
        if (peck) {
            for (; depth <= 4.5f; depth += 0.1f)
                EXPECT_FALSE(perf.drill(v, at(depth), 1.0f, 0.7f).clutchDisengaged) << depth;
            depth -= 2.0f;
        }
        for (; depth < 14.0f; depth += 0.1f)
            if (perf.drill(v, at(depth), 1.0f, 0.7f).clutchDisengaged)
                break;
        EXPECT_TRUE(sameDuraAndBrain(original, v));
        return depth;
    };
    const float plain = stopDepth(false), pecked = stopDepth(true);
    EXPECT_GT(plain, 5.0f);
    EXPECT_NEAR(pecked, plain, 0.5f) << "stopped at the inner table, not where the peck began";
}

TEST(Drill, PerforatorDisengagesWhenItBreaksThroughABoneBlock) {
    // makeBox(48): solid from z = -12 mm to +12 mm. Perforate straight down from above.
    Volume v = makeBox(48);
    Driller perf(ToolShape::perforator(9.0f));
    float z = 13.0f;
    bool stopped = false;
    for (; z > -20.0f; z -= 0.2f) {
        ToolPose pose;
        pose.position = glm::vec3(0.1f, -0.2f, z);
        if (perf.drill(v, pose, 1.0f, 1.0f).clutchDisengaged) {
            stopped = true;
            break;
        }
    }
    ASSERT_TRUE(stopped);
    EXPECT_LT(z, -11.8f); // the tip is out of the far side...
    EXPECT_GT(z, -13.5f); // ...only just
    // The rim under the cone remains.
    EXPECT_GT(countMaterial(v, Material::Cortical), 0);
    EXPECT_EQ(v.material(24 + 4, 24, 1 + 12), Material::Cortical);
    perf.resetClutch();
    EXPECT_FALSE(perf.clutchDisengaged());
}

// Released, lifted and pressed onto bone elsewhere, the perforator's clutch stayed disengaged: it
// re-engaged only inside drill(), whose first step at the new site already found bone around the
// tip. observe() (a tool state that does not drill) re-engages it once clear of bone, as a lift
// does while drilling; near bone it does not, and a burr ignores it.
TEST(Drill, APerforatorLiftedWithoutDrillingReEngagesForTheNextHole) {
    Volume v = makeBox(48); // solid from z = -12 mm to +12 mm
    Driller perf(ToolShape::perforator(9.0f));
    auto down = [](glm::vec2 xy, float z) {
        ToolPose pose;
        pose.position = glm::vec3(xy, z);
        return pose;
    };
    bool stopped = false;
    for (float z = 13.0f; z > -20.0f && !stopped; z -= 0.2f)
        stopped = perf.drill(v, down({0.0f, 0.0f}, z), 1.0f, 1.0f).clutchDisengaged;
    ASSERT_TRUE(stopped);
    perf.observe(v, down({0.0f, 0.0f}, -11.0f)); // still in its hole, bone around
    EXPECT_TRUE(perf.clutchDisengaged());
    perf.observe(v, down({0.0f, 0.0f}, 30.0f)); // the button up, lifted out
    EXPECT_FALSE(perf.clutchDisengaged());
    // Pressed 1 mm into the bone 10 mm away (beside the first hole): it cuts.
    const DrillResult cut = perf.drill(v, down({7.0f, 7.0f}, 11.0f), 1.0f, 1.0f);
    EXPECT_FALSE(cut.clutchDisengaged);
    EXPECT_GT(cut.voxelsChanged, 0);
    Driller burr(ToolShape::burr(5.0f));
    burr.observe(v, down({0.0f, 0.0f}, 30.0f));
    EXPECT_FALSE(burr.clutchDisengaged());
}

// The perforator's clutch looks ahead of its tip too: far away its voxel coordinates are no int
// (converting them was undefined; -fsanitize=float-cast-overflow reports it).
TEST(Drill, PosesFromFarAwayOrNotFiniteTouchNothing) {
    const Volume original = makeBox(16);
    Volume v = original;
    Driller d(ToolShape::perforator());
    const float inf = std::numeric_limits<float>::infinity();
    const float nan = std::numeric_limits<float>::quiet_NaN();
    ToolPose poses[4];
    poses[0].position = glm::vec3(1e30f, -1e30f, 0.0f);
    poses[1].position = glm::vec3(nan, 0.0f, 0.0f);
    poses[2].position = glm::vec3(0.0f, inf, 0.0f);
    poses[3].orientation = glm::quat(0.0f, 0.0f, 0.0f, 0.0f);
    for (const ToolPose& pose : poses) {
        DrillResult r = d.drill(v, pose, 1.0f, 1.0f);
        EXPECT_EQ(r.voxelsTouched, 0);
        EXPECT_TRUE(r.changed.empty());
    }
    EXPECT_TRUE(v == original);
}

// drill() normalises the orientation (a client's may be slightly off unit length): a scaled
// quaternion cuts exactly what the unit one cuts, for both cutters. A half turn scaled to norm
// 0.7 used to squash the voxel box (computed with the raw quaternion) to a sliver.
TEST(Drill, AScaledQuaternionCutsWhatTheUnitOneCuts) {
    const glm::quat halfTurn = glm::angleAxis(glm::pi<float>(), glm::vec3(0, 0, 1));
    for (const glm::quat& q : {halfTurn, tilted()})
        for (float scale : {0.7f, 0.98f, 1.3f})
            for (const ToolShape& shape : {ToolShape::burr(5.0f), ToolShape::perforator()}) {
                SCOPED_TRACE(shape.describe() + " scale " + std::to_string(scale));
                Volume unit = makeBox(48), scaled = unit;
                ToolPose a;
                a.position = glm::vec3(0.3f, -0.2f, 0.1f);
                a.orientation = q;
                ToolPose b = a;
                b.orientation = q * scale;
                Driller d1(shape), d2(shape);
                const DrillResult r1 = d1.drill(unit, a, 1.0f, 0.5f);
                const DrillResult r2 = d2.drill(scaled, b, 1.0f, 0.5f);
                EXPECT_GT(r1.voxelsTouched, 0);
                EXPECT_EQ(r2.voxelsTouched, r1.voxelsTouched);
                EXPECT_EQ(r2.changed, r1.changed);
                EXPECT_TRUE(scaled == unit);
            }
}

// [SECTION] Sweeping between sampled poses

TEST(Drill, SweepPosesCutAMoveIntoEqualStepsEndingAtTheTarget) {
    ToolPose a = ToolPose::fromAxis({0, 0, 0}, {0, 0, 1});
    ToolPose b = ToolPose::fromAxis({2.0f, 0, 0}, {1, 0, 1});
    std::vector<ToolPose> path = sweepPoses(a, b, 0.25f, 10.0f);
    ASSERT_EQ(path.size(), 8u);
    EXPECT_EQ(path.back().position, b.position);
    EXPECT_EQ(path.back().orientation, b.orientation);
    for (size_t i = 0; i < path.size(); ++i)
        EXPECT_NEAR(path[i].position.x, 0.25f * float(i + 1), 1e-5f);
    // Orientations turn steadily from a's to b's.
    EXPECT_LT(glm::angle(glm::inverse(a.orientation) * path[3].orientation),
              glm::angle(glm::inverse(a.orientation) * b.orientation));
    // Within a step, or a jump beyond maxSweepMm, or not finite: the target alone.
    EXPECT_EQ(sweepPoses(a, ToolPose::fromAxis({0.2f, 0, 0}, {0, 0, 1}), 0.25f, 10.0f).size(), 1u);
    EXPECT_EQ(sweepPoses(a, ToolPose::fromAxis({12.0f, 0, 0}, {0, 0, 1}), 0.25f, 10.0f).size(), 1u);
    ToolPose bad = b;
    bad.position.x = std::numeric_limits<float>::quiet_NaN();
    EXPECT_EQ(sweepPoses(a, bad, 0.25f, 10.0f).size(), 1u);
    EXPECT_EQ(sweepPoses(a, ToolPose::fromAxis({9.0f, 0, 0}, {0, 0, 1}), 0.01f, 10.0f).size(),
              size_t(kMaxSweepSteps));
}

// A step so small (or a sweep limit so large) that the step count overflows an int still gives
// kMaxSweepSteps equal steps ending at the target; it used to convert 5e30 to int (undefined;
// INT_MIN on x86, and reserve() threw).
TEST(Drill, SweepPosesCapsHugeStepCounts) {
    const ToolPose a = ToolPose::fromAxis({0, 0, 0}, {0, 0, 1});
    const ToolPose b = ToolPose::fromAxis({5.0f, 0, 0}, {0, 0, 1});
    const float inf = std::numeric_limits<float>::infinity();
    for (float step : {1e-30f, std::numeric_limits<float>::denorm_min(), 1e-9f}) {
        std::vector<ToolPose> path;
        ASSERT_NO_THROW(path = sweepPoses(a, b, step, inf));
        ASSERT_EQ(path.size(), size_t(kMaxSweepSteps));
        EXPECT_EQ(path.back().position, b.position);
        EXPECT_NEAR(path[0].position.x, 5.0f / float(kMaxSweepSteps), 1e-5f);
    }
    const ToolPose far = ToolPose::fromAxis({1e5f, 0, 0}, {0, 0, 1});
    EXPECT_EQ(sweepPoses(a, far, 1e-5f, inf).size(), size_t(kMaxSweepSteps));
}

// A burr moved 6 mm across bone between two sampled poses: drilled at the poses alone it leaves
// bone standing between the two dents; swept, it cuts a continuous groove.
TEST(Drill, ASweptStrokeCutsAGrooveWhereSampledPosesLeaveIslands) {
    const Volume original = makeBox(64);
    const glm::vec3 spacing = original.spacing();
    const float quarter = 0.25f * std::min({spacing.x, spacing.y, spacing.z});
    ToolPose from = ToolPose::fromAxis({-3.0f, 0, 0}, {0, 0, 1});
    ToolPose to = ToolPose::fromAxis({3.0f, 0, 0}, {0, 0, 1});
    Volume sampled = original, swept = original;
    Driller d1(ToolShape::burr(2.0f)), d2(ToolShape::burr(2.0f));
    d1.drill(sampled, from, 1.0f, 0.5f);
    d1.drill(sampled, to, 1.0f, 0.5f);
    d2.drill(swept, from, 1.0f, 0.5f);
    const std::vector<ToolPose> path = sweepPoses(from, to, quarter, 10.0f);
    ASSERT_GT(path.size(), 8u);
    for (const ToolPose& p : path)
        d2.drill(swept, p, 1.0f, 0.5f / float(path.size()));
    // Along the stroke's line, every voxel centre within the burr's radius of the path is cut.
    int cutSwept = 0, cutSampled = 0, along = 0;
    for (float x = -3.0f; x <= 3.0f; x += 0.25f) {
        const glm::ivec3 v = glm::ivec3(glm::round(original.toVoxel({x, 0.0f, 0.0f})));
        ++along;
        cutSwept += swept.density(v.x, v.y, v.z) < original.density(v.x, v.y, v.z);
        cutSampled += sampled.density(v.x, v.y, v.z) < original.density(v.x, v.y, v.z);
    }
    EXPECT_EQ(cutSwept, along) << "a continuous groove";
    EXPECT_LT(cutSampled, along) << "the sampled poses alone leave bone between the dents";
}

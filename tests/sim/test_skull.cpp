// The built-in volumes: the procedural skull's determinism, layers and proportions, and the
// analytic sphere and box the renderer and drilling tests rely on.
#include "libsim/skull.h"

#include "libsim/error.h"

#include <algorithm>
#include <cmath>
#include <glm/geometric.hpp>
#include <gtest/gtest.h>
#include <vector>

using namespace trephine;

namespace {

// One n = 256 skull for the read-only tests (about half a second to make).
const Volume& skull256() {
    static const Volume v = makeSkull(256);
    return v;
}

float trilinear(const Volume& v, glm::vec3 c) {
    glm::ivec3 i(glm::floor(c));
    glm::vec3 t = c - glm::floor(c);
    float acc = 0.0f;
    for (int k = 0; k < 8; ++k) {
        glm::ivec3 q = i + glm::ivec3(k & 1, (k >> 1) & 1, k >> 2);
        float w = ((k & 1) ? t.x : 1 - t.x) * ((k & 2) ? t.y : 1 - t.y) * ((k & 4) ? t.z : 1 - t.z);
        if (v.inside(q))
            acc += w * v.density(q.x, q.y, q.z);
    }
    return acc;
}

struct LayerRun {
    Material material;
    int length; // voxels
};

// Materials met walking from `start` (a voxel) in whole-voxel `step`s, run-length encoded.
std::vector<LayerRun> walk(const Volume& v, glm::ivec3 start, glm::ivec3 step) {
    std::vector<LayerRun> runs;
    for (glm::ivec3 q = start; v.inside(q); q += step) {
        Material m = v.material(q.x, q.y, q.z);
        if (runs.empty() || runs.back().material != m)
            runs.push_back({m, 0});
        runs.back().length++;
    }
    return runs;
}

} // namespace

TEST(Skull, SameSeedSameBytesAndOtherSeedsDiffer) {
    Volume a = makeSkull(64, 7);
    Volume b = makeSkull(64, 7);
    EXPECT_TRUE(a == b);
    Volume c = makeSkull(64, 8);
    EXPECT_FALSE(a == c);
    EXPECT_TRUE(makeSkull(48) == makeSkull(48, kDefaultSkullSeed));
}

TEST(Skull, FixedFieldOfViewAndSizeRange) {
    for (int n : {32, 100}) {
        Volume v = makeSkull(n);
        EXPECT_EQ(v.dims(), glm::ivec3(n));
        EXPECT_FLOAT_EQ(v.spacing().x, kSkullFieldOfViewMm / float(n));
        EXPECT_FLOAT_EQ(v.extentMm().z, kSkullFieldOfViewMm);
    }
    EXPECT_THROW(makeSkull(31), Error);
    EXPECT_THROW(makeSkull(513), Error);
    EXPECT_THROW(makeSkull(-1), Error);
}

TEST(Skull, RadialLinesCrossAirOuterTableDiploeInnerTableDuraBrain) {
    const Volume& v = skull256();
    const float h = v.spacing().x;
    // From a voxel at the vault's widest level, walk outward along lattice directions (so every
    // sample is a voxel centre) and read the layers back inward. Steps of at most sqrt(2) voxels
    // (1.1 mm) so that the 1 mm dura cannot be stepped over. The start lies half a voxel off the
    // midline (x = 0 is a voxel boundary): lines in the midline plane meet the sagittal sinus
    // where others meet dura.
    glm::ivec3 start(v.toVoxel(glm::vec3(0.0f, 0.0f, -15.0f)) + 0.5f);
    const glm::ivec3 steps[] = {{0, 0, 1},  {1, 0, 0},  {-1, 0, 0}, {0, 1, 0},  {0, -1, 0},
                                {1, 0, 1},  {-1, 0, 1}, {0, 1, 1},  {0, -1, 1}, {1, 1, 0},
                                {-1, 1, 0}, {1, -1, 0}, {-1, -1, 0}};
    for (glm::ivec3 step : steps) {
        SCOPED_TRACE(testing::Message() << "step " << step.x << "," << step.y << "," << step.z);
        std::vector<LayerRun> runs = walk(v, start, step);
        std::reverse(runs.begin(), runs.end()); // now from outside inward
        const bool midline = step.x == 0;
        const Material expected[] = {Material::Air,
                                     Material::Cortical,
                                     Material::Diploe,
                                     Material::Cortical,
                                     midline ? Material::Sinus : Material::Dura,
                                     Material::Brain};
        ASSERT_EQ(runs.size(), 6u);
        for (int i = 0; i < 6; ++i)
            EXPECT_EQ(runs[i].material, expected[i]) << "layer " << i;
        const float stepMm = h * glm::length(glm::vec3(step));
        // The outermost cortical voxels may be partial-volume ones outside the iso-surface.
        int partial = 0;
        for (glm::ivec3 q = start + step * (runs[2].length + runs[3].length + runs[4].length +
                                            runs[5].length + runs[1].length - 1);
             v.density(q.x, q.y, q.z) < kSurfaceDensity; q -= step)
            ++partial;
        const float outer = (runs[1].length - partial) * stepMm, diploe = runs[2].length * stepMm,
                    inner = runs[3].length * stepMm, dura = runs[4].length * stepMm;
        // Radial lines are within ~15 degrees of the surface normal here; allow one sample.
        EXPECT_NEAR(outer, 1.75f, 0.35f + stepMm);
        EXPECT_NEAR(diploe, 3.5f, 0.6f + stepMm);
        EXPECT_NEAR(inner, 1.25f, 0.3f + stepMm);
        EXPECT_NEAR(outer + diploe + inner, 7.0f, 1.0f + stepMm);
        EXPECT_GE(dura, stepMm);
        if (midline) // the sinus is 2.8 to 6.3 mm deep, front to back
            EXPECT_GE(dura, 2.0f);
        else
            EXPECT_LE(dura, 1.0f + 2 * stepMm);
    }
}

TEST(Skull, DensitiesShowBoneAndExposedDuraButNotBrain) {
    const Volume& v = skull256();
    const uint8_t* d = v.densityData();
    const uint8_t* m = v.materialData();
    int64_t diploe = 0, pores = 0, diploeSum = 0, brainVisible = 0, duraHidden = 0, airSolid = 0;
    for (size_t i = 0; i < v.voxelCount(); ++i) {
        switch (Material(m[i])) {
        case Material::Diploe:
            diploe++;
            diploeSum += d[i];
            pores += d[i] < kSurfaceDensity;
            break;
        case Material::Brain:
            brainVisible += d[i] >= kSurfaceDensity;
            break;
        case Material::Dura:
            duraHidden += d[i] < kSurfaceDensity && d[i] == kSkullDuraDensity;
            break;
        case Material::Air:
            airSolid += d[i] != 0;
            break;
        default:
            break;
        }
    }
    ASSERT_GT(diploe, 0);
    // Porous: marrow cavities below the iso-value, but mostly solid.
    EXPECT_GT(double(pores) / double(diploe), 0.05);
    EXPECT_LT(double(pores) / double(diploe), 0.35);
    double meanDiploe = double(diploeSum) / double(diploe);
    EXPECT_GT(meanDiploe, double(kSurfaceDensity));
    EXPECT_LT(meanDiploe, double(kSkullCorticalDensity));
    EXPECT_EQ(brainVisible, 0);
    EXPECT_EQ(duraHidden, 0);
    EXPECT_EQ(airSolid, 0); // air is density 0; a voxel eroded to 0 is relabelled air
    EXPECT_GE(kSkullDuraDensity, kSurfaceDensity);
    EXPECT_LT(kSkullBrainDensity, kSurfaceDensity);
}

TEST(Skull, HeadSizedOvoidVaultCutBelow) {
    const Volume& v = skull256();
    glm::vec3 lo(1e9f), hi(-1e9f);
    const glm::ivec3 n = v.dims();
    bool boneInLowestFifth = false;
    for (int z = 0; z < n.z; ++z)
        for (int y = 0; y < n.y; ++y)
            for (int x = 0; x < n.x; ++x)
                if (v.material(x, y, z) == Material::Cortical) {
                    glm::vec3 p = v.voxelCenter({x, y, z});
                    lo = glm::min(lo, p);
                    hi = glm::max(hi, p);
                    boneInLowestFifth |= z < n.z / 5;
                }
    glm::vec3 size = hi - lo;
    EXPECT_NEAR(size.x, 144.0f, 8.0f);  // breadth
    EXPECT_NEAR(size.y, 184.0f, 8.0f);  // length
    EXPECT_GT(size.y, size.x + 25.0f);  // longer than wide
    EXPECT_NEAR(size.z, 105.0f, 15.0f); // a skull cap: vertex down to the level of the orbits
    EXPECT_FALSE(boneInLowestFifth);
    // Everything fits, with a margin, in the field of view.
    EXPECT_GT(lo.x, -0.5f * kSkullFieldOfViewMm + 2.0f);
    EXPECT_LT(hi.y, 0.5f * kSkullFieldOfViewMm - 2.0f);
}

TEST(Skull, OuterSurfaceHasPartialVolumeDensities) {
    // The outer surface ramps across about one voxel, so a vertical trilinear ray crosses 128 with
    // a density step well below full cortical between neighbouring voxels.
    const Volume& v = skull256();
    int ramps = 0, columns = 0;
    for (float x = -40.0f; x <= 40.0f; x += 7.3f)
        for (float y = -50.0f; y <= 50.0f; y += 9.1f) {
            glm::ivec3 c(v.toVoxel(glm::vec3(x, y, 0.0f)) + 0.5f);
            for (int z = v.dims().z - 1; z > 0; --z)
                if (v.density(c.x, c.y, z) > 0) {
                    columns++;
                    uint8_t first = v.density(c.x, c.y, z);
                    ramps += first < kSkullCorticalDensity;
                    break;
                }
        }
    ASSERT_GT(columns, 100);
    EXPECT_GT(ramps, columns * 3 / 4);
}

TEST(Skull, DefaultBurrSiteIsKochersPointOnTheOuterTable) {
    const Volume& v = skull256();
    SurfaceSite s = defaultBurrSite(v);
    EXPECT_NEAR(s.position.x, kKocherPointXMm, 1e-3f);
    EXPECT_NEAR(s.position.y, kKocherPointYMm, 1e-3f);
    EXPECT_GT(s.position.z, 20.0f);
    EXPECT_NEAR(glm::length(s.normal), 1.0f, 1e-4f);
    EXPECT_GT(s.normal.z, 0.6f);  // upper vault
    EXPECT_LT(s.normal.x, -0.2f); // right side of the head faces the patient's right
    EXPECT_GT(s.normal.y, 0.1f);  // in front of the vertex
    EXPECT_NEAR(trilinear(v, v.toVoxel(s.position)), float(kSurfaceDensity), 1.0f);
    // Beyond the 2.5-voxel partial-volume ramp (2 mm at n = 256).
    glm::ivec3 out(v.toVoxel(s.position + 3.0f * s.normal) + 0.5f);
    glm::ivec3 in(v.toVoxel(s.position - 1.0f * s.normal) + 0.5f);
    EXPECT_EQ(v.material(out.x, out.y, out.z), Material::Air);
    EXPECT_EQ(v.material(in.x, in.y, in.z), Material::Cortical);
    // Same site in millimetres at another resolution.
    SurfaceSite coarse = defaultBurrSite(makeSkull(128));
    EXPECT_NEAR(coarse.position.z, s.position.z, 0.5f);
    EXPECT_GT(glm::dot(coarse.normal, s.normal), 0.98f);
}

TEST(Skull, DefaultBurrSiteRefusesAVolumeWithNoSurface) {
    Volume air({16, 16, 16}, glm::vec3(1.0f));
    EXPECT_THROW(defaultBurrSite(air), Error);
    EXPECT_THROW(defaultBurrSite(Volume{}), Error);
    // A volume of other proportions falls back to the vertex column.
    SurfaceSite s = defaultBurrSite(makeBox(32));
    EXPECT_NEAR(s.position.z, 8.0f, 0.6f); // box top face at z index 24 = +8 mm
    EXPECT_GT(s.normal.z, 0.99f);
}

TEST(Sphere, TrilinearIsoSurfaceIsTheAnalyticSphere) {
    for (int n : {32, 64, 101}) {
        Volume v = makeSphere(n);
        ASSERT_EQ(v.dims(), glm::ivec3(n));
        ASSERT_EQ(v.spacing(), glm::vec3(1.0f));
        const float r = sphereRadiusMm(n);
        EXPECT_FLOAT_EQ(r, 0.35f * n);
        float worst = 0.0f;
        for (int i = 0; i < 200; ++i) {
            // Spread directions by a golden-angle spiral; bisect the 128 crossing on each ray.
            float zc = 1.0f - (i + 0.5f) / 100.0f, phi = 2.39996323f * i;
            float rho = std::sqrt(std::max(0.0f, 1.0f - zc * zc));
            glm::vec3 dir(rho * std::cos(phi), rho * std::sin(phi), zc);
            float lo = r - 2.0f, hi = r + 2.0f; // inside / outside
            for (int it = 0; it < 40; ++it) {
                float mid = 0.5f * (lo + hi);
                (trilinear(v, v.toVoxel(mid * dir)) >= 128.0f ? lo : hi) = mid;
            }
            worst = std::max(worst, std::fabs(0.5f * (lo + hi) - r));
        }
        EXPECT_LT(worst, 0.05f) << "n = " << n;
    }
    Volume v = makeSphere(32);
    EXPECT_EQ(v.material(16, 16, 16), Material::Cortical);
    EXPECT_EQ(v.density(16, 16, 16), 255);
    EXPECT_EQ(v.density(0, 0, 0), 0);
    EXPECT_EQ(v.material(0, 0, 0), Material::Air);
    EXPECT_TRUE(makeSphere(40) == makeSphere(40));
    EXPECT_THROW(makeSphere(2), Error);
}

TEST(Box, FillsTheMiddleHalfWithSolidCortical) {
    const int n = 20;
    Volume v = makeBox(n);
    EXPECT_EQ(v.spacing(), glm::vec3(1.0f));
    Box3i inner = Box3i::fromMinMax(glm::ivec3(n / 4), glm::ivec3(3 * n / 4));
    for (int z = 0; z < n; ++z)
        for (int y = 0; y < n; ++y)
            for (int x = 0; x < n; ++x) {
                bool in = inner.contains({x, y, z});
                ASSERT_EQ(v.density(x, y, z), in ? 255 : 0);
                ASSERT_EQ(v.material(x, y, z), in ? Material::Cortical : Material::Air);
            }
    EXPECT_EQ(v.materialCounts()[int(Material::Cortical)], inner.count());
    EXPECT_THROW(makeBox(0), Error);
}

TEST(Skull, SurfaceBoxTopsOutAtTheBoneTheCameraOnPlusZSees) {
    Volume v = makeSkull(64);
    const glm::ivec3 d = v.dims();
    for (int n : {4, 10}) {
        const Box3i b = surfaceBox(v, n);
        EXPECT_EQ(b.size(), glm::ivec3(n));
        // Centred on the middle column; the voxel just below the top face is bone, nothing
        // above the box in that column is.
        EXPECT_EQ(b.lo.x, d.x / 2 - n / 2);
        EXPECT_EQ(b.lo.y, d.y / 2 - n / 2);
        EXPECT_GE(v.density(d.x / 2, d.y / 2, b.hi.z - 1), kSurfaceDensity);
        for (int z = b.hi.z; z < d.z; ++z)
            EXPECT_LT(v.density(d.x / 2, d.y / 2, z), kSurfaceDensity) << z;
    }
    EXPECT_EQ(surfaceBox(v, 6, 5).lo.x, d.x / 2 + 5 - 3);
    const Box3i big = surfaceBox(v, 200); // clipped to the volume
    EXPECT_EQ(big.lo, glm::ivec3(0));
    EXPECT_EQ(big.hi.x, d.x);
    EXPECT_EQ(big.hi.y, d.y);
}

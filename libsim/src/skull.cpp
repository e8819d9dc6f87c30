// Built-in volumes: the procedural skull and the analytic sphere and box.
//
// [SECTION] Hash noise      — small deterministic PRNG and value noise (no <random>)
// [SECTION] Skull model     — vault shape, layers, sutures, porosity; one voxel at a time
// [SECTION] Volumes         — makeSkull (threaded over z slabs), makeSphere, makeBox
// [SECTION] Burr site       — defaultBurrSite: march a ray into the actual volume; boxTopSite
#include "libsim/skull.h"

#include "libsim/error.h"
#include "libsim/thread_pool.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <glm/geometric.hpp>
#include <glm/vec2.hpp>
#include <optional>
#include <string>
#include <thread>
#include <vector>

namespace trephine {

namespace {

// [SECTION] Hash noise
// std::uniform_*_distribution differs between standard libraries, so the skull uses its own
// integer hash (lowbias32 by Chris Wellons) and value noise built on it: same seed, same bytes on
// every platform that does IEEE float arithmetic without fast-math.

uint32_t mix32(uint32_t x) {
    x ^= x >> 16;
    x *= 0x7feb352dU;
    x ^= x >> 15;
    x *= 0x846ca68bU;
    x ^= x >> 16;
    return x;
}

// Uniform in [-1, 1] from a 32-bit hash.
float hashToSigned(uint32_t h) {
    return float(h >> 8) * (2.0f / 16777216.0f) - 1.0f;
}

// Smooth 3D value noise in [-1, 1] with a lattice spacing of `cellMm`.
class ValueNoise {
public:
    ValueNoise(uint32_t seed, uint32_t channel, float cellMm)
        : m_seed(mix32(seed * 0x9e3779b9U + mix32(channel + 0x632be5abU))),
          m_invCell(1.0f / cellMm) {}

    float operator()(glm::vec3 pMm) const {
        glm::vec3 p = pMm * m_invCell;
        glm::vec3 f = glm::floor(p);
        glm::ivec3 i(f);
        glm::vec3 t = p - f;
        t = t * t * (3.0f - 2.0f * t); // smoothstep fade: continuous gradient
        float c[8];
        for (int k = 0; k < 8; ++k)
            c[k] = lattice(i.x + (k & 1), i.y + ((k >> 1) & 1), i.z + (k >> 2));
        float x00 = c[0] + (c[1] - c[0]) * t.x;
        float x10 = c[2] + (c[3] - c[2]) * t.x;
        float x01 = c[4] + (c[5] - c[4]) * t.x;
        float x11 = c[6] + (c[7] - c[6]) * t.x;
        float y0 = x00 + (x10 - x00) * t.y;
        float y1 = x01 + (x11 - x01) * t.y;
        return y0 + (y1 - y0) * t.z;
    }

private:
    float lattice(int x, int y, int z) const {
        uint32_t h = uint32_t(x) * 0x8da6b343U + uint32_t(y) * 0xd8163841U +
                     uint32_t(z) * 0xcb1ab31fU + m_seed;
        return hashToSigned(mix32(h));
    }
    uint32_t m_seed;
    float m_invCell;
};

// Seed-dependent scalar in [-1, 1], for per-patient variation of the head's proportions.
float seedParam(uint32_t seed, uint32_t which) {
    return hashToSigned(mix32(mix32(seed ^ 0x51ed270bU) + which * 0x2545f491U));
}

// [SECTION] Skull model
// A cranial vault: an egg-shaped ellipsoid (wider behind than in front) cut below by a plane at
// the level of the orbits. Layers are shells measured inward from the outer table surface with a
// first-order signed-distance estimate, which is within a few per cent of the true distance for
// these proportions. All lengths in mm; +z superior, +y anterior, +x patient's left.

struct SkullModel {
    explicit SkullModel(uint32_t seed, float spacingMm)
        : h(spacingMm), thickOuter(seed, 1, 45.0f), thickDiploe(seed, 2, 38.0f),
          thickInner(seed, 3, 41.0f), pores(seed, 4, kPoreCellMm), poresFine(seed, 5, 1.1f),
          suture(seed, 6, 1.6f) {
        a = 70.0f + 2.0f * seedParam(seed, 0);
        b = 92.0f + 2.5f * seedParam(seed, 1);
        c = 70.0f + 2.5f * seedParam(seed, 2);
        egg = 0.06f + 0.015f * seedParam(seed, 3);
        duraMm = std::max(kSkullDuraMm, h); // at least one voxel, so dura always lies under bone
        poreContrast = std::clamp((2.5f - h) / 1.5f, 0.0f, 1.0f); // full at h <= 1 mm
        zTop = zc + c;
        rampMm = std::max(h, std::min(kRampVoxels * h, kMaxRampMm));
    }

    static constexpr float zc = -15.0f;     // the vault's widest level (parietal eminences)
    static constexpr float kSideC = 100.0f; // below it the temporal walls fall nearly vertically
    static constexpr float kPoreCellMm = 2.2f;

    float h;      // voxel spacing
    float rampMm; // the partial-volume ramp's half-width at the surface
    float a, b, c, egg, duraMm, poreContrast, zTop;
    ValueNoise thickOuter, thickDiploe, thickInner, pores, poresFine, suture;

    // Signed distance estimate (mm) to the outer table surface without sutures: negative inside.
    float outerDistance(glm::vec3 p) const {
        float x = p.x, y = p.y, z = p.z - zc;
        // Two half-ellipsoids joined at the widest level: F and its gradient stay continuous.
        float c = z > 0.0f ? this->c : kSideC;
        float ay = a * (1.0f - egg * y / b); // egg: wider posteriorly (parietal eminences)
        float f2 = x * x / (ay * ay) + y * y / (b * b) + z * z / (c * c);
        float f = std::sqrt(f2);
        // grad(F^2) / 2; F = |q| is close to homogeneous, so (F - 1) / |grad F| is a good distance.
        glm::vec3 g(x / (ay * ay), y / (b * b) + x * x * a * egg / (b * ay * ay * ay), z / (c * c));
        float gradF = glm::length(g) / std::max(f, 1e-6f);
        return (f - 1.0f) / std::max(gradF, 1e-6f);
    }

    // Distance below the cut plane (positive below = outside the volume's skull cap).
    float cutDistance(glm::vec3 p) const {
        // Higher in front (above the orbits) than behind (through the occipital squama).
        float zCut = zc - 30.0f + 0.12f * p.y;
        return (zCut - p.z) * 0.99287f; // normalised: plane normal (0, -0.12, 1)
    }

    // Depth (mm) of the suture grooves in the outer table at p: coronal, sagittal, lambdoid.
    float sutureGroove(glm::vec3 p) const {
        // Coronal: through bregma (midline, y = kBregmaY at the vertex), slanting forward as it
        // descends towards the pterion.
        float dCoronal = (p.y - kBregmaY - 0.35f * (zTop - p.z)) * 0.94346f;
        // Lambdoid: through lambda, slanting forward as it descends towards the asterion.
        float dLambda = (p.y - kLambdaY - 0.8f * (zTop - 20.0f - p.z)) * 0.78087f;
        float d = std::min(std::fabs(dCoronal), std::fabs(dLambda));
        if (dCoronal < 0.0f && dLambda > 0.0f) // sagittal runs between the two on the midline
            d = std::min(d, std::fabs(p.x));
        d += 0.45f * suture(p); // serrated, not straight
        if (d >= kSutureHalfWidth)
            return 0.0f;
        float u = d / kSutureHalfWidth;
        return kSutureDepth * (1.0f - u * u);
    }

    // Partial volume at the outer surface and the cut: 128 (kSurfaceDensity) exactly on the
    // surface, linear in distance, 0 at rampMm outside (2.5 voxels, capped). The renderer's normal
    // is the trilinear blend of central differences at the hit cell's corners, a stencil reaching
    // about 2.7 voxels either side of the surface; where it meets a clamped ramp the normal tilts
    // with the surface's sub-voxel phase and the shading shows contour rings. A ramp of 2.5 voxels
    // keeps that stencil on the linear part.
    float ramp(float sd) const { return std::clamp(128.0f - 128.0f * sd / rampMm, 0.0f, 255.0f); }

    // Brain well below the inner table: depends on the cut plane only (y and z), so a row of
    // such voxels shares one value.
    void evaluateDeep(glm::vec3 p, uint8_t& density, Material& material) const {
        float sdCut = cutDistance(p);
        density = 0;
        material = Material::Air;
        if (sdCut >= rampMm)
            return;
        density = uint8_t(std::lround(std::min(float(kSkullBrainDensity), ramp(sdCut))));
        material = density ? Material::Brain : Material::Air;
    }

    // Half-widths in x of the row (y, z): outside |x| > outer every voxel is air; inside
    // |x| < deep every voxel takes evaluateDeep. Both follow from |grad F| <= kMaxGradF, which
    // bounds the distance estimate by |F - 1| / kMaxGradF; deep < 0 when the row has no such part.
    void rowBounds(float y, float z, float& outer, float& deep) const {
        float zq = z - zc;
        float cz = zq > 0.0f ? c : kSideC;
        float ay = a * (1.0f - egg * y / b);
        float yz = y * y / (b * b) + zq * zq / (cz * cz);
        float fOut = 1.0f + (rampMm + 0.01f) * kMaxGradF;
        float fIn = 1.0f - (deepMm() + 0.1f) * kMaxGradF;
        outer = fOut * fOut > yz ? ay * std::sqrt(fOut * fOut - yz) : -1.0f;
        deep = fIn > 0.0f && fIn * fIn > yz ? ay * std::sqrt(fIn * fIn - yz) : -1.0f;
    }

    void evaluate(glm::vec3 p, uint8_t& density, Material& material) const {
        float sd = outerDistance(p);
        float sdCut = cutDistance(p);
        density = 0;
        material = Material::Air;
        if (sd >= rampMm || sdCut >= rampMm)
            return;
        float depth = -sd;
        float cover = ramp(sdCut);
        if (depth > deepMm()) {
            evaluateDeep(p, density, material);
            return;
        }
        float tOuter = kSkullOuterTableMm + 0.2f * thickOuter(p);
        float tDiploe = kSkullDiploeMm + 0.35f * thickDiploe(p);
        float tInner = kSkullInnerTableMm + 0.15f * thickInner(p);
        float layer;
        // The outer ramp applies to every layer: at coarse n a voxel whose centre is in the
        // diploe can still straddle the outer surface. Only the outer band holds suture grooves.
        cover = std::min(cover, ramp(depth < rampMm + kSutureDepth ? sd + sutureGroove(p) : sd));
        if (depth < tOuter) {
            layer = float(kSkullCorticalDensity);
            material = Material::Cortical;
        } else if (depth < tOuter + tDiploe) {
            material = Material::Diploe;
            // Porous cancellous bone: marrow cavities where the pore noise is high. Voxels
            // coarser than the pores average them away, as a scanner would.
            float fine = poresFine(p);
            float solid = 188.0f + 22.0f * fine;
            if (pores(p) + 0.35f * fine > kPoreThreshold)
                layer = solid + poreContrast * (70.0f + 30.0f * poresFine(p * 0.7f) - solid);
            else
                layer = solid;
        } else if (depth < tOuter + tDiploe + tInner) {
            layer = float(kSkullCorticalDensity);
            material = Material::Cortical;
        } else {
            // Dura, then brain: the dura keeps its full density down to its lower boundary and
            // falls to brain across the next voxel, so dura exposed by drilling always renders
            // as a solid sheet (a blend reaching up into a one-voxel dura left holes at n = 128),
            // while the inside of the cap is still a ramp rather than a step. Labels follow the
            // iso-value.
            float below = (depth - (tOuter + tDiploe + tInner + duraMm)) / h;
            layer = std::clamp(float(kSkullDuraDensity) - 80.0f * below, float(kSkullBrainDensity),
                               float(kSkullDuraDensity));
            material = std::lround(layer) >= kSurfaceDensity ? Material::Dura : Material::Brain;
            blend(sinusCoverage(p, depth - (tOuter + tDiploe + tInner)), kSkullSinusDensity,
                  Material::Sinus, layer, material);
        }
        // The artery lies in a groove of the inner table, half in bone and half in dura.
        const float tBone = tOuter + tDiploe + tInner;
        if (std::fabs(depth - tBone) < arteryRadius() + h)
            blend(arteryCoverage(p, depth - (tBone - 0.35f * arteryRadius())), kSkullArteryDensity,
                  Material::Artery, layer, material);
        float d = std::min(layer, cover);
        density = uint8_t(std::lround(d));
        if (density == 0)
            material = Material::Air;
    }

    // [SECTION] Critical structures: the superior sagittal sinus and the middle meningeal artery.
    // Each has a signed distance to its boundary; a voxel takes the structure's density and label
    // by the fraction of it the structure covers (partial volume, one voxel wide), so the
    // structures' surfaces shade smoothly once a drill exposes them.

    // Fraction (0..1) of a voxel of edge h whose centre lies `sd` mm from a boundary (negative
    // inside).
    float coverage(float sd) const { return std::clamp(0.5f - sd / h, 0.0f, 1.0f); }
    // Brain made visible by the blend is labelled the structure: no brain voxel is ever drawn.
    static void blend(float cover, uint8_t density, Material m, float& layer, Material& material) {
        if (cover <= 0.0f)
            return;
        layer += cover * (float(density) - layer);
        if (cover >= 0.5f ||
            (material == Material::Brain && std::lround(layer) >= long(kSurfaceDensity)))
            material = m;
    }

    // The sinus: a triangle in cross-section, its base on the inner table in the midline and its
    // apex below, widening from front to back as the real sinus does. `below` is the depth under
    // the inner table.
    float sinusCoverage(glm::vec3 p, float below) const {
        float t = std::clamp((60.0f - p.y) / 160.0f, 0.0f, 1.0f);
        float half = kSinusFrontHalfWidthMm + t * (kSinusBackHalfWidthMm - kSinusFrontHalfWidthMm);
        float height = kSinusHeightPerWidth * half;
        // Distance to the triangle's sloping side (approximately, in the x-depth plane) or to
        // its base at the inner table.
        float side = (std::fabs(p.x) - half * (1.0f - below / height)) * height /
                     std::sqrt(height * height + half * half);
        return coverage(std::max(side, -below));
    }

    float arteryRadius() const { return std::max(kArteryRadiusMm, 0.6f * h); }

    // The artery: a tube along a branching path on each temporal-parietal wall, its course given
    // in (y, z) (the walls are nearly vertical there, so a distance in y-z is one along the
    // wall). `off` is the depth relative to the tube's centre line.
    float arteryCoverage(glm::vec3 p, float off) const {
        float along = 1e9f;
        for (const auto& branch : kArteryBranches)
            for (size_t i = 0; i + 1 < branch.size(); ++i)
                along = std::min(along, segmentDistance({p.y, p.z}, branch[i], branch[i + 1]));
        if (along > arteryRadius() + h)
            return 0.0f;
        return coverage(std::sqrt(along * along + off * off) - arteryRadius());
    }
    static float segmentDistance(glm::vec2 q, glm::vec2 a, glm::vec2 b) {
        glm::vec2 ab = b - a;
        float t = std::clamp(glm::dot(q - a, ab) / glm::dot(ab, ab), 0.0f, 1.0f);
        return glm::length(q - (a + t * ab));
    }

    static constexpr float kSinusFrontHalfWidthMm = 2.0f;
    static constexpr float kSinusBackHalfWidthMm = 4.5f;
    static constexpr float kSinusHeightPerWidth = 1.4f;
    static constexpr float kSinusMaxDepthMm = kSinusBackHalfWidthMm * kSinusHeightPerWidth;
    static constexpr float kArteryRadiusMm = 0.8f;
    // The trunk rises from the foramen spinosum above the cut, then splits into a frontal
    // branch running up behind the coronal suture and a parietal branch running back.
    static constexpr std::array<std::array<glm::vec2, 4>, 2> kArteryBranches = {{
        {{{6.0f, -41.0f}, {8.0f, -28.0f}, {18.0f, -12.0f}, {17.0f, 16.0f}}},
        {{{8.0f, -28.0f}, {-12.0f, -20.0f}, {-35.0f, -10.0f}, {-58.0f, 2.0f}}},
    }};

    static constexpr float kBregmaY = 22.0f;
    static constexpr float kLambdaY = -62.0f;
    static constexpr float kSutureHalfWidth = 0.6f;
    static constexpr float kSutureDepth = 0.45f;
    static constexpr float kPoreThreshold = 0.38f;
    // Bound on |grad F| over the volume: 1 / (smallest semi-axis, >= 62.9 mm over all seeds) plus
    // the egg term (< 0.001), with room to spare.
    static constexpr float kMaxGradF = 1.0f / 55.0f;
    static constexpr float kRampVoxels = 2.5f;
    // The ramp's width: 2.5 voxels, but at most kMaxRampMm (the outer table is 1.8 mm thick: a
    // wider ramp softens its bone and blurs it into the diploe at coarse spacings) and at least
    // one voxel.
    static constexpr float kMaxRampMm = 2.0f;
    // Below this depth every voxel is plain brain (the dura/brain blend is one voxel wide).
    float deepMm() const {
        return kMaxBoneMm + std::max({duraMm, kSinusMaxDepthMm, arteryRadius()}) + 2.0f * h + 0.01f;
    }
    static constexpr float kMaxBoneMm =
        kSkullOuterTableMm + 0.2f + kSkullDiploeMm + 0.35f + kSkullInnerTableMm + 0.15f;
};

void checkSize(int n, int lo, int hi, const char* what) {
    if (n < lo || n > hi)
        throw Error(std::string(what) + " size " + std::to_string(n) + " is out of range: use " +
                    std::to_string(lo) + " to " + std::to_string(hi));
}

// Runs fn(z0, z1) over slabs of z on up to hardware_concurrency threads. Each voxel is a pure
// function of its position, so the split does not change the bytes.
template <typename Fn>
void forEachSlab(int nz, int64_t voxels, Fn fn) {
    unsigned hw = std::max(1u, std::thread::hardware_concurrency());
    int threads = int(std::min<int64_t>({int64_t(hw), 8, std::max<int64_t>(1, voxels >> 20)}));
    if (threads <= 1) {
        fn(0, nz);
        return;
    }
    ThreadPool pool(threads, "skull");
    pool.parallelFor(threads, [&](int t) { fn(nz * t / threads, nz * (t + 1) / threads); });
}

// Trilinear density at a continuous voxel coordinate (voxel centres at integers); 0 outside.
float sampleDensity(const Volume& v, glm::vec3 c) {
    glm::vec3 f = glm::floor(c);
    glm::ivec3 i(f);
    glm::vec3 t = c - f;
    float acc = 0.0f;
    for (int k = 0; k < 8; ++k) {
        glm::ivec3 q = i + glm::ivec3(k & 1, (k >> 1) & 1, k >> 2);
        if (!v.inside(q))
            continue;
        float w = ((k & 1) ? t.x : 1.0f - t.x) * (((k >> 1) & 1) ? t.y : 1.0f - t.y) *
                  ((k >> 2) ? t.z : 1.0f - t.z);
        acc += w * float(v.density(q.x, q.y, q.z));
    }
    return acc;
}

} // namespace

// [SECTION] Volumes

Volume makeSkull(int n, uint32_t seed) {
    checkSize(n, 32, 512, "skull");
    float h = kSkullFieldOfViewMm / float(n);
    Volume vol({n, n, n}, glm::vec3(h));
    const SkullModel model(seed, h);
    uint8_t* den = vol.densityData();
    uint8_t* mat = vol.materialData();
    forEachSlab(n, int64_t(n) * n * n, [&](int z0, int z1) {
        for (int z = z0; z < z1; ++z)
            for (int y = 0; y < n; ++y) {
                size_t row = vol.index(0, y, z);
                glm::vec3 p = vol.voxelCenter({0, y, z});
                float outer, deep;
                model.rowBounds(p.y, p.z, outer, deep);
                if (outer < 0.0f)
                    continue; // all air, as the volume starts
                // Voxels with |x| <= outer; the rest stay air.
                int x0 = std::max(0, int(std::floor(-outer / h - 0.5f + 0.5f * float(n))));
                int x1 = std::min(n - 1, int(std::ceil(outer / h - 0.5f + 0.5f * float(n))));
                uint8_t deepDensity = 0;
                Material deepMaterial = Material::Air;
                if (deep > 0.0f)
                    model.evaluateDeep(p, deepDensity, deepMaterial);
                for (int x = x0; x <= x1; ++x) {
                    p.x = (float(x) + 0.5f - 0.5f * float(n)) * h;
                    Material m = deepMaterial;
                    if (std::fabs(p.x) < deep)
                        den[row + x] = deepDensity;
                    else
                        model.evaluate(p, den[row + x], m);
                    mat[row + x] = uint8_t(m);
                }
            }
    });
    return vol;
}

float sphereRadiusMm(int n) {
    return 0.35f * float(n);
}

Volume makeSphere(int n) {
    checkSize(n, 4, 512, "sphere");
    Volume vol({n, n, n}, glm::vec3(1.0f));
    const float r = sphereRadiusMm(n);
    uint8_t* den = vol.densityData();
    uint8_t* mat = vol.materialData();
    forEachSlab(n, int64_t(n) * n * n, [&](int z0, int z1) {
        for (int z = z0; z < z1; ++z)
            for (int y = 0; y < n; ++y)
                for (int x = 0; x < n; ++x) {
                    glm::vec3 p = vol.voxelCenter({x, y, z});
                    // Linear in distance with the 128 crossing at dist == r; the ramp spans
                    // +-kSphereRampMm so every trilinear cell that holds the iso-surface (corners
                    // within sqrt(3) voxels of it) is unclamped: the interpolated iso-surface is
                    // the analytic sphere to within byte rounding (~0.01 mm) and curvature.
                    float d = 128.0f + 127.0f * (r - glm::length(p)) / kSphereRampMm;
                    uint8_t v = uint8_t(std::lround(std::clamp(d, 0.0f, 255.0f)));
                    size_t i = vol.index(x, y, z);
                    den[i] = v;
                    mat[i] = uint8_t(v ? Material::Cortical : Material::Air);
                }
    });
    return vol;
}

Volume makeBox(int n) {
    checkSize(n, 4, 512, "box");
    Volume vol({n, n, n}, glm::vec3(1.0f));
    for (int z = n / 4; z < 3 * n / 4; ++z)
        for (int y = n / 4; y < 3 * n / 4; ++y)
            for (int x = n / 4; x < 3 * n / 4; ++x)
                vol.set(x, y, z, 255, Material::Cortical);
    return vol;
}

// [SECTION] Burr site

Box3i surfaceBox(const Volume& v, int n, int shift) {
    const glm::ivec3 d = v.dims();
    const int cx = std::clamp(d.x / 2 + shift, 0, d.x - 1), cy = d.y / 2;
    int top = d.z - 1;
    while (top > 0 && v.density(cx, cy, top) < kSurfaceDensity)
        --top;
    const glm::ivec3 lo(cx - n / 2, cy - n / 2, top + 1 - n);
    return Box3i::fromMinMax(lo, lo + glm::ivec3(n)).intersect(v.bounds());
}

std::optional<SurfaceSite> surfaceSiteBelow(const Volume& skull, glm::vec2 col) {
    if (skull.empty())
        return std::nullopt;
    const glm::vec3 ext = skull.extentMm();
    const float hMin = std::min({skull.spacing().x, skull.spacing().y, skull.spacing().z});
    // March down a vertical ray from the top face in quarter-voxel steps; the first crossing
    // of kSurfaceDensity is refined by bisection.
    const float step = 0.25f * hMin;
    glm::vec3 prev(col.x, col.y, 0.5f * ext.z);
    float prevD = sampleDensity(skull, skull.toVoxel(prev));
    // Counted steps (z from the step count, not accumulated): a float z -= step stops moving
    // where step falls under half z's ulp.
    const int steps = int(std::min(double(ext.z) / double(step), 1e8));
    for (int k = 1; k < steps; ++k) {
        const float z = 0.5f * ext.z - float(k) * step;
        glm::vec3 p(col.x, col.y, z);
        float d = sampleDensity(skull, skull.toVoxel(p));
        if (d >= float(kSurfaceDensity) && prevD < float(kSurfaceDensity)) {
            glm::vec3 lo = prev, hi = p; // lo outside, hi inside
            for (int it = 0; it < 24; ++it) {
                glm::vec3 mid = 0.5f * (lo + hi);
                if (sampleDensity(skull, skull.toVoxel(mid)) >= float(kSurfaceDensity))
                    hi = mid;
                else
                    lo = mid;
            }
            glm::vec3 s = 0.5f * (lo + hi);
            // Outward normal: minus the density gradient, by central differences one voxel
            // apart (smooths the byte quantisation).
            glm::vec3 c = skull.toVoxel(s);
            glm::vec3 g((sampleDensity(skull, c + glm::vec3(1, 0, 0)) -
                         sampleDensity(skull, c - glm::vec3(1, 0, 0))) /
                            skull.spacing().x,
                        (sampleDensity(skull, c + glm::vec3(0, 1, 0)) -
                         sampleDensity(skull, c - glm::vec3(0, 1, 0))) /
                            skull.spacing().y,
                        (sampleDensity(skull, c + glm::vec3(0, 0, 1)) -
                         sampleDensity(skull, c - glm::vec3(0, 0, 1))) /
                            skull.spacing().z);
            glm::vec3 nrm = glm::length(g) > 0.0f ? -glm::normalize(g) : glm::vec3(0, 0, 1);
            return SurfaceSite{s, nrm};
        }
        prev = p;
        prevD = d;
    }
    return std::nullopt;
}

SurfaceSite defaultBurrSite(const Volume& skull) {
    if (skull.empty())
        throw Error("cannot find a burr-hole site: the volume is empty");
    // Kocher's point, then the vertex, for volumes whose proportions differ from ours.
    for (glm::vec2 col : {glm::vec2(kKocherPointXMm, kKocherPointYMm), glm::vec2(0.0f, 0.0f)})
        if (const std::optional<SurfaceSite> site = surfaceSiteBelow(skull, col))
            return *site;
    throw Error("cannot find a burr-hole site: no surface at density " +
                std::to_string(int(kSurfaceDensity)) + " under the top of the volume");
}

SurfaceSite boxTopSite(const Volume& box) {
    // makeBox fills voxels [n/4, 3n/4); the trilinear iso-surface lies halfway between the last
    // solid voxel centre and the first air one.
    const int top = 3 * box.dims().z / 4;
    const float z = 0.5f * (box.voxelCenter({0, 0, top - 1}).z + box.voxelCenter({0, 0, top}).z);
    return {glm::vec3(0.0f, 0.0f, z), glm::vec3(0.0f, 0.0f, 1.0f)};
}

} // namespace trephine

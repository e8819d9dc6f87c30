// The CPU ray caster behind the DBI. docs/rendering.md explains the conventions and the reasoning.
//
// [SECTION] Frame setup: matrices and voxel-space constants shared by every ray of one render
// [SECTION] Sampling: trilinear density with air outside the volume, the marching test, gradient
// [SECTION] Marching: fixed sample indices, brick skipping, first hit, refinement
// [SECTION] Tile pass: one cone march per 8x8 pixel block, exact like any other skip
// [SECTION] Shading and depth
// [SECTION] Renderer: tiles over the worker pool
#include "libsim/renderer.h"

#include "libsim/dirty_rect.h"
#include "libsim/thread_pool.h"

#include <algorithm>
#include <atomic>
#include <cassert>
#include <climits>
#include <cmath>
#include <cstring>
#include <emmintrin.h>
#include <glm/geometric.hpp>
#include <glm/matrix.hpp>
#include <immintrin.h>

namespace trephine {

glm::vec3 materialColor(Material m) {
    switch (m) {
    case Material::Cortical:
        return {232.0f, 222.0f, 196.0f}; // ivory
    case Material::Diploe:
        return {190.0f, 132.0f, 108.0f}; // darker, reddish marrow
    case Material::Dura:
        return {205.0f, 84.0f, 88.0f}; // pinkish red
    case Material::Brain:
        return {226.0f, 178.0f, 172.0f}; // pinkish grey
    case Material::Sinus:
        return {92.0f, 52.0f, 120.0f}; // venous blue-purple
    case Material::Artery:
        return {214.0f, 38.0f, 34.0f}; // arterial red
    default:
        return {232.0f, 222.0f, 196.0f};
    }
}

namespace {

// [SECTION] Frame setup ------------------------------------------------------------------------

// GCC vector extensions (SSE2 on baseline x86-64): four floats or ints, lane-wise arithmetic with
// the same IEEE operations as the scalar code (no FMA contraction on baseline x86-64), so a
// vectorised formula gives the bits of its scalar form.
typedef float v4sf __attribute__((vector_size(16)));
typedef int32_t v4si __attribute__((vector_size(16)));
// Eight lanes: two SSE2 registers on baseline x86-64, one in the AVX2 build. Internal functions
// only, so the ABI of 32-byte vector arguments without AVX does not matter.
#pragma GCC diagnostic ignored "-Wpsabi"
typedef float v8sf __attribute__((vector_size(32)));
typedef int32_t v8si __attribute__((vector_size(32)));
typedef uint32_t v8su __attribute__((vector_size(32)));

struct Frame {
    const uint8_t* density;
    const uint8_t* material;
    glm::ivec3 n;
    ptrdiff_t sy, sz; // strides of y and z in voxels
    glm::vec3 spacing;
    glm::vec3 invSpacing;
    int width, height;
    double ndcPerPixelX, ndcPerPixelY; // 2 / width, 2 / height
    glm::dmat4 viewProj;
    // The far-plane point of a pixel, homogeneous: farH + ndc.x * farDx + ndc.y * farDy. Points
    // on the far plane share one clip w, so after the divide it is affine in the pixel.
    glm::dvec4 farH, farDx, farDy;
    double nearOverFar;
    double focalPx; // distance of the image plane from the eye, in pixels
    // Pixel rays in float (pixelRay): eye-to-far-plane vector of window position (wx, wy) is
    // toFar0 + wx * toFarDx + wy * toFarDy (lane 3 zero), affine since the far plane's clip w is
    // one constant.
    v4sf toFar0, toFarDx, toFarDy;
    v4sf invSpacing4; // invSpacing, lane 3 one
    float nearOverFarF;
    glm::dvec3 eye;
    glm::vec3 origin;        // eye in voxel coordinates
    v4sf origin4;            // origin, lane 3 zero
    v4sf regionLo, regionHi; // the sampled region [-1, n] per axis; lane 3 -inf, +inf
    // Rows 3 and 4 of viewProj (clip z and w of an object-space point), for windowDepth's
    // arithmetic inlined: z = (zx px + zy py + zz pz) + z0.
    double zx, zy, zz, z0, wx, wy, wz, w0;
    float dt; // sample step along the ray, mm
    float minSpacing;
    double maxSampleT;       // distance from the eye to the farthest corner of the volume
    float tLimit;            // kMaxSampleIndex * dt: no ray marches beyond (see makeFrame)
    const uint8_t* distance; // brick grid distances; null: no skipping
    const uint64_t* cells;   // brick grid cell masks
    const uint8_t* runs[6];  // brick grid runs of empty bricks, [2 axis + positive]
    glm::ivec3 nb;           // bricks per axis
    size_t nbxy;
    bool marchEight; // skipping on and voxel offsets fit int32: marchEight may run (AVX2 build)
    bool nearEye;    // sample positions are within ~1e-3 voxel of the exact ray (see makeFrame)
    // Renderer::renderChanged: a pixel whose cached first inside sample lies outside
    // [keepLo, keepHi] (sample coordinates; lane 3 -inf, +inf) keeps its frame values.
    bool keep = false;
    v4sf keepLo, keepHi;
};

// See makeFrame: float positions are exact to ~6e-8 of their magnitude, and skipping needs them
// within 1/765 voxel (see march).
constexpr float kMaxSkipEyeVoxels = 2048.0f;

// Sample indices are int (and a hit cache keeps them as int32_t): the farthest sample of any ray
// has at most this index, half of INT_MAX, so rounding can never take one past it. See makeFrame.
constexpr double kMaxSampleIndex = double(1 << 30);

Frame makeFrame(const Volume& volume, const Camera& camera, const RenderOptions& options,
                const BrickGrid& bricks) {
    Frame f;
    f.density = volume.densityData();
    f.material = volume.materialData();
    f.n = volume.dims();
    f.sy = f.n.x;
    f.sz = ptrdiff_t(f.n.x) * f.n.y;
    f.spacing = volume.spacing();
    f.invSpacing = 1.0f / f.spacing;
    f.invSpacing4 = v4sf{f.invSpacing.x, f.invSpacing.y, f.invSpacing.z, 1.0f};
    f.width = camera.width;
    f.height = camera.height;
    f.ndcPerPixelX = 2.0 / camera.width;
    f.ndcPerPixelY = 2.0 / camera.height;
    f.viewProj = viewProjection(camera);
    glm::dmat4 inv = glm::inverse(f.viewProj);
    f.farH = inv * glm::dvec4(0.0, 0.0, 1.0, 1.0);
    f.farDx = inv * glm::dvec4(1.0, 0.0, 0.0, 0.0);
    f.farDy = inv * glm::dvec4(0.0, 1.0, 0.0, 0.0);
    f.nearOverFar = double(camera.nearMm) / double(camera.farMm);
    f.focalPx = 0.5 * camera.height /
                std::tan(0.5 * (double(camera.fovYDeg) * 3.14159265358979323846 / 180.0));
    f.nearOverFarF = float(f.nearOverFar);
    {
        // h(ndc) = farH + ndc.x farDx + ndc.y farDy has one w over the far plane (farDx.w and
        // farDy.w are zero up to rounding: the inverse projection's w reads clip z and w only),
        // so the far point h / w is affine in the window position: no division per pixel.
        const double w = f.farH.w;
        const glm::dvec3 a = glm::dvec3(f.farH) / w - glm::dvec3(camera.eye);
        const glm::dvec3 dx = glm::dvec3(f.farDx) / w * f.ndcPerPixelX;
        const glm::dvec3 dy = glm::dvec3(f.farDy) / w * f.ndcPerPixelY;
        const glm::dvec3 a0 = a - dx * (camera.width * 0.5) - dy * (camera.height * 0.5);
        f.toFar0 = v4sf{float(a0.x), float(a0.y), float(a0.z), 0.0f};
        f.toFarDx = v4sf{float(dx.x), float(dx.y), float(dx.z), 0.0f};
        f.toFarDy = v4sf{float(dy.x), float(dy.y), float(dy.z), 0.0f};
    }
    f.eye = glm::dvec3(camera.eye);
    glm::dvec3 half = glm::dvec3(f.n) * 0.5 - 0.5;
    f.origin = glm::vec3(f.eye / glm::dvec3(f.spacing) + half);
    f.origin4 = v4sf{f.origin.x, f.origin.y, f.origin.z, 0.0f};
    f.regionLo = v4sf{-1.0f, -1.0f, -1.0f, -INFINITY};
    f.regionHi = v4sf{float(f.n.x), float(f.n.y), float(f.n.z), INFINITY};
    f.zx = f.viewProj[0][2], f.zy = f.viewProj[1][2], f.zz = f.viewProj[2][2];
    f.z0 = f.viewProj[3][2];
    f.wx = f.viewProj[0][3], f.wy = f.viewProj[1][3], f.wz = f.viewProj[2][3];
    f.w0 = f.viewProj[3][3];
    f.minSpacing = std::min({f.spacing.x, f.spacing.y, f.spacing.z});
    f.maxSampleT = 0.0;
    glm::dvec3 h = glm::dvec3(volume.extentMm()) * 0.5 + glm::dvec3(f.spacing); // + a voxel
    for (int i = 0; i < 8; ++i)
        f.maxSampleT = std::max(f.maxSampleT,
                                glm::length(glm::dvec3((i & 1) ? h.x : -h.x, (i & 2) ? h.y : -h.y,
                                                       (i & 4) ? h.z : -h.z) -
                                            f.eye));
    // Sample k is at t = k dt and every sample lies in the volume, so k <= maxSampleT / dt: up to
    // 3.5e9 with the eye 1e6 mm out on each axis (trephine render --eye) and 0.001 mm voxels, past
    // INT_MAX. Where that would pass kMaxSampleIndex the step widens so that it does not. Such a
    // view loses nothing by it: there float t is already rounded to ulp(2^30 dt), 64 to 128 dt,
    // so finer samples would not be distinct. Every view a client may ask for (eye within 1e5 mm,
    // 4096 voxels, spacings within 1000x of each other) at the default half-voxel step stays under
    // 3.7e8 and keeps its step bit for bit.
    f.dt = std::max(1e-3f, options.stepVoxels) * f.minSpacing;
    const double dtFloor = f.maxSampleT / kMaxSampleIndex;
    if (double(f.dt) < dtFloor)
        f.dt = std::nextafter(float(dtFloor), INFINITY);
    f.tLimit = float(kMaxSampleIndex) * f.dt; // >= maxSampleT
    // Skipping relies on sample positions being within ~1e-3 voxel of the exact ray (float
    // rounding grows with the distance of the eye, in voxels): beyond that, march everything.
    glm::vec3 eyeVoxels = glm::abs(f.origin - glm::vec3(f.n) * 0.5f);
    f.nearEye = std::max({eyeVoxels.x, eyeVoxels.y, eyeVoxels.z}) < kMaxSkipEyeVoxels;
    f.distance =
        options.skipEmpty && !bricks.empty() && f.nearEye ? bricks.distanceData() : nullptr;
    f.cells = bricks.cellData();
    for (int i = 0; i < 6; ++i)
        f.runs[i] = bricks.empty() ? nullptr : bricks.runData(i / 2, i % 2 != 0);
    f.nb = bricks.dims();
    f.nbxy = size_t(f.nb.x) * size_t(f.nb.y);
    f.marchEight = f.distance != nullptr && f.n.x >= 4 && f.n.y >= 2 && f.n.z >= 2 &&
                   f.sz * ptrdiff_t(f.n.z) < ptrdiff_t(INT32_MAX);
    return f;
}

// [SECTION] Sampling ---------------------------------------------------------------------------

// floor(x) for x > -16 without libm (baseline x86-64 has no SSE4.1 round, so floorf is a call):
// truncation of a positive number. x + 16 may round up to the next integer when x lies within an
// ulp below one; the sample then uses the next cell with a weight of about -1e-6, which is the
// same value to within 1e-4 and, being a function of x alone, the same in every render. Sample,
// hit and gradient positions lie in [-2, n + 2]; brick lookups clamp whatever this gives below 0.
inline int floorInt(float x) {
    return int(x + 16.0f) - 16;
}

inline float voxelAt(const Frame& f, int x, int y, int z) {
    if (x < 0 || y < 0 || z < 0 || x >= f.n.x || y >= f.n.y || z >= f.n.z)
        return 0.0f;
    return f.density[x + f.sy * y + f.sz * z];
}

// Trilinear density at voxel coordinate p (voxel centres at integers); voxels outside the volume
// are air. The in-volume fast path and the border path feed the same arithmetic, so a sample
// depends on p alone.
//
// Each lerp is (1 - t) a + t b with both weights >= 0, never a + t (b - a): every float operation
// is then monotone in every corner, so lowering corners (erosion) can never raise a sample, not
// even by an ulp. The hit cache relies on it (HitCache). a + t (b - a) is not monotone in a: with
// t near 1 its rounding can outweigh the (1 - t) share of a change of a.
inline float trilinear(float tx, float ty, float tz, float c000, float c100, float c010, float c110,
                       float c001, float c101, float c011, float c111) {
    const float ux = 1.0f - tx, uy = 1.0f - ty, uz = 1.0f - tz;
    float c00 = ux * c000 + tx * c100, c10 = ux * c010 + tx * c110;
    float c01 = ux * c001 + tx * c101, c11 = ux * c011 + tx * c111;
    float c0 = uy * c00 + ty * c10, c1 = uy * c01 + ty * c11;
    return uz * c0 + tz * c1;
}

// The same arithmetic four lanes at a time: floorInt of every lane (lane 3 is padding).
inline v4si floorInt4(v4sf p) {
    return __builtin_convertvector(p + 16.0f, v4si) - 16;
}

template <int I>
inline v4sf broadcast(v4sf v) {
    return __builtin_shuffle(v, v4si{I, I, I, I});
}

// The eight corners of the trilinear cell whose lowest voxel is b, one byte each, in the low 8
// bytes (the high 8 are zero): the x pairs of the rows (y, z) = (0, 0), (1, 0), (0, 1), (1, 1),
// i.e. c000 c100 c010 c110 c001 c101 c011 c111. Four 2-byte loads instead of eight byte loads.
inline __m128i loadCorners(const uint8_t* b, ptrdiff_t sy, ptrdiff_t sz) {
    uint16_t r0, r1, r2, r3;
    std::memcpy(&r0, b, 2);
    std::memcpy(&r1, b + sy, 2);
    std::memcpy(&r2, b + sz, 2);
    std::memcpy(&r3, b + sz + sy, 2);
    __m128i v = _mm_cvtsi32_si128(int(uint32_t(r0) | uint32_t(r1) << 16));
    v = _mm_insert_epi16(v, r2, 2);
    return _mm_insert_epi16(v, r3, 3);
}

// trilinear() of the corners from loadCorners at fractions t (lanes x, y, z): the same IEEE
// operations lane by lane (the four x lerps in one vector, the two y lerps in another), so the
// same bits, in about half the instructions of eight byte conversions and seven scalar lerps.
inline float trilinearCorners(__m128i corners, v4sf t) {
    const __m128i w = _mm_unpacklo_epi8(corners, _mm_setzero_si128());              // 8 x u16
    const v4sf a = (v4sf)_mm_cvtepi32_ps(_mm_and_si128(w, _mm_set1_epi32(0xffff))); // x = 0
    const v4sf b = (v4sf)_mm_cvtepi32_ps(_mm_srli_epi32(w, 16));                    // x = 1
    const v4sf u = 1.0f - t;
    const v4sf x = broadcast<0>(u) * a + broadcast<0>(t) * b; // c00 c10 c01 c11
    const v4sf lo = __builtin_shuffle(x, v4si{0, 2, 0, 2}),
               hi = __builtin_shuffle(x, v4si{1, 3, 1, 3});
    const v4sf y = broadcast<1>(u) * lo + broadcast<1>(t) * hi; // c0 c1
    return u[2] * y[0] + t[2] * y[1];
}

inline bool cellInVolume(const Frame& f, int ix, int iy, int iz) {
    return unsigned(ix) < unsigned(f.n.x - 1) && unsigned(iy) < unsigned(f.n.y - 1) &&
           unsigned(iz) < unsigned(f.n.z - 1);
}

// p: voxel coordinates (lane 3 padding), i: floorInt4(p).
inline float sampleDensity(const Frame& f, v4sf p, v4si i) {
    const int ix = i[0], iy = i[1], iz = i[2];
    const v4sf t = p - __builtin_convertvector(i, v4sf);
    if (cellInVolume(f, ix, iy, iz))
        return trilinearCorners(loadCorners(f.density + ix + f.sy * iy + f.sz * iz, f.sy, f.sz), t);
    if (ix < -1 || iy < -1 || iz < -1 || ix >= f.n.x || iy >= f.n.y || iz >= f.n.z)
        return 0.0f;
    return trilinear(t[0], t[1], t[2], voxelAt(f, ix, iy, iz), voxelAt(f, ix + 1, iy, iz),
                     voxelAt(f, ix, iy + 1, iz), voxelAt(f, ix + 1, iy + 1, iz),
                     voxelAt(f, ix, iy, iz + 1), voxelAt(f, ix + 1, iy, iz + 1),
                     voxelAt(f, ix, iy + 1, iz + 1), voxelAt(f, ix + 1, iy + 1, iz + 1));
}

inline float sampleDensity(const Frame& f, v4sf p) {
    return sampleDensity(f, p, floorInt4(p));
}

// The marching test: is the sample at p at or above the iso-value? A trilinear sample is a convex
// combination of its eight corners, so when no corner reaches 128 (bit 7 clear in all of them)
// the answer is no without interpolating; otherwise the sample decides, exactly as
// sampleDensity would. Returns the sample in `value`, or -1 when the corner test answered.
static_assert(kSurfaceDensity == 128, "the corner test below reads bit 7");
inline bool insideSample(const Frame& f, v4sf p, v4si i, float& value) {
    const int ix = i[0], iy = i[1], iz = i[2];
    if (cellInVolume(f, ix, iy, iz)) {
        const __m128i c = loadCorners(f.density + ix + f.sy * iy + f.sz * iz, f.sy, f.sz);
        if (_mm_movemask_epi8(c) == 0) {
            value = -1.0f;
            return false;
        }
        value = trilinearCorners(c, p - __builtin_convertvector(i, v4sf));
    } else {
        value = sampleDensity(f, p, i);
    }
    return value >= float(kSurfaceDensity);
}

inline v4sf lerp4(v4sf a, v4sf b, float t) {
    return a + t * (b - a);
}

// gradientAt near the volume's faces, voxel by voxel with air outside (kept out of line: rare).
__attribute__((noinline)) v4sf gradientAtBorder(const Frame& f, int ix, int iy, int iz, v4sf t) {
    v4sf g[8];
    for (int i = 0; i < 8; ++i) {
        const int x = ix + (i & 1), y = iy + ((i >> 1) & 1), z = iz + (i >> 2);
        const glm::vec3 d(voxelAt(f, x + 1, y, z) - voxelAt(f, x - 1, y, z),
                          voxelAt(f, x, y + 1, z) - voxelAt(f, x, y - 1, z),
                          voxelAt(f, x, y, z + 1) - voxelAt(f, x, y, z - 1));
        const glm::vec3 gs = d * 0.5f;
        g[i] = v4sf{gs.x, gs.y, gs.z, 0.0f};
    }
    const v4sf g00 = lerp4(g[0], g[1], t[0]), g10 = lerp4(g[2], g[3], t[0]);
    const v4sf g01 = lerp4(g[4], g[5], t[0]), g11 = lerp4(g[6], g[7], t[0]);
    return lerp4(lerp4(g00, g10, t[1]), lerp4(g01, g11, t[1]), t[2]);
}

// Density gradient (per voxel) at p: central differences at the eight voxels around p,
// trilinearly interpolated. Smooth across voxel faces, unlike differences of trilinear samples,
// so the shading shows no terraces. Reads voxels within 2 of p (see kDirtyStencilVoxels).
// i: floorInt4(p). Returns (x, y, z, 0). Central differences at the eight corners of p's cell read
// the 32 voxels of the cell and its face neighbours (never the edges or corners of the 4^3
// neighbourhood).
inline v4sf gradientAt(const Frame& f, v4sf p, v4si i) {
    const int ix = i[0], iy = i[1], iz = i[2];
    const v4sf t = p - __builtin_convertvector(i, v4sf);
    if (!(ix >= 1 && iy >= 1 && iz >= 1 && ix + 2 < f.n.x && iy + 2 < f.n.y && iz + 2 < f.n.z))
        return gradientAtBorder(f, ix, iy, iz, t);
    // In SSE2, component by component: for each of x, y, z the differences at the four corners
    // with x = 0 (A) and the four with x = 1 (B), lanes in corner order (y, z) = (0, 0), (1, 0),
    // (0, 1), (1, 1). The 32 voxels come in as twelve 4-byte rows (x = -1..2) and byte k of a row
    // is lane-wise (row >> 8k) & 255. Differences of bytes in integers, converted once:
    // float(a) - float(b) is exact for bytes. Then the x lerps per component (the lanes of the
    // per-corner vec3 formula, the same operations), a transpose to one vector (x, y, z, 0) per
    // cell edge, and the y and z lerps as in gradientAtBorder: bit for bit its result.
    const uint8_t* b = f.density + (ix - 1) + f.sy * iy + f.sz * iz;
    const ptrdiff_t sy = f.sy, sz = f.sz;
    auto row = [&](int y, int z) {
        int32_t v;
        std::memcpy(&v, b + sy * y + sz * z, 4);
        return v;
    };
    auto rows = [](int32_t r0, int32_t r1, int32_t r2, int32_t r3) {
        return _mm_set_epi32(r3, r2, r1, r0);
    };
    const __m128i r00 = rows(row(0, 0), row(1, 0), row(0, 1), row(1, 1));
    const __m128i yp = rows(row(1, 0), row(2, 0), row(1, 1), row(2, 1));
    const __m128i ym = rows(row(-1, 0), row(0, 0), row(-1, 1), row(0, 1));
    const __m128i zp = rows(row(0, 1), row(1, 1), row(0, 2), row(1, 2));
    const __m128i zm = rows(row(0, -1), row(1, -1), row(0, 0), row(1, 0));
    const __m128i m8 = _mm_set1_epi32(0xff);
    auto byte1 = [&](__m128i v) { return _mm_and_si128(_mm_srli_epi32(v, 8), m8); };
    auto byte2 = [&](__m128i v) { return _mm_and_si128(_mm_srli_epi32(v, 16), m8); };
    auto half = [](__m128i d) { return __builtin_convertvector((v4si)d, v4sf) * 0.5f; };
    const v4sf ax = half(_mm_sub_epi32(byte2(r00), _mm_and_si128(r00, m8)));
    const v4sf bx = half(_mm_sub_epi32(_mm_srli_epi32(r00, 24), byte1(r00)));
    const v4sf ay = half(_mm_sub_epi32(byte1(yp), byte1(ym)));
    const v4sf by = half(_mm_sub_epi32(byte2(yp), byte2(ym)));
    const v4sf az = half(_mm_sub_epi32(byte1(zp), byte1(zm)));
    const v4sf bz = half(_mm_sub_epi32(byte2(zp), byte2(zm)));
    __m128 gx = (__m128)lerp4(ax, bx, t[0]), gy = (__m128)lerp4(ay, by, t[0]);
    __m128 gz = (__m128)lerp4(az, bz, t[0]), gw = _mm_setzero_ps();
    _MM_TRANSPOSE4_PS(gx, gy, gz, gw); // now g00, g10, g01, g11
    return lerp4(lerp4((v4sf)gx, (v4sf)gy, t[1]), lerp4((v4sf)gz, (v4sf)gw, t[1]), t[2]);
}

// [SECTION] Marching ---------------------------------------------------------------------------

struct Ray {
    glm::dvec3 dir;  // unit, object space
    glm::vec3 dv;    // direction in voxel units per mm
    glm::vec3 invDv; // 1 / dv (inf where dv is 0)
    double tNear;    // distance along the ray to the near and far planes
    double tFar;
    v4sf dv4;     // dv, lane 3 zero
    v4sf dir4;    // dir in float (exact: pixelRay computes it in float), lane 3 zero
    v4sf invDv4;  // invDv, lane 3 one
    int mainAxis; // the axis of the largest |dv|: voxels crossed fastest
};

inline int mainAxisOf(glm::vec3 dv) {
    const glm::vec3 a = glm::abs(dv);
    return a.x >= a.y ? (a.x >= a.z ? 0 : 2) : (a.y >= a.z ? 1 : 2);
}

// The ray through window position (wx, wy) (pixel x's centre is x + 0.5).
// Divisions are few and done once (they are most of the cost of setting up a ray).
Ray windowRay(const Frame& f, double wx, double wy) {
    double ndcX = wx * f.ndcPerPixelX - 1.0, ndcY = wy * f.ndcPerPixelY - 1.0;
    glm::dvec4 h = f.farH + ndcX * f.farDx + ndcY * f.farDy;
    glm::dvec3 toFar = glm::dvec3(h) * (1.0 / h.w) - f.eye;
    Ray r;
    r.tFar = std::sqrt(glm::dot(toFar, toFar));
    r.dir = toFar * (1.0 / r.tFar);
    r.tNear = r.tFar * f.nearOverFar; // eye-space depth grows linearly along the ray
    r.dv = glm::vec3(r.dir) * f.invSpacing;
    r.invDv = 1.0f / r.dv;
    r.dv4 = v4sf{r.dv.x, r.dv.y, r.dv.z, 0.0f};
    r.dir4 = v4sf{float(r.dir.x), float(r.dir.y), float(r.dir.z), 0.0f};
    r.invDv4 = v4sf{r.invDv.x, r.invDv.y, r.invDv.z, 1.0f};
    r.mainAxis = mainAxisOf(r.dv);
    return r;
}

// The ray through pixel (x, y)'s centre as render() traces it: float, no division but the
// normalisation and the reciprocals (one vector division). Float is ample: the direction is good
// to ~1e-7, i.e. 3e-5 mm at 300 mm; skipping only needs samples, leaps and exits to use the same
// dv and invDv, which they do.
Ray pixelRay(const Frame& f, int x, int y) {
    const v4sf toFar = f.toFar0 + (float(x) + 0.5f) * f.toFarDx + (float(y) + 0.5f) * f.toFarDy;
    const v4sf sq = toFar * toFar;
    const float len = std::sqrt(sq[0] + sq[1] + sq[2]);
    const v4sf dir = toFar * (1.0f / len);
    v4sf dv = dir * f.invSpacing4;
    dv[3] = 1.0f;
    const v4sf invDv = 1.0f / dv;
    Ray r;
    r.dir = glm::dvec3(dir[0], dir[1], dir[2]);
    r.tFar = len;
    r.tNear = len * f.nearOverFarF;
    r.dv = glm::vec3(dv[0], dv[1], dv[2]);
    r.invDv = glm::vec3(invDv[0], invDv[1], invDv[2]);
    r.dv4 = dv;
    r.dv4[3] = 0.0f;
    r.dir4 = dir;
    r.invDv4 = invDv;
    r.mainAxis = mainAxisOf(r.dv);
    return r;
}

inline glm::vec3 samplePos(const Frame& f, const Ray& r, float t) {
    return glm::vec3(f.origin.x + t * r.dv.x, f.origin.y + t * r.dv.y, f.origin.z + t * r.dv.z);
}

// samplePos in one vector (lane 3 zero): the same operations, the same bits.
inline v4sf samplePos4(const Frame& f, const Ray& r, float t) {
    return f.origin4 + t * r.dv4;
}

// renderChanged: the pixel's cached first inside sample `k` (known) proves its hit, and all the
// hit reads, clear of the change, or the ray can never hit.
inline bool keptPixel(const Frame& f, const Ray& r, int32_t k) {
    if (k == HitCache::kNever)
        return true;
    const v4sf p = samplePos4(f, r, float(k) * f.dt);
    return p[0] < f.keepLo[0] || p[1] < f.keepLo[1] || p[2] < f.keepLo[2] || p[0] > f.keepHi[0] ||
           p[1] > f.keepHi[1] || p[2] > f.keepHi[2];
}

inline int brickCoord(float p, int n) {
    return std::clamp(floorInt(p), 0, n - 1) >> BrickGrid::kShift;
}

// Where the ray leaves the box of bricks within Chebyshev distance `radius` of brick b. A face on
// the grid's edge is open: samples beyond it still belong to the edge brick.
inline float boxExit(const Frame& f, const Ray& r, glm::ivec3 lo, glm::ivec3 hi) {
    float tExit = INFINITY;
    for (int a = 0; a < 3; ++a) {
        if (r.dv[a] > 0.0f) {
            if (hi[a] < f.nb[a] - 1)
                tExit = std::min(tExit, (float((hi[a] + 1) << BrickGrid::kShift) - f.origin[a]) *
                                            r.invDv[a]);
        } else if (r.dv[a] < 0.0f) {
            if (lo[a] > 0)
                tExit =
                    std::min(tExit, (float(lo[a] << BrickGrid::kShift) - f.origin[a]) * r.invDv[a]);
        }
    }
    return tExit;
}

inline float boxExit(const Frame& f, const Ray& r, glm::ivec3 b, int radius) {
    return boxExit(f, r, b - radius, b + radius);
}

// Where the ray leaves the empty bricks around brick b (distance d > 0): the cube of bricks
// within d - 1, or, when it reaches further, the column of empty bricks from b along the ray's
// main axis (BrickGrid::run): beside a wall that runs along the ray the cube is one brick, the
// column many.
inline float emptyExit(const Frame& f, const Ray& r, glm::ivec3 b, size_t bi, int d) {
    float tExit = boxExit(f, r, b, d - 1);
    const int a = r.mainAxis;
    const bool positive = r.dv[a] > 0.0f;
    const int run = f.runs[2 * a + positive][bi];
    if (run > d) {
        glm::ivec3 lo = b, hi = b;
        (positive ? hi : lo)[a] += positive ? run - 1 : 1 - run;
        tExit = std::max(tExit, boxExit(f, r, lo, hi));
    }
    return tExit;
}

struct March {
    bool hit = false;
    float t = 0.0f;   // refined hit distance, mm (set by refineHit)
    float tIn = 0.0f; // first sample inside
    // Index of the first sample inside (tIn = kIn * dt), or HitCache::kNever when no sample of the
    // ray is inside.
    int32_t kIn = HitCache::kNever;
    float value = 0.0f;  // the density at the first sample inside
    bool refine = false; // a sample before it lies in the ray's sampled span (kIn > kStart)
    // The last sample below the iso-value whose density the march computed (by the same arithmetic
    // as sampleDensity, so reusing it for the refinement changes no bit), INT_MIN if none.
    int lastK = INT_MIN;
    float lastValue = 0.0f;
};

// Eight lanes' brick cell masks (brick index `bi`) read by two gathers of four 64-bit masks
// (half the loads of 32-bit halves), as bits: `nonEmpty`, the brick may hold surface; `setBits`,
// the lane's cell (bit 0..63 of its brick's mask) is set.
__attribute__((target("avx2,bmi2"), always_inline)) inline void
cellBits(const Frame& f, v8si bi, v8su bit, unsigned& nonEmpty, unsigned& setBits) {
    const long long* const masks = reinterpret_cast<const long long*>(f.cells);
    nonEmpty = setBits = 0;
    for (int h = 0; h < 2; ++h) {
        const __m128i idx =
            h ? _mm256_extracti128_si256((__m256i)bi, 1) : _mm256_castsi256_si128((__m256i)bi);
        const __m128i at =
            h ? _mm256_extracti128_si256((__m256i)bit, 1) : _mm256_castsi256_si128((__m256i)bit);
        const __m256i mask = _mm256_i32gather_epi64(masks, idx, 8);
        const __m256i empty = _mm256_cmpeq_epi64(mask, _mm256_setzero_si256());
        const __m256i cell =
            _mm256_slli_epi64(_mm256_srlv_epi64(mask, _mm256_cvtepu32_epi64(at)), 63);
        nonEmpty |= unsigned(~_mm256_movemask_pd((__m256d)empty) & 15) << (4 * h);
        setBits |= unsigned(_mm256_movemask_pd((__m256d)cell)) << (4 * h);
    }
}

// The trilinear density at eight positions (p) in cells (i) inside the volume, lanes of `lanes`
// (others read voxel 0): each cell's four voxel rows by gathers, then sample8's arithmetic
// (trilinearCorners' operations lane by lane).
__attribute__((target("avx2,bmi2"), always_inline)) inline v8sf
trilinearGathered(const Frame& f, v8sf px, v8sf py, v8sf pz, v8si ix, v8si iy, v8si iz,
                  v8si lanes) {
    const int* const voxels = reinterpret_cast<const int*>(f.density);
    const v8si base = lanes ? ix + int(f.sy) * iy + int(f.sz) * iz : v8si{};
    const v8su r0 = (v8su)_mm256_i32gather_epi32(voxels, (__m256i)base, 1);
    const v8su r1 = (v8su)_mm256_i32gather_epi32(voxels, (__m256i)(base + int(f.sy)), 1);
    const v8su r2 = (v8su)_mm256_i32gather_epi32(voxels, (__m256i)(base + int(f.sz)), 1);
    const v8su r3 = (v8su)_mm256_i32gather_epi32(voxels, (__m256i)(base + int(f.sz + f.sy)), 1);
    auto lo = [](v8su w) { return __builtin_convertvector(v8si(w & 255u), v8sf); };
    auto hi = [](v8su w) { return __builtin_convertvector(v8si((w >> 8) & 255u), v8sf); };
    const v8sf tx = px - __builtin_convertvector(ix, v8sf),
               ty = py - __builtin_convertvector(iy, v8sf),
               tz = pz - __builtin_convertvector(iz, v8sf);
    const v8sf ux = 1.0f - tx, uy = 1.0f - ty, uz = 1.0f - tz;
    const v8sf c00 = ux * lo(r0) + tx * hi(r0), c10 = ux * lo(r1) + tx * hi(r1);
    const v8sf c01 = ux * lo(r2) + tx * hi(r2), c11 = ux * lo(r3) + tx * hi(r3);
    const v8sf c0 = uy * c00 + ty * c10, c1 = uy * c01 + ty * c11;
    return uz * c0 + tz * c1;
}

// The AVX2 build's march step: samples k .. k + 7 at once, as far as they stay in bricks that
// may hold surface, in cells inside the volume, and at most kEnd. Lane by lane the scalar loop's
// arithmetic (positions, floors, the cell test, the trilinear sample of insideSample), with the
// grid and the volume read by gathers. Returns how many samples it took (0: the scalar step takes
// sample k, and leaps if its brick is empty); on a hit, `found`, the hit's offset from k and its
// value. Updates lastK and lastValue as the scalar loop does.
__attribute__((target("avx2,bmi2"))) inline int marchEight(const Frame& f, const Ray& r, int k,
                                                           int kEnd, bool& found, float& value,
                                                           int& lastK, float& lastValue) {
    const v8si kv = k + v8si{0, 1, 2, 3, 4, 5, 6, 7};
    const v8sf t = __builtin_convertvector(kv, v8sf) * f.dt;
    const v8sf px = f.origin.x + t * r.dv.x, py = f.origin.y + t * r.dv.y,
               pz = f.origin.z + t * r.dv.z;
    const v8si ix = __builtin_convertvector(px + 16.0f, v8si) - 16;
    const v8si iy = __builtin_convertvector(py + 16.0f, v8si) - 16;
    const v8si iz = __builtin_convertvector(pz + 16.0f, v8si) - 16;
    // In the volume with three voxels to spare along x (a 4-byte gather of a cell's row then
    // stays inside the volume's data), and not past the ray's last sample.
    const v8si inVolume = ((v8su)ix < unsigned(f.n.x - 3)) & ((v8su)iy < unsigned(f.n.y - 1)) &
                          ((v8su)iz < unsigned(f.n.z - 1)) & (kv <= kEnd);
    // Each lane's brick and its cell mask (lanes outside read brick 0).
    constexpr int S = BrickGrid::kShift;
    const v8si bi = inVolume ? (ix >> S) + f.nb.x * (iy >> S) + int(f.nbxy) * (iz >> S) : v8si{};
    static_assert(BrickGrid::kSize == 4, "a brick's cell mask is 64 bits, x + 4 y + 16 z");
    const v8su bit = (v8su)((ix & 3) + 4 * (iy & 3) + 16 * (iz & 3));
    unsigned nonEmpty, setBits;
    cellBits(f, bi, bit, nonEmpty, setBits);
    // An empty brick's mask is zero: the scalar step leaps from there.
    const unsigned okMask = unsigned(_mm256_movemask_ps((__m256)inVolume)) & nonEmpty;
    const int n = __builtin_ctz(~okMask); // the leading lanes that qualify
    if (n == 0)
        return 0;
    const unsigned lanes = (1u << n) - 1u;
    const unsigned setMask = setBits & lanes;
    if (setMask == 0)
        return n; // all clear: below the iso-value without reading the volume
    // The trilinear samples (sample8's arithmetic, trilinearCorners' operations lane by lane);
    // lanes that do not qualify read voxel 0.
    const v8si ok = (v8si{1, 2, 4, 8, 16, 32, 64, 128} & int(okMask)) != 0;
    const v8sf v = trilinearGathered(f, px, py, pz, ix, iy, iz, ok);
    const unsigned inside =
        unsigned(_mm256_movemask_ps((__m256)(v >= float(kSurfaceDensity)))) & setMask;
    const unsigned below = inside ? setMask & ((1u << __builtin_ctz(inside)) - 1u) : setMask;
    if (below) {
        const int l = 31 - __builtin_clz(below);
        lastK = k + l, lastValue = v[l];
    }
    if (!inside)
        return n;
    const int h = __builtin_ctz(inside);
    found = true;
    value = v[h];
    return h;
}

// Samples sit at t = k * dt from the eye for integer k, whatever is skipped. A brick at Chebyshev
// distance d > 0 from surface lets the ray jump out of the (2d - 1)^3 bricks around it; those
// samples are all below the iso-value, so the first sample inside is the same with or without
// skipping. Inside a brick that may hold surface every sample is taken, but a sample in a clear
// cell (BrickGrid::cellMask) needs no volume read.
//
// Why rounding cannot break this: in an empty brick every trilinear corner is at most 127, so the
// field is <= 127 there; it changes by at most 255 per voxel along each axis, so a sample that
// float rounding (under 2.5e-4 voxel with the eye within kMaxSkipEyeVoxels) put just outside the
// brick, or a box exit rounded a little late, reads at most 127 + 765 * 2.5e-4 < 128.
//
// `kResume` is a lower bound on the index of the first sample inside (a hit cache's entry; 0 when
// unknown, kNever when no sample can be inside): marching starts there, which changes nothing but
// the time taken.
// `resumeInside`: the hit cache saw sample kResume inside last time, and after the first sample of
// the ray's span (HitCache::m_inside). Then, unless the cone proved more, the march starts there,
// and if that sample is still inside (erosion left it) it is the first inside sample: the span
// (slabs, divisions) is not needed. insideSample decides exactly as the march's brick and cell
// tests would.
// `Wide`: the AVX2 build, which takes up to eight samples a step (marchEight).
// Where a ray's march starts: its span's first and last sample and the first sample not yet
// proved below the iso-value (marchSpan), or no march at all.
struct Span {
    int kStart = 0, kEnd = -1, k = 0;
};

// The set-up of marchToSurface: false when it is decided without marching (`m` says how: no
// hit, or the cache's still-inside sample); else `s` is where to march.
bool marchSpan(const Frame& f, const Ray& r, float tSkipTo, int32_t kResume, bool resumeInside,
               March& m, Span& s) {
    if (tSkipTo == INFINITY) // a cone proved the whole ray empty
        return false;
    if (resumeInside && tSkipTo * (1.0f / f.dt) < float(kResume)) {
        const v4sf p = samplePos4(f, r, float(kResume) * f.dt);
        float value;
        if (insideSample(f, p, floorInt4(p), value)) {
            m.hit = true;
            m.kIn = kResume;
            m.tIn = float(kResume) * f.dt;
            m.t = m.tIn;
            m.value = value;
            m.refine = true;
            return false;
        }
    }
    // Samples live where some trilinear corner is inside the volume: voxel coordinates [-1, n].
    float t0 = float(std::max(r.tNear, 0.0)), t1 = float(r.tFar);
    if (r.dv.x != 0.0f && r.dv.y != 0.0f && r.dv.z != 0.0f) {
        // The three slabs at once: minps(b, a) is b < a ? b : a, std::min(a, b) exactly, and
        // maxps(b, a) std::max(a, b); lane 3 gives (-inf, inf), which changes nothing.
        const v4sf ta = (f.regionLo - f.origin4) * r.invDv4,
                   tb = (f.regionHi - f.origin4) * r.invDv4;
        const v4sf lo = (v4sf)_mm_min_ps((__m128)tb, (__m128)ta);
        const v4sf hi = (v4sf)_mm_max_ps((__m128)tb, (__m128)ta);
        t0 = std::max(std::max(std::max(t0, lo[0]), lo[1]), lo[2]);
        t1 = std::min(std::min(std::min(t1, hi[0]), hi[1]), hi[2]);
    } else {
        for (int a = 0; a < 3; ++a) {
            float o = f.origin[a];
            if (r.dv[a] == 0.0f) {
                if (o < -1.0f || o > float(f.n[a]))
                    return false;
                continue;
            }
            float ta = (-1.0f - o) * r.invDv[a], tb = (float(f.n[a]) - o) * r.invDv[a];
            t0 = std::max(t0, std::min(ta, tb));
            t1 = std::min(t1, std::max(ta, tb));
        }
    }
    // Beyond the volume anyway; but float rounding of a far eye's slabs must not take t1, and
    // with it kEnd, past int (tLimit / dt is 2^30).
    t1 = std::min(t1, f.tLimit);
    if (!(t0 <= t1))
        return false;
    const float dt = f.dt;
    const float invDt = 1.0f / dt;
    const int kStart = int(std::ceil(t0 / dt));
    const int kEnd = int(std::floor(t1 / dt));

    // The tile pass proved that no sample before tSkipTo can be inside; the cache, none before
    // kResume.
    if (!(tSkipTo <= t1) || kResume > kEnd)
        return false;
    int k = tSkipTo > t0 ? std::max(kStart, int(tSkipTo * invDt)) : kStart;
    k = std::max(k, int(kResume));
    s = Span{kStart, kEnd, k};
    return true;
}

// The march proper from sample s.k: fixed sample indices, brick leaps, clear cells, the first
// sample inside. `lastK`, `lastValue`: the last computed sample below the iso-value before s.k.
template <bool Wide = false>
March marchFrom(const Frame& f, const Ray& r, const Span& s, int lastK = INT_MIN,
                float lastValue = 0.0f) {
    March m;
    const float dt = f.dt;
    const float invDt = 1.0f / dt;
    const int kStart = s.kStart, kEnd = s.kEnd;
    int k = s.k;
    float value = 0.0f;
    bool found = false;
    constexpr int S = BrickGrid::kShift;
    while (k <= kEnd && !found) {
        uint64_t cells = ~uint64_t(0);
        glm::ivec3 cellBase(0);
        if (f.distance) {
            const v4si i = floorInt4(samplePos4(f, r, float(k) * dt));
            glm::ivec3 b(std::clamp(i[0], 0, f.n.x - 1) >> S, std::clamp(i[1], 0, f.n.y - 1) >> S,
                         std::clamp(i[2], 0, f.n.z - 1) >> S);
            size_t bi = size_t(b.x) + size_t(f.nb.x) * size_t(b.y) + f.nbxy * size_t(b.z);
            int d = f.distance[bi];
            if (d > 0) {
                // Last sample before the exit of the empty cube (one a rounding error beyond it
                // is still below the iso-value, see above).
                float kLast = emptyExit(f, r, b, bi, d) * invDt;
                if (!(kLast < float(kEnd)))
                    return m;
                k = std::max(k + 1, floorInt(kLast) + 1);
                continue;
            }
            cells = f.cells[bi];
            cellBase = b << S;
        }
        for (; k <= kEnd; ++k) {
            if constexpr (Wide) {
                if (f.marchEight) {
                    const int taken = marchEight(f, r, k, kEnd, found, value, lastK, lastValue);
                    if (found) {
                        k += taken;
                        break;
                    }
                    if (taken > 0) {
                        k += taken - 1; // and the loop's ++k
                        continue;
                    }
                }
            }
            const v4sf p = samplePos4(f, r, float(k) * dt);
            const v4si i = floorInt4(p);
            const int fx = i[0], fy = i[1], fz = i[2];
            int cx = fx - cellBase.x, cy = fy - cellBase.y, cz = fz - cellBase.z;
            if (unsigned(cx | cy | cz) >= unsigned(BrickGrid::kSize) && f.distance) {
                // The sample is in another brick: go on with that brick's cells if it may hold
                // surface, or leave it to the leap above if it is empty.
                glm::ivec3 b(std::clamp(fx, 0, f.n.x - 1) >> S, std::clamp(fy, 0, f.n.y - 1) >> S,
                             std::clamp(fz, 0, f.n.z - 1) >> S);
                size_t bi = size_t(b.x) + size_t(f.nb.x) * size_t(b.y) + f.nbxy * size_t(b.z);
                if (f.distance[bi] > 0)
                    break;
                cells = f.cells[bi];
                cellBase = b << S;
                cx = fx - cellBase.x, cy = fy - cellBase.y, cz = fz - cellBase.z;
            }
            // A clear cell of this brick: below the iso-value without touching the volume. A
            // sample outside the grid's bricks takes the full test.
            if (unsigned(cx | cy | cz) < unsigned(BrickGrid::kSize) &&
                !((cells >> (cx + 4 * cy + 16 * cz)) & 1u))
                continue;
            if (insideSample(f, p, i, value)) {
                found = true;
                break;
            }
            if (value >= 0.0f)
                lastK = k, lastValue = value;
        }
    }
    if (!found)
        return m;

    m.hit = true;
    m.kIn = k;
    m.tIn = float(k) * dt;
    m.t = m.tIn;
    m.value = value;
    m.refine = k > kStart;
    m.lastK = lastK;
    m.lastValue = lastValue;
    return m;
}

template <bool Wide = false>
March marchToSurface(const Frame& f, const Ray& r, float tSkipTo, int32_t kResume,
                     bool resumeInside = false) {
    March m;
    Span s;
    if (!marchSpan(f, r, tSkipTo, kResume, resumeInside, m, s))
        return m;
    return marchFrom<Wide>(f, r, s);
}

// Steps of a packet before the lanes still marching go on alone (a ray grazing the surface).
constexpr int kPacketMaxSteps = 24;

// Eight rays of a pixel row marched in lockstep, one sample per ray a step (AVX2 build). A ray
// marched alone is a chain of dependent loads and branches that mispredict where its surface
// comes; eight side by side need few more steps than one and share them. Each lane is the
// scalar loop's arithmetic and tests (marchEight's, lane by lane), so it finds the same first
// inside sample. A lane leaves the packet where the scalar march would do more than test a cell:
// a sample in an empty brick (a leap), outside the volume's cells or within 3 voxels of the high
// x face, or past its last sample; `k` then says where marchFrom goes on; a lane that finds its
// first inside sample stops at it, its density in `value`.
struct Packet {
    v8sf dvx, dvy, dvz;
    v8si k, kEnd;
    v8si lastK;
    v8sf lastValue, value;
};

// One step of a packet: each live lane takes its sample k (lanes that leave keep it, lanes that
// find their first inside sample are added to `hitLanes`), then moves on one sample.
__attribute__((target("avx2,bmi2"), always_inline)) inline void
stepPacket(const Frame& f, Packet& pk, v8si& k, unsigned& live, unsigned& hitLanes) {
    constexpr int S = BrickGrid::kShift;
    const v8sf t = __builtin_convertvector(k, v8sf) * f.dt;
    const v8sf px = f.origin.x + t * pk.dvx, py = f.origin.y + t * pk.dvy,
               pz = f.origin.z + t * pk.dvz;
    const v8si ix = __builtin_convertvector(px + 16.0f, v8si) - 16;
    const v8si iy = __builtin_convertvector(py + 16.0f, v8si) - 16;
    const v8si iz = __builtin_convertvector(pz + 16.0f, v8si) - 16;
    const v8si inVolume = ((v8su)ix < unsigned(f.n.x - 3)) & ((v8su)iy < unsigned(f.n.y - 1)) &
                          ((v8su)iz < unsigned(f.n.z - 1)) & (k <= pk.kEnd);
    const v8si bi = inVolume ? (ix >> S) + f.nb.x * (iy >> S) + int(f.nbxy) * (iz >> S) : v8si{};
    const v8su bit = (v8su)((ix & 3) + 4 * (iy & 3) + 16 * (iz & 3));
    unsigned nonEmpty, setBits;
    cellBits(f, bi, bit, nonEmpty, setBits);
    // Lanes that leave: the scalar march takes their sample k.
    live &= unsigned(_mm256_movemask_ps((__m256)inVolume)) & nonEmpty;
    const unsigned setMask = setBits & live;
    if (setMask != 0) {
        const v8si laneSet = (v8si{1, 2, 4, 8, 16, 32, 64, 128} & int(setMask)) != 0;
        const v8sf v = trilinearGathered(f, px, py, pz, ix, iy, iz, laneSet);
        const v8si in = v >= float(kSurfaceDensity);
        const unsigned inside = unsigned(_mm256_movemask_ps((__m256)in)) & setMask;
        // Computed and below: the last sample outside so far.
        const v8si below = laneSet & ~in;
        pk.lastK = below ? k : pk.lastK;
        pk.lastValue = below ? v : pk.lastValue;
        pk.value = (laneSet & in) ? v : pk.value;
        hitLanes |= inside;
        live &= ~inside;
    }
    // Every lane still marching moves on one sample; the others keep their k.
    const v8si liveMask = v8si{1, 2, 4, 8, 16, 32, 64, 128} & int(live);
    k = liveMask != 0 ? k + 1 : k;
}

// Marches `count` packets (up to kPackets) whose lanes of live[i] march; returns each one's
// lanes that found their first inside sample, in hits[i]. Packets step side by side: a step is a
// chain of dependent gathers, and the other packets' chains fill the wait.
constexpr int kPackets = 4;
__attribute__((target("avx2,bmi2"))) inline void
marchPackets(const Frame& f, Packet* pk, unsigned* live, unsigned* hits, int count) {
    v8si k[kPackets];
    unsigned l[kPackets];
    for (int i = 0; i < kPackets; ++i) {
        k[i] = i < count ? pk[i].k : v8si{};
        l[i] = i < count ? live[i] : 0u;
        hits[i] = 0;
    }
    for (int step = 0; step < kPacketMaxSteps; ++step) {
        unsigned any = 0;
        for (int i = 0; i < kPackets; ++i)
            if (l[i]) {
                stepPacket(f, pk[i], k[i], l[i], hits[i]);
                any |= l[i];
            }
        if (!any)
            break;
    }
    for (int i = 0; i < count; ++i)
        pk[i].k = k[i];
}

// Refines a hit between the last sample outside and the first inside: a secant (regula falsi)
// step, one sample there to narrow the bracket, and a final secant. The outside sample is
// recomputed unless the march just computed it, so skipping it changes nothing. (Bisection costs
// three more samples and as many mispredicted branches, for accuracy the depth test does not
// need.) refineAndDifferentiate8 does the same for eight hits at once, lane by lane the same
// operations.
void refineHit(const Frame& f, const Ray& r, March& m) {
    if (!m.refine)
        return;
    const float iso = float(kSurfaceDensity);
    const int k = m.kIn;
    float ta = float(k - 1) * f.dt, tb = m.tIn;
    float fa = (m.lastK == k - 1 ? m.lastValue : sampleDensity(f, samplePos4(f, r, ta))) - iso;
    if (!(fa < 0.0f))
        return; // no bracket: a hit cache used against its contract (refineAndDifferentiate8)
    float fb = m.value - iso;
    for (int i = 0; i < kRefineSteps; ++i) {
        float tm = ta + (tb - ta) * (fa / (fa - fb));
        float fm = sampleDensity(f, samplePos4(f, r, tm)) - iso;
        bool in = fm >= 0.0f;
        ta = in ? ta : tm, fa = in ? fa : fm;
        tb = in ? tm : tb, fb = in ? fm : fb;
    }
    m.t = ta + (tb - ta) * (fa / (fa - fb));
}

March march(const Frame& f, const Ray& r, float tSkipTo, int32_t kResume) {
    March m = marchToSurface(f, r, tSkipTo, kResume);
    if (m.hit)
        refineHit(f, r, m);
    return m;
}

// [SECTION] Tile pass ----------------------------------------------------------------------------

// The bits c * step for the cells c of [lo, hi] clipped to a brick's [0, kSize): summed over
// three axes' spans (steps 1, 4, 16) by multiplying, the cells of a box in a brick's cell mask.
inline uint64_t cellSpan(int lo, int hi, int step) {
    static_assert(BrickGrid::kSize == 4, "four cells an axis: bits 0, step, 2 step, 3 step");
    lo = std::max(lo, 0);
    hi = std::min(hi, BrickGrid::kSize - 1);
    if (lo > hi)
        return 0;
    const uint64_t all =
        1u | uint64_t(1) << step | uint64_t(1) << (2 * step) | uint64_t(1) << (3 * step);
    return all & ((uint64_t(2) << (hi * step)) - 1) & ~((uint64_t(1) << (lo * step)) - 1);
}

// Pixels per edge of the blocks that share one cone march.
constexpr int kConeBlock = 8;
// The widest box of bricks (per axis) a cone's cross-section may overlap for the cone march to go
// on.
constexpr int kConeMaxBricks = 4;
// Leaps per cone march (through bricks far out, through clear cells near the surface).
constexpr int kConeMaxSteps = 128;

// A lower bound on t before which every sample of every ray of the pixel block [x0, x1) x
// [y0, y1) lies in an empty brick or a clear trilinear cell (+inf: all of them do). Every ray of
// the block lies within a cone around the block's central ray; at distance t its points are within
// t * tan(angle) of the central point. The central ray leaps through boxes proved empty (by brick
// distances far out, by cell masks near the surface) with that radius taken off every box, so
// whatever the cone sweeps is below the iso-value. Skipping those samples is exact, like any
// brick skip: results never depend on the block a pixel was rendered in.
//
// `tStart`: the march starts there instead of at the eye (samples before it are the caller's
// business: a hit cache proves them below the iso-value ray by ray), and the result is at least
// tStart unless the cone never meets surface.
//
// `fromCone`: tStart is where a wider cone around this block stopped, near surface by design, so
// the cheap test below (made for cache resumes) would stop this narrower one at once.
float coneSkipTo(const Frame& f, int x0, int y0, int x1, int y1, float tStart,
                 bool fromCone = false) {
    const Ray c = windowRay(f, 0.5 * (x0 + x1), 0.5 * (y0 + y1));
    if (tStart > 0.0f && !fromCone) {
        // Resuming from a cache: where the block's rays last met bone and the central point's
        // brick may still hold surface (an ordinary stroke), the cone would stop at once.
        glm::vec3 p = samplePos(f, c, tStart);
        glm::ivec3 b(brickCoord(p.x, f.n.x), brickCoord(p.y, f.n.y), brickCoord(p.z, f.n.z));
        if (f.distance[size_t(b.x) + size_t(f.nb.x) * size_t(b.y) + f.nbxy * size_t(b.z)] == 0)
            return tStart;
    }
    // The angle between the central ray and any pixel's ray of the block: two points of the
    // image plane, at least focalPx from the eye, a distance h apart, subtend sin A <= h /
    // focalPx (law of sines), whatever the block's place in the window.
    const double hx = 0.5 * (x1 - x0) - 0.5, hy = 0.5 * (y1 - y0) - 0.5;
    const double sinA = std::sqrt(hx * hx + hy * hy) / f.focalPx;
    if (!(sinA < 0.8)) // a block wider than ~53 degrees: nothing worth proving
        return 0.0f;
    const double tanA = sinA / std::sqrt(1.0 - sinA * sinA);
    // Cone radius in voxels at distance t: grow * t + 0.05, whose 1 % and 0.05 voxel of slack
    // cover float's rounding; at most its value at the farthest sample.
    const float grow = float(tanA / f.minSpacing) * 1.01f;
    const float radius = float(tanA * f.maxSampleT / f.minSpacing) * 1.01f + 0.05f;

    // Where the central ray is within `radius` of the sampled region [-1, n] (near and far
    // planes differ between the block's rays, so they play no part here).
    float t0 = 0.0f, t1 = INFINITY;
    for (int a = 0; a < 3; ++a) {
        float o = f.origin[a], lo = -1.0f - radius, hi = float(f.n[a]) + radius;
        if (c.dv[a] == 0.0f) {
            if (o < lo || o > hi)
                return INFINITY;
            continue;
        }
        float ta = (lo - o) * c.invDv[a], tb = (hi - o) * c.invDv[a];
        t0 = std::max(t0, std::min(ta, tb));
        t1 = std::min(t1, std::max(ta, tb));
    }
    if (!(t0 <= t1))
        return INFINITY;
    float t = std::max(t0, tStart);
    if (!(t <= t1))
        return tStart;
    const int nbx = f.nb.x;
    constexpr int S = BrickGrid::kShift;
    for (int step = 0; step < kConeMaxSteps; ++step) {
        glm::vec3 p = samplePos(f, c, t);
        // The cross-section's radius here: the box tested only has to reach it for the march to
        // go on (the leap below shrinks the box by the radius where the ray leaves it).
        const float rt = std::min(radius, grow * t + 0.05f);
        // The bricks that the cone's cross-section around p can touch, reaching half a voxel
        // further so that the march always moves on, and the smallest distance among them.
        glm::ivec3 lo, hi;
        for (int a = 0; a < 3; ++a) {
            lo[a] = brickCoord(p[a] - radius - 0.5f, f.n[a]);
            hi[a] = brickCoord(p[a] + radius + 0.5f, f.n[a]);
            if (hi[a] - lo[a] >= kConeMaxBricks)
                return t; // a cone this wide gains nothing here
        }
        int d = BrickGrid::kMaxDistance;
        for (int z = lo.z; z <= hi.z; ++z)
            for (int y = lo.y; y <= hi.y; ++y) {
                const uint8_t* row = f.distance + size_t(nbx) * size_t(y) + f.nbxy * size_t(z);
                for (int x = lo.x; x <= hi.x; ++x)
                    d = std::min(d, int(row[x]));
            }
        // An empty box around p, in voxel coordinates (infinite faces: open at the grid's edge).
        glm::vec3 boxLo, boxHi;
        if (d > 0) {
            // Every brick within d - 1 of the box of bricks [lo, hi] is within d - 1 of one of
            // them, so empty.
            lo -= d - 1;
            hi += d - 1;
            for (int a = 0; a < 3; ++a) {
                boxLo[a] = lo[a] <= 0 ? -INFINITY : float(lo[a] << S);
                boxHi[a] = hi[a] >= f.nb[a] - 1 ? INFINITY : float((hi[a] + 1) << S);
            }
        } else {
            // Near surface: the trilinear cells the cross-section can touch must all be clear
            // (no corner at the iso-value, BrickGrid::cellMask); samples there are below it.
            glm::ivec3 clo, chi;
            for (int a = 0; a < 3; ++a) {
                clo[a] = floorInt(p[a] - rt - 0.5f);
                chi[a] = floorInt(p[a] + rt + 0.5f);
                if (clo[a] < 0 || chi[a] >= (f.nb[a] << S) || chi[a] - clo[a] >= 8)
                    return t;
            }
            // Brick by brick: the cells of the box that lie in the brick as one 64-bit mask
            // (bit cx + 4 cy + 16 cz), against the brick's cell mask.
            for (int bz = clo.z >> S; bz <= chi.z >> S; ++bz) {
                const uint64_t zs = cellSpan(clo.z - (bz << S), chi.z - (bz << S), 16);
                for (int by = clo.y >> S; by <= chi.y >> S; ++by) {
                    const uint64_t ys = cellSpan(clo.y - (by << S), chi.y - (by << S), 4);
                    const size_t row = size_t(nbx) * size_t(by) + f.nbxy * size_t(bz);
                    for (int bx = clo.x >> S; bx <= chi.x >> S; ++bx) {
                        const uint64_t xs = cellSpan(clo.x - (bx << S), chi.x - (bx << S), 1);
                        if (f.cells[row + size_t(bx)] & (xs * ys * zs))
                            return t;
                    }
                }
            }
            boxLo = glm::vec3(clo);
            boxHi = glm::vec3(chi + 1);
        }
        // The cone's radius grows with t: over the part of the central ray inside the box it is
        // at most its radius where the ray leaves the box.
        float tBox = INFINITY;
        for (int a = 0; a < 3; ++a) {
            if (c.dv[a] > 0.0f && boxHi[a] < INFINITY)
                tBox = std::min(tBox, (boxHi[a] - f.origin[a]) * c.invDv[a]);
            else if (c.dv[a] < 0.0f && boxLo[a] > -INFINITY)
                tBox = std::min(tBox, (boxLo[a] - f.origin[a]) * c.invDv[a]);
        }
        float r = tBox < INFINITY ? std::min(radius, grow * tBox + 0.05f) : radius;
        // The box shrunk by the radius; the central point must be inside it for the cone to be.
        float tNext = INFINITY;
        for (int a = 0; a < 3; ++a) {
            float l = boxLo[a] + r, h = boxHi[a] - r;
            if (!(p[a] >= l && p[a] <= h))
                return t;
            if (c.dv[a] > 0.0f && h < INFINITY)
                tNext = std::min(tNext, (h - f.origin[a]) * c.invDv[a]);
            else if (c.dv[a] < 0.0f && l > -INFINITY)
                tNext = std::min(tNext, (l - f.origin[a]) * c.invDv[a]);
        }
        if (!(tNext < t1))
            return INFINITY; // the cone stays in empty space until it leaves the volume
        if (!(tNext > t))
            return t;
        t = tNext;
    }
    return t;
}

// [SECTION] Shading and depth ------------------------------------------------------------------

// pHit: the hit in voxel coordinates, pIn: the first sample inside.
Material hitMaterial(const Frame& f, v4sf pHit, v4sf pIn) {
    auto label = [&](int x, int y, int z) { return Material(f.material[x + f.sy * y + f.sz * z]); };
    const v4si vi = floorInt4(pHit + 0.5f);
    glm::ivec3 v(vi[0], vi[1], vi[2]);
    v = glm::clamp(v, glm::ivec3(0), f.n - 1);
    Material m = label(v.x, v.y, v.z);
    if (m != Material::Air)
        return m;
    // The nearest voxel is air (the surface passes between voxels): take the labelled corner of
    // the first sample inside that lies nearest the hit, the denser on a tie: the layer the
    // surface passes through, not a denser one beyond it (a hole's diploe floor over the inner
    // table).
    const v4si ci = floorInt4(pIn);
    glm::ivec3 c(ci[0], ci[1], ci[2]);
    float bestD2 = INFINITY;
    int best = -1;
    for (int i = 0; i < 8; ++i) {
        glm::ivec3 q = c + glm::ivec3(i & 1, (i >> 1) & 1, (i >> 2) & 1);
        if (q.x < 0 || q.y < 0 || q.z < 0 || q.x >= f.n.x || q.y >= f.n.y || q.z >= f.n.z ||
            label(q.x, q.y, q.z) == Material::Air)
            continue;
        const float dx = float(q.x) - pHit[0], dy = float(q.y) - pHit[1], dz = float(q.z) - pHit[2];
        const float d2 = dx * dx + dy * dy + dz * dz;
        const int d = f.density[q.x + f.sy * q.y + f.sz * q.z];
        if (d2 < bestD2 || (d2 == bestD2 && d > best))
            bestD2 = d2, best = d, m = label(q.x, q.y, q.z);
    }
    return m == Material::Air ? Material::Cortical : m;
}

// What the render loop needs of a hit; castRay dresses it up as a RayHit.
struct Hit {
    float t;     // refined hit distance, mm
    v4sf normal; // unit, pointing out of the bone (lane 3 padding)
    Material material;
};

// `resume`: in, a lower bound on the first inside sample's index (see march); out, that index.
// False when the ray meets no bone.
// The unit normal from a gradient in density per voxel: lane by lane the vec3 arithmetic (glm's
// length and division), bit for bit. Pointing out of the bone; the ray's reverse where flat.
inline v4sf hitNormal(const Frame& f, const Ray& r, v4sf gradVoxel) {
    const v4sf grad = gradVoxel * f.invSpacing4; // density per mm
    const float len = std::sqrt(grad[0] * grad[0] + grad[1] * grad[1] + grad[2] * grad[2]);
    return len > 0.0f ? -grad / len : -r.dir4;
}

// Normal and material of a refined hit.
inline void finishHit(const Frame& f, const Ray& r, const March& m, Hit& h) {
    h.t = m.t;
    const v4sf p = samplePos4(f, r, m.t);
    h.normal = hitNormal(f, r, gradientAt(f, p, floorInt4(p)));
    h.material = hitMaterial(f, p, samplePos4(f, r, m.tIn));
}

bool traceRay(const Frame& f, const Ray& r, float tSkipTo, int32_t& resume, Hit& h) {
    March m = march(f, r, tSkipTo, resume);
    resume = m.kIn;
    if (!m.hit)
        return false;
    finishHit(f, r, m, h);
    return true;
}

// [SECTION] Hits eight at a time ------------------------------------------------------------------
//
// After the march, what is left of a hit (the refinement's two samples, the 32-voxel gradient) is
// the same arithmetic for every ray, so the render loop marches a block's rays (one by one, or in
// packets in the AVX2 build) and then refines and differentiates their hits eight at a time, one
// ray per lane of GCC's 8-wide vectors (two SSE2 registers on baseline x86-64). Lane by lane these
// are the scalar functions' IEEE operations in the scalar order (no FMA on baseline x86-64), so the
// pixels are bit for bit those of refineHit + finishHit, which castRay and RenderOptions::batchHits
// = false still use. Hits whose samples or shading stencil reach the volume's faces (the border
// paths) take the scalar functions.

struct PendingHit {
    Ray r;
    March m;
    int ox, oy; // output pixel
};

// Eight samples whose cells lie inside the volume: trilinearCorners lane by lane.
// floorInt4 and the fractions of eight positions, lane by lane.
struct Cells8 {
    v8si ix, iy, iz;
    v8sf tx, ty, tz;
};

inline Cells8 cells8(v8sf px, v8sf py, v8sf pz) {
    Cells8 c;
    c.ix = __builtin_convertvector(px + 16.0f, v8si) - 16;
    c.iy = __builtin_convertvector(py + 16.0f, v8si) - 16;
    c.iz = __builtin_convertvector(pz + 16.0f, v8si) - 16;
    c.tx = px - __builtin_convertvector(c.ix, v8sf);
    c.ty = py - __builtin_convertvector(c.iy, v8sf);
    c.tz = pz - __builtin_convertvector(c.iz, v8sf);
    return c;
}

inline v8sf sample8(const Frame& f, v8sf px, v8sf py, v8sf pz) {
    const auto [ix, iy, iz, tx, ty, tz] = cells8(px, py, pz);
    v8su r0, r1, r2, r3; // rows (y, z) = (0, 0), (1, 0), (0, 1), (1, 1): x = 0 low, x = 1 high
    for (int l = 0; l < 8; ++l) {
        const uint8_t* b = f.density + ix[l] + f.sy * iy[l] + f.sz * iz[l];
        uint16_t a0, a1, a2, a3;
        std::memcpy(&a0, b, 2);
        std::memcpy(&a1, b + f.sy, 2);
        std::memcpy(&a2, b + f.sz, 2);
        std::memcpy(&a3, b + f.sz + f.sy, 2);
        r0[l] = a0, r1[l] = a1, r2[l] = a2, r3[l] = a3;
    }
    auto lo = [](v8su r) { return __builtin_convertvector(v8si(r & 255u), v8sf); };
    auto hi = [](v8su r) { return __builtin_convertvector(v8si(r >> 8), v8sf); };
    const v8sf ux = 1.0f - tx, uy = 1.0f - ty, uz = 1.0f - tz;
    const v8sf c00 = ux * lo(r0) + tx * hi(r0), c10 = ux * lo(r1) + tx * hi(r1);
    const v8sf c01 = ux * lo(r2) + tx * hi(r2), c11 = ux * lo(r3) + tx * hi(r3);
    const v8sf c0 = uy * c00 + ty * c10, c1 = uy * c01 + ty * c11;
    return uz * c0 + tz * c1;
}

// gradientAt of eight positions whose stencil lies inside the volume, lane by lane; writes the
// gradient (per voxel) of lane l to g[l].
inline void gradient8(const Frame& f, v8sf px, v8sf py, v8sf pz, v4sf g[8]) {
    const auto [ix, iy, iz, tx, ty, tz] = cells8(px, py, pz);
    // Rows of x = ix - 1 .. ix + 2 (byte k is x = ix - 1 + k) at (y, z) offsets: R[y + 1][z + 1].
    v8su R[4][4];
    static constexpr int kRows[12][2] = {{0, 0},  {1, 0},  {0, 1}, {1, 1}, {2, 0},  {2, 1},
                                         {-1, 0}, {-1, 1}, {0, 2}, {1, 2}, {0, -1}, {1, -1}};
    for (int l = 0; l < 8; ++l) {
        const uint8_t* b = f.density + (ix[l] - 1) + f.sy * iy[l] + f.sz * iz[l];
        for (const auto& yz : kRows) {
            uint32_t v;
            std::memcpy(&v, b + f.sy * yz[0] + f.sz * yz[1], 4);
            R[yz[0] + 1][yz[1] + 1][l] = v;
        }
    }
    auto byteOf = [](v8su r, int k) { return v8si((r >> (8 * k)) & 255u); };
    auto half = [](v8si d) { return __builtin_convertvector(d, v8sf) * 0.5f; };
    auto lerp8 = [](v8sf a, v8sf b, v8sf t) { return a + t * (b - a); };
    // Per corner (y, z) of the cell: the x lerp of the differences at x = 0 and x = 1.
    v8sf gx[4], gy[4], gz[4];
    for (int c = 0; c < 4; ++c) {
        const int y = (c & 1) + 1, z = (c >> 1) + 1;
        const v8su r = R[y][z];
        const v8sf ax = half(byteOf(r, 2) - byteOf(r, 0)), bx = half(byteOf(r, 3) - byteOf(r, 1));
        const v8sf ay = half(byteOf(R[y + 1][z], 1) - byteOf(R[y - 1][z], 1));
        const v8sf by = half(byteOf(R[y + 1][z], 2) - byteOf(R[y - 1][z], 2));
        const v8sf az = half(byteOf(R[y][z + 1], 1) - byteOf(R[y][z - 1], 1));
        const v8sf bz = half(byteOf(R[y][z + 1], 2) - byteOf(R[y][z - 1], 2));
        gx[c] = lerp8(ax, bx, tx), gy[c] = lerp8(ay, by, tx), gz[c] = lerp8(az, bz, tx);
    }
    // Then the y and z lerps of the corners' vectors, component by component.
    auto yz = [&](const v8sf* v) {
        const v8sf e0 = lerp8(v[0], v[1], ty), e1 = lerp8(v[2], v[3], ty);
        return lerp8(e0, e1, tz);
    };
    const v8sf rx = yz(gx), ry = yz(gy), rz = yz(gz);
    for (int l = 0; l < 8; ++l)
        g[l] = v4sf{rx[l], ry[l], rz[l], 0.0f};
}

// Whether every sample and the shading stencil of hit `h` stay off the volume's faces, so that
// the fast paths (sample8, gradient8) hold: the cells of the samples at kIn - 1 and kIn and every
// position between them (the refinement's) have their lowest voxel in [1, n - 3] on each axis.
inline bool hitInside(const Frame& f, const PendingHit& h) {
    auto inside = [&](float t) {
        const v4si i = floorInt4(samplePos4(f, h.r, t));
        return i[0] >= 1 && i[1] >= 1 && i[2] >= 1 && i[0] + 2 < f.n.x && i[1] + 2 < f.n.y &&
               i[2] + 2 < f.n.z;
    };
    return inside(h.m.tIn) && (!h.m.refine || inside(float(h.m.kIn - 1) * f.dt));
}

// refineHit then the gradient of finishHit for up to eight hits (all hitInside), lane by lane;
// writes each hit's refined t into its March and its gradient (per voxel) to g.
void refineAndDifferentiate8(const Frame& f, PendingHit* const* hits, int count, v4sf g[8]) {
    v8sf ox{}, oy{}, oz{}, dx{}, dy{}, dz{}, tIn{}, value{}, ta{}, before{}; // set lane by lane
    v8si refine{};
    // The sample before the first inside one: most often the march computed it (lastK), by
    // sample8's arithmetic, and then it is not sampled again.
    bool known = true;
    for (int l = 0; l < 8; ++l) {
        const PendingHit& h = *hits[l < count ? l : 0]; // lanes past count repeat the first
        ox[l] = f.origin.x, oy[l] = f.origin.y, oz[l] = f.origin.z;
        dx[l] = h.r.dv.x, dy[l] = h.r.dv.y, dz[l] = h.r.dv.z;
        tIn[l] = h.m.tIn;
        value[l] = h.m.value;
        before[l] = h.m.lastValue;
        known = known && (!h.m.refine || h.m.lastK == h.m.kIn - 1);
        // A hit at the first sample of the ray's span is not refined: its lanes bracket [tIn, tIn]
        // with fa < 0, so every sample below stays at tIn (inside the volume, never NaN) and is
        // dropped at the end.
        ta[l] = h.m.refine ? float(h.m.kIn - 1) * f.dt : h.m.tIn;
        refine[l] = h.m.refine ? -1 : 0;
    }
    const float iso = float(kSurfaceDensity);
    v8sf tb = tIn;
    v8sf fa = (known ? before : sample8(f, ox + ta * dx, oy + ta * dy, oz + ta * dz)) - iso;
    // fa < 0 <= fb brackets the iso-value; the march and a valid hit cache guarantee it (the
    // sample before the first inside one was below, and erosion only lowers it). A cache kept
    // across a rise in density (no Renderer::rebuild) can break it, and the secant would then
    // extrapolate out of the volume: such a hit is left unrefined at its first inside sample,
    // a wrong pixel instead of a crash. Valid hits are unchanged bit for bit.
    refine = refine & (fa < 0.0f);
    ta = refine ? ta : tIn;
    const v8sf minusOne = v8sf{} - 1.0f;
    fa = refine ? fa : minusOne;
    v8sf fb = value - iso;
    for (int i = 0; i < kRefineSteps; ++i) {
        const v8sf tm = ta + (tb - ta) * (fa / (fa - fb));
        const v8sf fm = sample8(f, ox + tm * dx, oy + tm * dy, oz + tm * dz) - iso;
        const v8si in = fm >= 0.0f;
        ta = in ? ta : tm, fa = in ? fa : fm;
        tb = in ? tm : tb, fb = in ? fm : fb;
    }
    const v8sf t = refine ? ta + (tb - ta) * (fa / (fa - fb)) : tIn;
    for (int l = 0; l < count; ++l)
        hits[l]->m.t = t[l];
    gradient8(f, ox + t * dx, oy + t * dy, oz + t * dz, g);
}

// windowDepth(viewProj, eye + t dir), the same double arithmetic inlined.
inline float hitDepth(const Frame& f, const Ray& r, float t) {
    const glm::dvec3 q = f.eye + double(t) * r.dir;
    const double z = f.zx * q.x + f.zy * q.y + f.zz * q.z + f.z0;
    const double w = f.wx * q.x + f.wy * q.y + f.wz * q.z + f.w0;
    const double d = (z / w) * 0.5 + 0.5;
    return float(std::clamp(d, 0.0, 1.0));
}

struct Shade {
    v4sf color; // materialColor, lane 3 zero
    float ambient, diffuse, specular;
    int shininessLog2; // specular exponent 2^shininessLog2
};

// Per material (indexed by Material; air, never a hit, as cortical bone).
const Shade kShades[kMaterialCount] = {
    {{232.0f, 222.0f, 196.0f, 0.0f}, 0.20f, 0.75f, 0.12f, 5}, // (air)
    {{232.0f, 222.0f, 196.0f, 0.0f}, 0.20f, 0.75f, 0.12f, 5}, // cortical
    {{190.0f, 132.0f, 108.0f, 0.0f}, 0.22f, 0.75f, 0.05f, 4}, // diploe
    {{205.0f, 84.0f, 88.0f, 0.0f}, 0.22f, 0.75f, 0.15f, 6},   // dura: wet, a tighter highlight
    {{226.0f, 178.0f, 172.0f, 0.0f}, 0.22f, 0.75f, 0.12f, 6}, // brain
    {{92.0f, 52.0f, 120.0f, 0.0f}, 0.22f, 0.75f, 0.15f, 6},   // sinus: wet
    {{214.0f, 38.0f, 34.0f, 0.0f}, 0.22f, 0.75f, 0.15f, 6},   // artery: wet
};

// Headlight Phong: the light sits at the eye, so the half vector is the view vector.
inline void shadePixel(const Hit& h, const Ray& r, uint8_t* rgba) {
    const v4sf n = h.normal, d = r.dir4;
    float ndl = std::max(0.0f, -(n[0] * d[0] + n[1] * d[1] + n[2] * d[2]));
    const Shade& s = kShades[int(h.material)];
    // ndl^(2^k) by k squarings, all taken and one picked: no loop whose length follows the
    // material.
    float powers[7];
    powers[0] = ndl;
    for (int i = 1; i < 7; ++i)
        powers[i] = powers[i - 1] * powers[i - 1];
    const float spec = powers[s.shininessLog2];
    const v4sf c = s.color * (s.ambient + s.diffuse * ndl) + s.specular * spec * 255.0f;
    // uint8_t(min(255, c) + 0.5) per channel: min, truncation, then packing values in [0, 255].
    const v4sf rounded = (v4sf)_mm_min_ps((__m128)c, _mm_set1_ps(255.0f)) + 0.5f;
    const __m128i q = _mm_cvttps_epi32((__m128)rounded);
    const __m128i b = _mm_packus_epi16(_mm_packs_epi32(q, q), _mm_setzero_si128());
    const uint32_t px = uint32_t(_mm_cvtsi128_si32(b)) | 0xff000000u; // alpha 255
    std::memcpy(rgba, &px, 4);
}

} // namespace

// [SECTION] Renderer -----------------------------------------------------------------------------

namespace {

// Generations are unique across renderers, so a cache can never match another renderer's volume.
std::atomic<uint64_t> g_generations{0};

uint64_t nextGeneration() {
    return g_generations.fetch_add(1, std::memory_order_relaxed) + 1;
}

} // namespace

void HitCache::clear() {
    m_generation = 0;
    m_resume.clear();
    m_inside.clear();
    m_rowKnown.clear();
    m_resumed = 0;
    m_kept = 0;
}

bool HitCache::validFor(const Renderer& renderer, const Camera& camera) const {
    return m_generation == renderer.generation() && m_camera == camera &&
           m_stepVoxels == renderer.options().stepVoxels &&
           m_spacing == renderer.volume().spacing() &&
           m_resume.size() == size_t(camera.width) * size_t(camera.height);
}

Renderer::Renderer(const Volume& volume, ThreadPool* pool, RenderOptions options)
    : m_volume(&volume), m_pool(pool), m_options(options), m_generation(nextGeneration()) {
    m_bricks.build(volume);
}

void Renderer::volumeChanged(const Box3i& changed) {
    if (m_bricks.update(*m_volume, changed))
        m_generation = nextGeneration(); // surface appeared: not erosion, caches may be wrong
}

void Renderer::rebuild() {
    m_bricks.build(*m_volume);
    m_generation = nextGeneration();
}

RayHit Renderer::castRay(const Camera& camera, int x, int y) const {
    Frame f = makeFrame(*m_volume, camera, m_options, m_bricks);
    int32_t resume = 0;
    const Ray r = pixelRay(f, x, y);
    RayHit out;
    out.direction = glm::vec3(r.dir);
    Hit h;
    if (!traceRay(f, r, 0.0f, resume, h))
        return out;
    out.hit = true;
    out.distanceMm = h.t;
    out.position = f.eye + double(h.t) * r.dir;
    out.depth = hitDepth(f, r, h.t);
    out.normal = glm::vec3(h.normal[0], h.normal[1], h.normal[2]);
    out.material = h.material;
    return out;
}

Dbi Renderer::render(const Camera& camera) const {
    return render(camera, nullptr);
}

Dbi Renderer::render(const Camera& camera, HitCache* cache) const {
    Dbi frame(camera.width, camera.height);
    render(camera, frame.bounds(), frame, cache);
    return frame;
}

void Renderer::render(const Camera& camera, const PixelRect& rect, Dbi& frame) const {
    render(camera, rect, frame, nullptr);
}

void Renderer::render(const Camera& camera, const PixelRect& rect, Dbi& frame,
                      HitCache* cache) const {
    const PixelRect r = prepare(camera, rect, frame, cache);
    renderInto(camera, r, frame, r.x, r.y, cache, Tiling{});
}

void Renderer::renderChanged(const Camera& camera, const PixelRect& rect, Dbi& frame,
                             HitCache& cache, const Box3i& changed) const {
    const PixelRect r = prepare(camera, rect, frame, &cache);
    renderInto(camera, r, frame, r.x, r.y, &cache, Tiling{}, &changed);
}

PixelRect Renderer::prepare(const Camera& camera, const PixelRect& rect, const Dbi& frame,
                            HitCache* cache) const {
    assert(frame.width() == camera.width && frame.height() == camera.height &&
           "Renderer::render: the frame must be the camera's window size");
    if (cache && !cache->validFor(*this, camera)) {
        // Another view or a volume that may have gained density: start afresh. 0 (unknown) is a
        // valid lower bound for every pixel.
        cache->m_camera = camera;
        cache->m_generation = m_generation;
        cache->m_stepVoxels = m_options.stepVoxels;
        cache->m_spacing = m_volume->spacing();
        // Cleared first, so a larger view's arrays are not copied over: rows are zeroed below.
        cache->m_resume.clear();
        cache->m_inside.clear();
        cache->m_resume.resize(size_t(camera.width) * size_t(camera.height));
        cache->m_inside.resize(size_t(camera.width) * size_t(camera.height));
        cache->m_rowKnown.assign(size_t(camera.height), 0);
        cache->m_resumed = 0;
        cache->m_kept = 0;
    }
    // Inside the camera's window too: the hit cache is sized and strided by it, and the assert
    // above is gone from a release build.
    const PixelRect r =
        intersect(intersect(rect, frame.bounds()), PixelRect(0, 0, camera.width, camera.height));
    if (cache) {
        // Rows are zeroed whole, here before the tiles run: a tile reads and writes only its own
        // pixels, and a later rectangle in the row finds it known.
        const size_t width = size_t(camera.width);
        for (int y = r.y; y < r.y + r.h; ++y) {
            if (cache->m_rowKnown[size_t(y)])
                continue;
            std::fill_n(cache->m_resume.begin() + ptrdiff_t(size_t(y) * width), width, 0);
            std::fill_n(cache->m_inside.begin() + ptrdiff_t(size_t(y) * width), width, 0);
            cache->m_rowKnown[size_t(y)] = 1;
        }
    }
    return r;
}

Dbi Renderer::renderRect(const Camera& camera, const PixelRect& rect) const {
    assert(PixelRect(0, 0, camera.width, camera.height).contains(rect) &&
           "Renderer::renderRect: rectangle outside the window");
    Dbi out(rect.w, rect.h);
    renderInto(camera, rect, out, 0, 0, nullptr, Tiling{});
    return out;
}

namespace {

// One tile's pixels (see Renderer::renderInto): what the tile loop of a render shares.
struct TileJob {
    const Frame& f;
    PixelRect rect;
    Dbi& out;
    int outX, outY;
    int tile, tileH, tilesX; // tile's width, height; tiles in a row
    int32_t* cacheResume;    // the hit cache's arrays (null: no cache)
    uint8_t* cacheInside;
    size_t cacheStride;
    bool batchHits;
    std::atomic<int64_t>& resumed;
    std::atomic<int64_t>& kept;
};

// std::max(a, b) and std::min(a, b) lane by lane: maxps(b, a), minps(b, a). (Functions, not
// lambdas: a lambda would not inherit the target.)
__attribute__((target("avx2,bmi2"), always_inline)) inline v8sf maxOf(v8sf a, v8sf b) {
    return (v8sf)_mm256_max_ps((__m256)b, (__m256)a);
}
__attribute__((target("avx2,bmi2"), always_inline)) inline v8sf minOf(v8sf a, v8sf b) {
    return (v8sf)_mm256_min_ps((__m256)b, (__m256)a);
}

// int(v) lane by lane, by cvttps: defined for every lane (INT_MIN for what int cannot hold).
__attribute__((target("avx2,bmi2"), always_inline)) inline v8si truncOf(v8sf v) {
    return (v8si)_mm256_cvttps_epi32((__m256)v);
}

// A row's rays and their spans (AVX2 build): pixelRay's and marchSpan's operations lane by lane
// in eight lanes, so the same bits, with their divisions and square root done once for eight
// rays. A lane whose direction lies in a plane of the axes, or with a cached inside sample to
// test, takes marchSpan itself. Lanes that march are added to `live` with their span in `spans`
// and the packet `p`; the others' March says whether they hit.
__attribute__((target("avx2,bmi2"))) inline void setUpRow(const Frame& f, int bx, int n, int py,
                                                          v8sf skip, v8si k0, unsigned in0,
                                                          PendingHit* h, Span* spans, Packet& p,
                                                          unsigned& live, unsigned& kept) {
    const v8sf fx = __builtin_convertvector(bx + v8si{0, 1, 2, 3, 4, 5, 6, 7}, v8sf) + 0.5f;
    const float fy = float(py) + 0.5f;
    v8sf toFar[3], dv[3], invDv[3];
    for (int c = 0; c < 3; ++c)
        toFar[c] = (f.toFar0[c] + fx * f.toFarDx[c]) + fy * f.toFarDy[c];
    const v8sf len = (v8sf)_mm256_sqrt_ps(
        (__m256)((toFar[0] * toFar[0] + toFar[1] * toFar[1]) + toFar[2] * toFar[2]));
    const v8sf inv = 1.0f / len;
    v8sf dir[3];
    v8si flat = v8si{};
    for (int c = 0; c < 3; ++c) {
        dir[c] = toFar[c] * inv;
        dv[c] = dir[c] * f.invSpacing4[c];
        invDv[c] = 1.0f / dv[c];
        flat |= dv[c] == 0.0f;
    }
    const v8sf tNear = len * f.nearOverFarF;
    v8sf t0 = maxOf(tNear, v8sf{}), t1 = len;
    for (int c = 0; c < 3; ++c) {
        const v8sf ta = (f.regionLo[c] - f.origin4[c]) * invDv[c];
        const v8sf tb = (f.regionHi[c] - f.origin4[c]) * invDv[c];
        t0 = maxOf(t0, minOf(ta, tb));
        t1 = minOf(t1, maxOf(ta, tb));
    }
    t1 = minOf(t1, v8sf{} + f.tLimit);
    const float dt = f.dt, invDt = 1.0f / dt;
    // (Lanes that miss the volume, or that a cone proved empty, convert an infinity or a NaN
    // here, and are not marched.)
    const v8si kStart = truncOf(
        (v8sf)_mm256_round_ps((__m256)(t0 / dt), _MM_FROUND_TO_POS_INF | _MM_FROUND_NO_EXC));
    const v8si kEnd = truncOf(
        (v8sf)_mm256_round_ps((__m256)(t1 / dt), _MM_FROUND_TO_NEG_INF | _MM_FROUND_NO_EXC));
    const v8si marches = (skip != INFINITY) & (t0 <= t1) & (skip <= t1) & (k0 <= kEnd);
    const v8si kSkip = truncOf(skip * invDt);
    v8si k = skip > t0 ? (kSkip > kStart ? kSkip : kStart) : kStart;
    k = k0 > k ? k0 : k;
    // keptPixel lane by lane (a kNever lane's position is far out of any box).
    v8si keeps = v8si{};
    if (f.keep) {
        const v8sf tk = __builtin_convertvector(k0, v8sf) * dt;
        for (int c = 0; c < 3; ++c) {
            const v8sf pc = f.origin4[c] + tk * dv[c];
            keeps |= (pc < f.keepLo[c]) | (pc > f.keepHi[c]);
        }
        keeps &= k0 != 0;
    }
    for (int l = 0; l < n; ++l) {
        Ray& r = h[l].r;
        r.dir = glm::dvec3(dir[0][l], dir[1][l], dir[2][l]);
        r.tFar = len[l];
        r.tNear = tNear[l];
        r.dv = glm::vec3(dv[0][l], dv[1][l], dv[2][l]);
        r.invDv = glm::vec3(invDv[0][l], invDv[1][l], invDv[2][l]);
        r.dv4 = v4sf{dv[0][l], dv[1][l], dv[2][l], 0.0f};
        r.dir4 = v4sf{dir[0][l], dir[1][l], dir[2][l], 0.0f};
        r.invDv4 = v4sf{invDv[0][l], invDv[1][l], invDv[2][l], 1.0f};
        r.mainAxis = mainAxisOf(r.dv);
        h[l].m = March{};
        bool marching;
        if (keeps[l]) {
            kept |= 1u << l;
            marching = false;
        } else if (flat[l] || (in0 >> l & 1u)) {
            marching = marchSpan(f, r, skip[l], k0[l], (in0 >> l & 1u) != 0, h[l].m, spans[l]);
        } else {
            marching = marches[l] != 0;
            spans[l] = Span{kStart[l], kEnd[l], k[l]};
        }
        if (marching) {
            live |= 1u << l;
            p.dvx[l] = r.dv.x, p.dvy[l] = r.dv.y, p.dvz[l] = r.dv.z;
            p.k[l] = spans[l].k, p.kEnd[l] = spans[l].kEnd;
        } else {
            p.dvx[l] = p.dvy[l] = p.dvz[l] = 0.0f;
            p.k[l] = 0, p.kEnd[l] = -1;
        }
    }
}

// The rays of pixels [bx, bx1) of rows y .. y + rows - 1 (up to kPackets) marched as one packet a
// row (AVX2 build): each ray's span set up on its own, the packets' lockstep march, then
// marchFrom for lanes that left it. Hits go to `pending` in pixel order, misses straight to
// `out`; the hit cache (tile copy, origin (x0, y0)) as in the scalar loop of renderTileBody.
__attribute__((always_inline)) inline void
marchRows(const Frame& f, int x0, int y0, int bx, int bx1, int y, int rows,
          const float* quarterSkip, int midX, int midY, int32_t* resume, uint8_t* inside,
          size_t stride, int64_t& known, int64_t& keptCount, PendingHit* pending, int& npending,
          Dbi& out, const PixelRect& rect, int outX, int outY) {
    const int n = bx1 - bx;
    Span spans[kPackets][8];
    Packet pk[kPackets];
    unsigned live[kPackets] = {}, hits[kPackets] = {}, kept[kPackets] = {};
    for (int row = 0; row < rows; ++row) {
        const int py = y + row;
        Packet& p = pk[row];
        v8sf skip{};
        v8si k0{};
        unsigned in0 = 0;
        for (int l = 0; l < n; ++l) {
            const int x = bx + l;
            if (resume) {
                const size_t at = size_t(py - y0) * stride + size_t(x - x0);
                k0[l] = resume[at];
                in0 |= unsigned(inside[at] != 0) << l;
                known += resume[at] != 0;
            }
            PendingHit& h = pending[npending + row * n + l];
            h.ox = x - rect.x + outX, h.oy = py - rect.y + outY;
            skip[l] = quarterSkip[(x >= midX) + 2 * (py >= midY)];
        }
        setUpRow(f, bx, n, py, skip, k0, in0, &pending[npending + row * n], spans[row], p,
                 live[row], kept[row]);
        keptCount += __builtin_popcount(kept[row]);
        known -= __builtin_popcount(kept[row]); // kept lanes were known, and are not rendered
        for (int l = n; l < 8; ++l)
            p.dvx[l] = p.dvy[l] = p.dvz[l] = 0.0f, p.k[l] = 0, p.kEnd[l] = -1;
        p.lastK = v8si{} + INT_MIN;
        p.lastValue = v8sf{};
        p.value = v8sf{};
    }
    unsigned marching[kPackets], any = 0;
    for (int i = 0; i < kPackets; ++i)
        marching[i] = live[i], any |= live[i];
    if (any)
        marchPackets(f, pk, live, hits, rows);
    // Row by row, lane by lane: hits move down to `next` (never past a lane still to be read).
    int next = npending;
    for (int row = 0; row < rows; ++row)
        for (int l = 0; l < n; ++l) {
            if (kept[row] >> l & 1u)
                continue; // its frame pixel and cache entry stand
            PendingHit& h = pending[npending + row * n + l];
            const Packet& p = pk[row];
            if (marching[row] >> l & 1u) {
                Span s = spans[row][l];
                if (hits[row] >> l & 1u) {
                    March& m = h.m;
                    m.hit = true;
                    m.kIn = p.k[l];
                    m.tIn = float(p.k[l]) * f.dt;
                    m.t = m.tIn;
                    m.value = p.value[l];
                    m.refine = p.k[l] > s.kStart;
                    m.lastK = p.lastK[l];
                    m.lastValue = p.lastValue[l];
                } else {
                    s.k = p.k[l];
                    h.m = marchFrom<true>(f, h.r, s, p.lastK[l], p.lastValue[l]);
                }
            }
            if (resume) {
                const size_t at = size_t(y + row - y0) * stride + size_t(bx + l - x0);
                resume[at] = h.m.kIn;
                inside[at] = h.m.hit && h.m.refine;
            }
            if (h.m.hit) {
                if (&pending[next] != &h)
                    pending[next] = h;
                ++next;
            } else {
                std::memcpy(out.color(h.ox, h.oy), kBackgroundRgba, 4);
                out.depth()[out.index(h.ox, h.oy)] = kBackgroundDepth;
            }
        }
    npending = next;
}

template <bool Wide>
__attribute__((always_inline)) inline void renderTileBody(const TileJob& job, int i) {
    const Frame& f = job.f;
    const PixelRect& rect = job.rect;
    Dbi& out = job.out;
    const int outX = job.outX, outY = job.outY, tile = job.tile, tileH = job.tileH,
              tilesX = job.tilesX;
    int32_t* const cacheResume = job.cacheResume;
    uint8_t* const cacheInside = job.cacheInside;
    const size_t cacheStride = job.cacheStride;
    std::atomic<int64_t>& resumed = job.resumed;
    int tx = i % tilesX, ty = i / tilesX;
    int64_t keptCount = 0;
    int x0 = rect.x + tx * tile, y0 = rect.y + ty * tileH;
    int x1 = std::min(x0 + tile, rect.x + rect.w), y1 = std::min(y0 + tileH, rect.y + rect.h);
    int64_t known = 0;
    // The tile's part of the hit cache, in this thread's own copy, read once and written
    // back once: tiles side by side (other threads) share cache lines of the per-pixel
    // arrays (four tiles a line of the 1-byte flags), and updating them pixel by pixel in
    // place measured two threads slower than one (a 500 x 500 frame: 6.6 ms on two, 5.7 on
    // one; 4.6 ms uncached on two).
    const int tw = x1 - x0, th = y1 - y0;
    thread_local std::vector<int32_t> tileResume;
    thread_local std::vector<uint8_t> tileInside;
    int32_t* resume = nullptr;
    uint8_t* inside = nullptr;
    if (cacheResume) {
        tileResume.resize(size_t(tw) * size_t(th));
        tileInside.resize(size_t(tw) * size_t(th));
        for (int y = 0; y < th; ++y) {
            const size_t from = size_t(y0 + y) * cacheStride + size_t(x0);
            std::memcpy(&tileResume[size_t(y) * size_t(tw)], cacheResume + from,
                        size_t(tw) * sizeof(int32_t));
            std::memcpy(&tileInside[size_t(y) * size_t(tw)], cacheInside + from, size_t(tw));
        }
        resume = tileResume.data();
        inside = tileInside.data();
    }
    const size_t stride = size_t(tw); // of the tile's copy, whose (0, 0) is (x0, y0)
    auto local = [&](int x, int y) { return size_t(y - y0) * stride + size_t(x - x0); };
    for (int by = y0; by < y1; by += kConeBlock)
        for (int bx = x0; bx < x1; bx += kConeBlock) {
            int bx1 = std::min(bx + kConeBlock, x1), by1 = std::min(by + kConeBlock, y1);
            // The cone starts where the block's earliest cached first hit was (the eye where
            // some pixel is unknown): the cache already proves every ray empty before that,
            // and after erosion the cone leaps through the emptied space once for the block
            // instead of every ray leaping on its own. A block whose rays can never hit needs
            // no cone.
            int32_t kMin = resume ? HitCache::kNever : 0;
            for (int y = by; y < by1 && kMin > 0; ++y)
                for (int x = bx; x < bx1; ++x)
                    kMin = std::min(kMin, resume[local(x, y)]);
            const float tStart = float(kMin) * f.dt;
            const float tSkipTo = f.distance && kMin != HitCache::kNever
                                      ? coneSkipTo(f, bx, by, bx1, by1, tStart)
                                      : 0.0f;
            // A cone that went some way and then stopped near surface (a hole's wall, the
            // rim of a cut) may have stopped for the sake of a few of the block's rays: the
            // quarters' narrower cones go on from there, each for its own 4 x 4 rays. (Cones
            // that stop at once stay whole: quartering them measured slower, and so did a
            // second level of quarters.)
            const int midX = (bx + bx1) / 2, midY = (by + by1) / 2;
            float quarterSkip[4] = {tSkipTo, tSkipTo, tSkipTo, tSkipTo};
            if (tSkipTo > tStart && tSkipTo < INFINITY && midX > bx && midY > by)
                for (int q = 0; q < 4; ++q)
                    quarterSkip[q] =
                        coneSkipTo(f, q & 1 ? midX : bx, q & 2 ? midY : by, q & 1 ? bx1 : midX,
                                   q & 2 ? by1 : midY, tSkipTo, true);
            if (quarterSkip[0] == INFINITY && quarterSkip[1] == INFINITY &&
                quarterSkip[2] == INFINITY && quarterSkip[3] == INFINITY) {
                // The cones proved every ray of the block empty: background, never to hit.
                for (int y = by; y < by1; ++y)
                    for (int x = bx; x < bx1; ++x) {
                        const int ox = x - rect.x + outX, oy = y - rect.y + outY;
                        std::memcpy(out.color(ox, oy), kBackgroundRgba, 4);
                        out.depth()[out.index(ox, oy)] = kBackgroundDepth;
                        if (resume) {
                            const size_t at = local(x, y);
                            known += resume[at] != 0;
                            resume[at] = HitCache::kNever;
                            inside[at] = 0;
                        }
                    }
                continue;
            }
            // March the block's rays (in packets of a row, AVX2 build); refine and shade their hits
            // eight at a time.
            PendingHit pending[kConeBlock * kConeBlock];
            int npending = 0;
            for (int y = by; y < by1; ++y) {
                if constexpr (Wide) {
                    if (f.marchEight) {
                        const int rows = std::min(kPackets, by1 - y);
                        marchRows(f, x0, y0, bx, bx1, y, rows, quarterSkip, midX, midY, resume,
                                  inside, stride, known, keptCount, pending, npending, out, rect,
                                  outX, outY);
                        y += rows - 1;
                        continue;
                    }
                }
                for (int x = bx; x < bx1; ++x) {
                    int ox = x - rect.x + outX, oy = y - rect.y + outY;
                    int32_t k = 0;
                    uint8_t notInside = 0;
                    const size_t at = resume ? local(x, y) : 0;
                    int32_t* slot = resume ? &resume[at] : &k;
                    uint8_t* wasInside = resume ? &inside[at] : &notInside;
                    PendingHit& h = pending[npending];
                    h.r = pixelRay(f, x, y);
                    if (f.keep && *slot != 0 && keptPixel(f, h.r, *slot)) {
                        ++keptCount;
                        continue;
                    }
                    known += *slot != 0;
                    const float skip = quarterSkip[(x >= midX) + 2 * (y >= midY)];
                    h.m = marchToSurface<Wide>(f, h.r, skip, *slot, *wasInside != 0);
                    *slot = h.m.kIn;
                    *wasInside = h.m.hit && h.m.refine;
                    if (h.m.hit) {
                        h.ox = ox, h.oy = oy;
                        ++npending;
                    } else {
                        std::memcpy(out.color(ox, oy), kBackgroundRgba, 4);
                        out.depth()[out.index(ox, oy)] = kBackgroundDepth;
                    }
                }
            }
            auto write = [&](const PendingHit& p, const Hit& hit) {
                shadePixel(hit, p.r, out.color(p.ox, p.oy));
                out.depth()[out.index(p.ox, p.oy)] = hitDepth(f, p.r, hit.t);
            };
            PendingHit* batch[8];
            int nbatch = 0;
            auto flush = [&] {
                v4sf g[8];
                refineAndDifferentiate8(f, batch, nbatch, g);
                for (int l = 0; l < nbatch; ++l) {
                    const PendingHit& p = *batch[l];
                    Hit hit;
                    hit.t = p.m.t;
                    hit.normal = hitNormal(f, p.r, g[l]);
                    hit.material =
                        hitMaterial(f, samplePos4(f, p.r, p.m.t), samplePos4(f, p.r, p.m.tIn));
                    write(p, hit);
                }
                nbatch = 0;
            };
            for (int i = 0; i < npending; ++i) {
                PendingHit& p = pending[i];
                if (job.batchHits && hitInside(f, p)) {
                    batch[nbatch++] = &p;
                    if (nbatch == 8)
                        flush();
                    continue;
                }
                refineHit(f, p.r, p.m);
                Hit hit;
                finishHit(f, p.r, p.m, hit);
                write(p, hit);
            }
            if (nbatch > 0)
                flush();
        }
    if (resume) {
        for (int y = 0; y < th; ++y) {
            const size_t to = size_t(y0 + y) * cacheStride + size_t(x0);
            std::memcpy(cacheResume + to, &tileResume[size_t(y) * size_t(tw)],
                        size_t(tw) * sizeof(int32_t));
            std::memcpy(cacheInside + to, &tileInside[size_t(y) * size_t(tw)], size_t(tw));
        }
        resumed.fetch_add(known, std::memory_order_relaxed);
        job.kept.fetch_add(keptCount, std::memory_order_relaxed);
    }
}

// The tile loop compiled twice: for baseline x86-64 (SSE2) and, with everything it calls inlined
// (flatten), for AVX2, chosen at run time. Both are the same IEEE operations in the same order
// (no FMA: contraction would change bits), so the pixels are the same bit for bit.
__attribute__((flatten)) void renderTileBaseline(const TileJob& job, int i) {
    renderTileBody<false>(job, i);
}

__attribute__((flatten, target("avx2,bmi2"))) void renderTileAvx2(const TileJob& job, int i) {
    renderTileBody<true>(job, i);
}

bool cpuHasAvx2() {
    static const bool has = __builtin_cpu_supports("avx2") && __builtin_cpu_supports("bmi2");
    return has;
}

} // namespace

int Renderer::renderInto(const Camera& camera, const PixelRect& rect, Dbi& out, int outX, int outY,
                         HitCache* cache, const Tiling& tiling, const Box3i* changed) const {
    if (rect.empty())
        return 0;
    const int tile = std::max(4, m_options.tileSize);
    const int tileH = tiling.stop ? rect.h : tile;
    const int tilesX = (rect.w + tile - 1) / tile, tilesY = (rect.h + tileH - 1) / tileH;
    if (m_volume->empty()) {
        // Every pixel of the rectangle is written, as a render writes a miss: frames start
        // unfilled.
        out.apply(Dbi(rect.w, rect.h), outX, outY);
        return tilesX * tilesY;
    }
    Frame f = makeFrame(*m_volume, camera, m_options, m_bricks);
    if (changed && cache && f.nearEye) {
        // The changed voxels' faces (sample coordinates: voxel v's centre at v) grown by what a
        // hit reads (kDirtyStencilVoxels) and one step, as the hit lies between the cached
        // sample and the one before. (A far eye's positions round by more than the stencil's
        // half-voxel margin: it renders every pixel.)
        f.keep = true;
        const float grow =
            kDirtyStencilVoxels + f.dt * std::max({f.invSpacing.x, f.invSpacing.y, f.invSpacing.z});
        for (int c = 0; c < 3; ++c) {
            f.keepLo[c] = float(changed->lo[c]) - 0.5f - grow;
            f.keepHi[c] = float(changed->hi[c]) - 0.5f + grow;
        }
        f.keepLo[3] = -INFINITY;
        f.keepHi[3] = INFINITY;
    }
    int32_t* cacheResume = cache ? cache->m_resume.data() : nullptr;
    uint8_t* cacheInside = cache ? cache->m_inside.data() : nullptr;
    const size_t cacheStride = size_t(camera.width);
    std::atomic<int64_t> resumed{0}, kept{0};
    const TileJob job{f,       rect,   out,         outX,        outY,        tile,
                      tileH,   tilesX, cacheResume, cacheInside, cacheStride, m_options.batchHits,
                      resumed, kept};
    const bool avx2 = m_options.avx2 && cpuHasAvx2();
    auto renderTile = [&](int i) {
        if (avx2)
            renderTileAvx2(job, i);
        else
            renderTileBaseline(job, i);
    };
    const int tiles = tilesX * tilesY;
    ThreadPool* pool = tiling.pool ? tiling.pool : m_pool;
    int done = tiles;
    if (tiling.stop) {
        const int atLeast =
            int((int64_t(tiling.atLeast) + int64_t(tile) * tileH - 1) / (int64_t(tile) * tileH));
        if (pool) {
            done = pool->parallelForUntil(tiles, renderTile, *tiling.stop, atLeast);
        } else {
            done = 0;
            while (done < tiles && (done < atLeast || !(*tiling.stop)()))
                renderTile(done++);
        }
    } else if (pool) {
        pool->parallelFor(tiles, renderTile);
    } else {
        for (int i = 0; i < tiles; ++i)
            renderTile(i);
    }
    if (cache) {
        cache->m_resumed += resumed.load(std::memory_order_relaxed);
        cache->m_kept += kept.load(std::memory_order_relaxed);
    }
    return done;
}

int Renderer::renderBulk(const Camera& camera, const PixelRect& rect, Dbi& frame, HitCache* cache,
                         const std::function<bool()>& stop, int atLeast) const {
    const PixelRect r = prepare(camera, rect, frame, cache);
    if (r.empty())
        return rect.w; // nothing to render: all of it done
    const int tile = std::max(4, m_options.tileSize);
    const int w = std::min(r.w, tile * renderInto(camera, r, frame, r.x, r.y, cache,
                                                  {m_bulkPool, &stop, std::max(atLeast, 1)}));
    return w == r.w ? rect.w : r.x - rect.x + w;
}

} // namespace trephine

#include "libsim/brick_grid.h"

#include "libsim/volume.h"

#include <algorithm>
#include <climits>

namespace trephine {

namespace {

int floorDiv(int a, int b) {
    return a >= 0 ? a / b : -((-a + b - 1) / b);
}

// o[i] = 0 where the brick maximum m[i] reaches the iso-value, else kMaxDistance (vectorised).
void sources(uint8_t* __restrict o, const uint8_t* __restrict m, size_t n) {
    for (size_t i = 0; i < n; ++i)
        o[i] = m[i] >= kSurfaceDensity ? 0 : BrickGrid::kMaxDistance;
}

// d[i] = min(d[i], n[i] + 1), the sum saturating at kMaxDistance (vectorised).
void lowerTo(uint8_t* __restrict d, const uint8_t* __restrict n, size_t count) {
    for (size_t i = 0; i < count; ++i) {
        const uint8_t v = n[i];
        d[i] = std::min(d[i], uint8_t(v + (v != BrickGrid::kMaxDistance)));
    }
}

// o[i] = min(a[i], b[i], c[i]) for i < n (vectorised).
void minOf3(uint8_t* __restrict o, const uint8_t* a, const uint8_t* b, const uint8_t* c, size_t n) {
    for (size_t i = 0; i < n; ++i)
        o[i] = std::min(std::min(a[i], b[i]), c[i]);
}

} // namespace

void BrickGrid::regionMax(const Volume& volume, glm::ivec3 b0, glm::ivec3 b1,
                          std::vector<uint8_t>& out) {
    // Separable maximum, each brick over its voxels plus apron: first along z and then y as
    // element-wise maxima of whole voxel rows (vectorised), so that only one row per brick row is
    // left for the x pass.
    const glm::ivec3 n = volume.dims();
    const glm::ivec3 B = b1 - b0 + 1; // bricks of the region per axis
    const uint8_t* d = volume.densityData();
    auto range = [](int b, int limit) {
        return std::pair{std::max(0, b * kSize - kApronLo),
                         std::min(limit, b * kSize + kSize + kApronHi)};
    };
    // Voxels the region's bricks read, per axis.
    glm::ivec3 v0, v1;
    for (int a = 0; a < 3; ++a) {
        v0[a] = range(b0[a], n[a]).first;
        v1[a] = range(b1[a], n[a]).second;
    }
    const int len = v1.x - v0.x, ny = v1.y - v0.y;
    auto maxInto = [len](uint8_t* __restrict o, const uint8_t* __restrict in) {
        for (int i = 0; i < len; ++i)
            o[i] = std::max(o[i], in[i]);
    };
    thread_local std::vector<uint8_t> mz, myz;
    mz.resize(size_t(B.z) * ny * len);
    for (int bz = 0; bz < B.z; ++bz) {
        auto [z0, z1] = range(b0.z + bz, n.z);
        for (int y = 0; y < ny; ++y) {
            uint8_t* o = &mz[(size_t(bz) * ny + y) * len];
            std::copy_n(d + volume.index(v0.x, v0.y + y, z0), len, o);
            for (int z = z0 + 1; z < z1; ++z)
                maxInto(o, d + volume.index(v0.x, v0.y + y, z));
        }
    }
    myz.resize(size_t(B.z) * B.y * len);
    for (int bz = 0; bz < B.z; ++bz)
        for (int by = 0; by < B.y; ++by) {
            auto [y0, y1] = range(b0.y + by, n.y);
            uint8_t* o = &myz[(size_t(bz) * B.y + by) * len];
            const uint8_t* in = &mz[(size_t(bz) * ny + (y0 - v0.y)) * len];
            std::copy_n(in, len, o);
            for (int y = y0 + 1; y < y1; ++y)
                maxInto(o, in += len);
        }
    out.resize(size_t(B.x) * B.y * B.z);
    uint8_t* o = out.data();
    for (size_t r = 0; r < size_t(B.z) * B.y; ++r) {
        const uint8_t* row = &myz[r * len];
        for (int bx = 0; bx < B.x; ++bx) {
            auto [x0, x1] = range(b0.x + bx, n.x);
            *o++ = *std::max_element(row + (x0 - v0.x), row + (x1 - v0.x));
        }
    }
}

void BrickGrid::build(const Volume& volume) {
    m_volumeDims = volume.dims();
    m_dims = (m_volumeDims + (kSize - 1)) / kSize;
    const glm::ivec3 B = m_dims;
    regionMax(volume, glm::ivec3(0), B - 1, m_max);
    m_cells.assign(m_max.size(), 0);
    for (int bz = 0; bz < B.z; ++bz)
        for (int by = 0; by < B.y; ++by)
            for (int bx = 0; bx < B.x; ++bx) {
                size_t i = index({bx, by, bz});
                // A cell's corners lie inside the brick's apron, so a brick below the iso-value
                // everywhere has no marked cell.
                if (m_max[i] >= kSurfaceDensity)
                    m_cells[i] = computeCellMask(volume, {bx, by, bz});
            }
    m_distance.assign(m_max.size(), kMaxDistance);
    computeDistances();
    for (std::vector<uint8_t>& r : m_runs)
        r.assign(m_max.size(), 0);
    computeRuns(glm::ivec3(0), B - 1);
}

void BrickGrid::computeRuns(glm::ivec3 lo, glm::ivec3 hi) {
    const glm::ivec3 B = m_dims;
    auto empty = [&](size_t at) { return m_max[at] < kSurfaceDensity; };
    auto next = [](uint8_t run) { return uint8_t(run + (run != kMaxDistance)); };
    // Along x: row by row.
    for (int z = lo.z; z <= hi.z; ++z)
        for (int y = lo.y; y <= hi.y; ++y) {
            const size_t row = index({0, y, z});
            uint8_t* plus = &m_runs[1][row];
            uint8_t* minus = &m_runs[0][row];
            uint8_t run = 0;
            for (int x = B.x - 1; x >= 0; --x)
                plus[x] = run = empty(row + size_t(x)) ? next(run) : 0;
            run = 0;
            for (int x = 0; x < B.x; ++x)
                minus[x] = run = empty(row + size_t(x)) ? next(run) : 0;
        }
    // Along y and z: whole stretches of x at a time, from the neighbouring row or slice.
    auto sweep = [&](int axis, size_t step, int outerLo, int outerHi, auto at) {
        const int n = B[axis];
        uint8_t* plus = m_runs[size_t(2 * axis + 1)].data();
        uint8_t* minus = m_runs[size_t(2 * axis)].data();
        for (int o = outerLo; o <= outerHi; ++o) {
            for (int k = n - 1; k >= 0; --k) {
                const size_t first = at(o, k);
                for (int x = lo.x; x <= hi.x; ++x) {
                    const size_t i = first + size_t(x);
                    plus[i] = empty(i) ? (k + 1 < n ? next(plus[i + step]) : 1) : 0;
                }
            }
            for (int k = 0; k < n; ++k) {
                const size_t first = at(o, k);
                for (int x = lo.x; x <= hi.x; ++x) {
                    const size_t i = first + size_t(x);
                    minus[i] = empty(i) ? (k > 0 ? next(minus[i - step]) : 1) : 0;
                }
            }
        }
    };
    const size_t rowStep = size_t(B.x), sliceStep = size_t(B.x) * size_t(B.y);
    sweep(1, rowStep, lo.z, hi.z, [&](int z, int y) { return index({0, y, z}); });
    sweep(2, sliceStep, lo.y, hi.y, [&](int y, int z) { return index({0, y, z}); });
}

uint64_t BrickGrid::computeCellMask(const Volume& volume, glm::ivec3 b) const {
    static_assert(kSize == 4, "one 64-bit mask holds the 4^3 cells of a brick");
    // Solid bits of the 5^3 voxels 4b .. 4b + 4 (air outside the volume), 5 bits per row.
    glm::ivec3 lo = b * kSize;
    uint32_t rows[5][5] = {};
    for (int z = 0; z < 5; ++z)
        for (int y = 0; y < 5; ++y) {
            glm::ivec3 v = lo + glm::ivec3(0, y, z);
            if (v.y >= m_volumeDims.y || v.z >= m_volumeDims.z)
                continue;
            const uint8_t* row = volume.densityData() + volume.index(v.x, v.y, v.z);
            int n = std::min(5, m_volumeDims.x - v.x);
            uint32_t bits = 0;
            for (int x = 0; x < n; ++x)
                bits |= uint32_t(row[x] >= kSurfaceDensity) << x;
            rows[z][y] = bits;
        }
    uint64_t mask = 0;
    for (int z = 0; z < 4; ++z)
        for (int y = 0; y < 4; ++y) {
            uint32_t r = rows[z][y] | rows[z][y + 1] | rows[z + 1][y] | rows[z + 1][y + 1];
            uint32_t cells = (r | (r >> 1)) & 0xFu; // cell x spans voxels x and x + 1
            mask |= uint64_t(cells) << (4 * y + 16 * z);
        }
    return mask;
}

bool BrickGrid::update(const Volume& volume, const Box3i& changed) {
    if (empty() || volume.dims() != m_volumeDims) {
        build(volume);
        return true;
    }
    Box3i box = changed.intersect(volume.bounds());
    if (box.empty())
        return false;
    // Brick b covers voxels [4b - apronLo, 4b + 4 + apronHi): it overlaps [lo, hi) when
    // 4b + 4 + apronHi > lo and 4b - apronLo < hi.
    glm::ivec3 b0, b1;
    for (int a = 0; a < 3; ++a) {
        b0[a] = std::max(0, floorDiv(box.lo[a] - kSize - kApronHi, kSize) + 1);
        b1[a] = std::min(m_dims[a] - 1, floorDiv(box.hi[a] - 1 + kApronLo, kSize));
    }
    if (b0.x > b1.x || b0.y > b1.y || b0.z > b1.z)
        return false;
    bool gained = false;
    glm::ivec3 e0(INT_MAX), e1(INT_MIN); // bricks that emptied out
    thread_local std::vector<uint8_t> maxima;
    regionMax(volume, b0, b1, maxima);
    const uint8_t* next = maxima.data();
    for (int z = b0.z; z <= b1.z; ++z)
        for (int y = b0.y; y <= b1.y; ++y) {
            size_t i = index({b0.x, y, z});
            for (int x = b0.x; x <= b1.x; ++x, ++i) {
                uint8_t m = *next++;
                bool was = m_max[i] >= kSurfaceDensity;
                bool now = m >= kSurfaceDensity;
                m_max[i] = m;
                // A brick below the iso-value was and stays without marked cells.
                if (now)
                    m_cells[i] = computeCellMask(volume, {x, y, z});
                else if (was)
                    m_cells[i] = 0;
                if (now && !was)
                    gained = true;
                else if (was && !now) {
                    e0 = glm::min(e0, glm::ivec3(x, y, z));
                    e1 = glm::max(e1, glm::ivec3(x, y, z));
                }
            }
        }
    if (gained) {
        computeDistances();
        computeRuns(glm::ivec3(0), m_dims - 1);
    } else if (e0.x <= e1.x) {
        computeRuns(e0, e1);
        // Recompute out to the distance a ray in the emptied box can use (half its widest extent
        // plus a margin, at most kMaxRegionGrowth), and there only as far as a distance can have
        // changed at all.
        const glm::ivec3 extent = e1 - e0 + 1;
        const int grow =
            std::clamp(std::max({extent.x, extent.y, extent.z}) / 2 + 2, 2, int(kMaxRegionGrowth));
        glm::ivec3 lo, hi;
        affectedBox(e0, e1, glm::max(e0 - grow, glm::ivec3(0)), glm::min(e1 + grow, m_dims - 1), lo,
                    hi);
        sweepDistances(lo, hi);
    }
    return gained;
}

void BrickGrid::affectedBox(glm::ivec3 e0, glm::ivec3 e1, glm::ivec3 cap0, glm::ivec3 cap1,
                            glm::ivec3& lo, glm::ivec3& hi) const {
    // Distances only grow when bricks empty, and only for a brick b whose old distance d(b) was
    // realised by an emptied brick e: d(b) = |b - e|, so d(b) >= s(b), its Chebyshev distance
    // to the emptied bricks' box [e0, e1]. Grow a box from [e0, e1] face by face until no brick
    // of the ring just outside it has d >= s. Then no brick beyond the ring changes either: a
    // shortest king-move path from e to such a brick leaves the box through a ring brick r,
    // and every brick on it has the old distance of its place on the path, so d(r) = |r - e| >=
    // s(r). The box stops at [cap0, cap1]: beyond it distances stay lower bounds. (With lower
    // bounds instead of exact distances the bricks left out keep lower bounds.)
    const glm::ivec3 n = m_dims;
    auto axisDist = [](int v, int a, int b) { return v < a ? a - v : v > b ? v - b : 0; };
    thread_local std::vector<uint8_t> sx;
    sx.resize(size_t(n.x));
    for (int x = 0; x < n.x; ++x)
        sx[x] = uint8_t(std::min(axisDist(x, e0.x, e1.x), int(kMaxDistance)));
    // Whether a brick of the slab [s0, s1] may change.
    auto mayChange = [&](glm::ivec3 s0, glm::ivec3 s1) {
        for (int z = s0.z; z <= s1.z; ++z)
            for (int y = s0.y; y <= s1.y; ++y) {
                const uint8_t c = uint8_t(std::min(
                    std::max(axisDist(z, e0.z, e1.z), axisDist(y, e0.y, e1.y)), int(kMaxDistance)));
                const uint8_t* d = &m_distance[index({0, y, z})];
                const uint8_t* t = sx.data();
                uint8_t any = 0;
                for (int x = s0.x; x <= s1.x; ++x)
                    any |= uint8_t(d[x] >= std::max(c, t[x]));
                if (any)
                    return true;
            }
        return false;
    };
    lo = e0;
    hi = e1;
    for (bool grew = true; grew;) {
        grew = false;
        for (int a = 0; a < 3; ++a)
            for (int side : {-1, 1})
                for (;;) {
                    const int p = side < 0 ? lo[a] - 1 : hi[a] + 1;
                    if (p < cap0[a] || p > cap1[a])
                        break;
                    glm::ivec3 s0 = glm::max(lo - 1, glm::ivec3(0));
                    glm::ivec3 s1 = glm::min(hi + 1, n - 1);
                    s0[a] = s1[a] = p;
                    if (!mayChange(s0, s1))
                        break;
                    (side < 0 ? lo[a] : hi[a]) = p;
                    grew = true;
                }
    }
}

void BrickGrid::computeDistances() {
    ++m_distancePasses;
    sweepDistances(glm::ivec3(0), m_dims - 1);
}

void BrickGrid::sweepDistances(glm::ivec3 lo, glm::ivec3 hi) {
    // The Chebyshev distance with sources: D(b) = min over bricks o of f(o) + |b - o|, with f = 0
    // for bricks that may hold surface in [lo, hi], the stored distances in the ring of bricks
    // just outside it (read, never written), and "none" elsewhere. Exact when the ring is:
    // a shortest path from the nearest occupied brick outside enters the box through the ring.
    // Computed by directional sweeps, each a plain minimum over whole slices or rows:
    //  - z cones: slice by slice, forward then backward, each brick takes 1 + the smallest of
    //    the 9 bricks around it in the previous slice. That covers every source o with
    //    |dz| >= |dx|, |dy| (the path steps one slice at a time and drifts at most one brick
    //    per step in x and y).
    //  - y cones: row by row the same, for |dy| >= |dx|, |dz|.
    //  - x lines: a source with |dx| > |dy|, |dz| is reached by max(|dy|, |dz|) diagonal steps
    //    (a path in a z or y cone, already swept) and then a straight run along x, which the
    //    last two passes add row by row (the only sequential part).
    // Every value is the length of some path from a source, so nothing drops below the true
    // distance, and the minimum over the cones is the distance. Bytes saturate at kMaxDistance.
    const glm::ivec3 ext = hi - lo + 3; // the box with its ring
    const int W = ext.x, H = ext.y, D = ext.z;
    const size_t S = size_t(W) * H; // bytes per slice
    thread_local std::vector<uint8_t> buf, tmp, tmp2, mask;
    buf.resize(S * D);
    tmp.resize(S);
    tmp2.resize(size_t(W));
    // Ring columns of a slice are never written: 255 there leaves them as they are.
    mask.assign(S, 0);
    for (int y = 0; y < H; ++y) {
        mask[size_t(y) * W] = kMaxDistance;
        mask[size_t(y) * W + W - 1] = kMaxDistance;
    }
    // Bricks outside the grid are sources of nothing (kMaxDistance).
    const int gx0 = std::max(lo.x - 1, 0), gx1 = std::min(hi.x + 1, m_dims.x - 1);
    for (int z = 0; z < D; ++z)
        for (int y = 0; y < H; ++y) {
            uint8_t* o = &buf[(size_t(z) * H + y) * W];
            const int gz = lo.z - 1 + z, gy = lo.y - 1 + y;
            std::fill(o, o + W, kMaxDistance);
            if (gz < 0 || gz >= m_dims.z || gy < 0 || gy >= m_dims.y)
                continue;
            const size_t i = index({0, gy, gz});
            uint8_t* ox = o + (gx0 - (lo.x - 1));
            if (z == 0 || z == D - 1 || y == 0 || y == H - 1) {
                std::copy(&m_distance[i + gx0], &m_distance[i + gx1 + 1], ox);
                continue;
            }
            sources(ox, &m_max[i + gx0], size_t(gx1 - gx0 + 1));
            if (lo.x > 0)
                o[0] = m_distance[i + lo.x - 1];
            if (hi.x + 1 < m_dims.x)
                o[W - 1] = m_distance[i + hi.x + 1];
        }
    auto inc = [](uint8_t v) { return uint8_t(v + (v != kMaxDistance)); };
    uint8_t* __restrict b = buf.data();
    uint8_t* __restrict t = tmp.data();
    uint8_t* __restrict t2 = tmp2.data();
    const uint8_t* mk = mask.data();
    // z cones.
    for (int dir : {1, -1})
        for (int k = 1; k < D - 1; ++k) {
            const int z = dir > 0 ? k : D - 1 - k;
            const uint8_t* prev = b + size_t(z - dir) * S;
            uint8_t* cur = b + size_t(z) * S;
            minOf3(t + 1, prev, prev + 1, prev + 2, S - 2);
            for (size_t i = W; i < S - W; ++i) {
                uint8_t m = std::min(std::min(t[i - W], t[i]), t[i + W]);
                cur[i] = std::min(cur[i], std::max(inc(m), mk[i]));
            }
        }
    // y cones.
    for (int dir : {1, -1})
        for (int k = 1; k < H - 1; ++k) {
            const int y = dir > 0 ? k : H - 1 - k;
            for (int z = 1; z < D - 1; ++z) {
                uint8_t* cur = b + (size_t(z) * H + y) * W;
                const uint8_t* p0 = b + (size_t(z - 1) * H + (y - dir)) * W;
                const uint8_t* p1 = p0 + S;
                const uint8_t* p2 = p1 + S;
                minOf3(t, p0, p1, p2, size_t(W));
                minOf3(t2, t, t + 1, t + 2, size_t(W - 2));
                lowerTo(cur + 1, t2, size_t(W - 2));
            }
        }
    // x lines.
    for (int z = 1; z < D - 1; ++z)
        for (int y = 1; y < H - 1; ++y) {
            uint8_t* r = b + (size_t(z) * H + y) * W;
            for (int x = 1; x < W - 1; ++x)
                r[x] = std::min(r[x], inc(r[x - 1]));
            for (int x = W - 2; x >= 1; --x)
                r[x] = std::min(r[x], inc(r[x + 1]));
        }
    for (int z = 1; z < D - 1; ++z)
        for (int y = 1; y < H - 1; ++y) {
            const uint8_t* r = b + (size_t(z) * H + y) * W + 1;
            std::copy(r, r + (W - 2), &m_distance[index({lo.x, lo.y + y - 1, lo.z + z - 1})]);
        }
}

} // namespace trephine

#include "libsim/brick_grid.h"

#include "libsim/volume.h"

#include <algorithm>
#include <climits>

namespace trephine {

namespace {

int floorDiv(int a, int b) {
    return a >= 0 ? a / b : -((-a + b - 1) / b);
}

} // namespace

void BrickGrid::regionMax(const Volume& volume, glm::ivec3 b0, glm::ivec3 b1,
                          std::vector<uint8_t>& out) const {
    // Separable maximum: along x per voxel row, then y, then z, each over a brick plus apron.
    const glm::ivec3 n = m_volumeDims;
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
    const int ny = v1.y - v0.y, nz = v1.z - v0.z;
    std::vector<uint8_t> mx(size_t(B.x) * ny * nz);
    // Along x: the maximum of 4 voxels from two pairwise passes over the row (vectorised), then
    // each brick's 4 voxels and its apron voxel; a brick cut short by the volume's edge directly.
    static_assert(kApronLo == 0 && kApronHi == 1 && kSize == 4, "the x pass reads 4 + 1 voxels");
    const int len = v1.x - v0.x;
    std::vector<uint8_t> m2(size_t(len) + 4), m4(size_t(len) + 4);
    for (int z = 0; z < nz; ++z)
        for (int y = 0; y < ny; ++y) {
            const uint8_t* row = d + volume.index(v0.x, v0.y + y, v0.z + z);
            uint8_t* o = &mx[(size_t(z) * ny + y) * B.x];
            for (int i = 0; i + 1 < len; ++i)
                m2[i] = std::max(row[i], row[i + 1]);
            for (int i = 0; i + 3 < len; ++i)
                m4[i] = std::max(m2[i], m2[i + 2]);
            for (int bx = 0; bx < B.x; ++bx) {
                auto [x0, x1] = range(b0.x + bx, n.x);
                o[bx] = x1 - x0 == kSize + kApronHi
                            ? std::max(m4[x0 - v0.x], row[x0 - v0.x + kSize])
                            : *std::max_element(row + (x0 - v0.x), row + (x1 - v0.x));
            }
        }
    std::vector<uint8_t> mxy(size_t(B.x) * B.y * nz);
    for (int z = 0; z < nz; ++z)
        for (int by = 0; by < B.y; ++by) {
            auto [y0, y1] = range(b0.y + by, n.y);
            uint8_t* o = &mxy[(size_t(z) * B.y + by) * B.x];
            std::fill(o, o + B.x, uint8_t(0));
            for (int y = y0; y < y1; ++y) {
                const uint8_t* in = &mx[(size_t(z) * ny + (y - v0.y)) * B.x];
                for (int bx = 0; bx < B.x; ++bx)
                    o[bx] = std::max(o[bx], in[bx]);
            }
        }
    out.assign(size_t(B.x) * B.y * B.z, 0);
    for (int bz = 0; bz < B.z; ++bz) {
        auto [z0, z1] = range(b0.z + bz, n.z);
        uint8_t* o = &out[size_t(bz) * B.y * B.x];
        for (int z = z0; z < z1; ++z) {
            const uint8_t* in = &mxy[size_t(z - v0.z) * B.y * B.x];
            for (size_t i = 0; i < size_t(B.y) * B.x; ++i)
                o[i] = std::max(o[i], in[i]);
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
    computeDistances();
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
    // Brick b covers voxels [8b - apronLo, 8b + 8 + apronHi): it overlaps [lo, hi) when
    // 8b + 8 + apronHi > lo and 8b - apronLo < hi.
    glm::ivec3 b0, b1;
    for (int a = 0; a < 3; ++a) {
        b0[a] = std::max(0, floorDiv(box.lo[a] - kSize - kApronHi, kSize) + 1);
        b1[a] = std::min(m_dims[a] - 1, floorDiv(box.hi[a] - 1 + kApronLo, kSize));
    }
    if (b0.x > b1.x || b0.y > b1.y || b0.z > b1.z)
        return false;
    bool gained = false;
    glm::ivec3 e0(INT_MAX), e1(INT_MIN); // bricks that emptied out
    std::vector<uint8_t> maxima;
    regionMax(volume, b0, b1, maxima);
    const uint8_t* next = maxima.data();
    for (int z = b0.z; z <= b1.z; ++z)
        for (int y = b0.y; y <= b1.y; ++y)
            for (int x = b0.x; x <= b1.x; ++x) {
                size_t i = index({x, y, z});
                uint8_t m = *next++;
                bool was = m_max[i] >= kSurfaceDensity;
                bool now = m >= kSurfaceDensity;
                m_max[i] = m;
                m_cells[i] = now ? computeCellMask(volume, {x, y, z}) : 0;
                if (now && !was)
                    gained = true;
                else if (was && !now) {
                    e0 = glm::min(e0, glm::ivec3(x, y, z));
                    e1 = glm::max(e1, glm::ivec3(x, y, z));
                }
            }
    if (gained) {
        computeDistances();
    } else if (e0.x <= e1.x) {
        // Distances only grow when bricks empty. Left at small lower bounds, a hole's bricks make
        // every ray through it step brick by brick; recompute them, and the bricks around whose
        // nearest surface may have been in the hole, out to the distance a ray in the emptied
        // box can use: half its widest extent, plus a margin.
        const glm::ivec3 extent = e1 - e0 + 1;
        const int grow =
            std::clamp(std::max({extent.x, extent.y, extent.z}) / 2 + 2, 2, int(kMaxRegionGrowth));
        computeDistances(glm::max(e0 - grow, glm::ivec3(0)), glm::min(e1 + grow, m_dims - 1));
    }
    return gained;
}

void BrickGrid::computeDistances() {
    ++m_distancePasses;
    m_distance.assign(m_max.size(), kMaxDistance);
    computeDistances(glm::ivec3(0), m_dims - 1);
}

void BrickGrid::computeDistances(glm::ivec3 lo, glm::ivec3 hi) {
    // Two-pass chamfer transform with the 26-neighbourhood and unit weights over the bricks
    // [lo, hi]; bricks outside the box are read, never written. On the whole grid this is the
    // exact Chebyshev (chessboard) distance to the nearest occupied brick. On a box it is
    // min(distance to the nearest occupied brick in the box, min over bricks k just outside it of
    // distance(k) + |k - b|): every king-move path from an occupied brick that moves monotonically
    // towards b (a shortest one exists, and the two passes follow one) enters the box once, from a
    // brick just outside it, so with the outside holding lower bounds the result is a lower bound,
    // exact where the nearest surface is in the box or the outside is exact.
    const glm::ivec3 B = m_dims;
    for (int z = lo.z; z <= hi.z; ++z)
        for (int y = lo.y; y <= hi.y; ++y)
            for (int x = lo.x; x <= hi.x; ++x) {
                size_t i = index({x, y, z});
                m_distance[i] = m_max[i] >= kSurfaceDensity ? 0 : kMaxDistance;
            }
    // Row by row: the neighbours already visited in scan order are the three rows of the previous
    // z slice around this row, the previous row of this slice (each at x - 1, x, x + 1), and the
    // previous brick of this row. The rows' part is a plain minimum over whole rows (vectorised);
    // only the last is sequential.
    const int x0 = std::max(lo.x - 1, 0), x1 = std::min(hi.x + 1, B.x - 1); // with the ring
    const int w = x1 - x0 + 1;
    std::vector<uint8_t> near(size_t(w) + 2);
    auto inc = [](uint8_t v) { return uint8_t(v + (v != kMaxDistance)); };
    auto pass = [&](int sign) {
        int zs = sign > 0 ? lo.z : hi.z, ze = sign > 0 ? hi.z + 1 : lo.z - 1;
        int ys = sign > 0 ? lo.y : hi.y, ye = sign > 0 ? hi.y + 1 : lo.y - 1;
        for (int z = zs; z != ze; z += sign)
            for (int y = ys; y != ye; y += sign) {
                // near[1 + x - x0]: the smallest visited neighbour distance above x, from the rows;
                // near[0] and near[w + 1] pad the grid's edges.
                std::fill(near.begin(), near.end(), kMaxDistance);
                uint8_t* m = near.data() + 1;
                auto row = [&](int ry, int rz) {
                    if (ry < 0 || ry >= B.y || rz < 0 || rz >= B.z)
                        return;
                    const uint8_t* r = &m_distance[index({x0, ry, rz})];
                    for (int i = 0; i < w; ++i)
                        m[i] = std::min(m[i], r[i]);
                };
                row(y - 1, z - sign);
                row(y, z - sign);
                row(y + 1, z - sign);
                row(y - sign, z);
                // Widen by one brick either way (x - 1 and x + 1), then one step further away.
                uint8_t prev = kMaxDistance;
                for (int i = 0; i < w; ++i) {
                    uint8_t here = m[i];
                    m[i] = inc(std::min({prev, here, m[i + 1]}));
                    prev = here;
                }
                uint8_t* d = &m_distance[index({0, y, z})];
                const int xs = sign > 0 ? lo.x : hi.x, xe = sign > 0 ? hi.x + 1 : lo.x - 1;
                uint8_t last = (xs - sign >= 0 && xs - sign < B.x) ? d[xs - sign] : kMaxDistance;
                for (int x = xs; x != xe; x += sign) {
                    uint8_t v = std::min({d[x], m[x - x0], inc(last)});
                    d[x] = v;
                    last = v;
                }
            }
    };
    pass(+1);
    pass(-1);
}

} // namespace trephine

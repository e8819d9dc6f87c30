#include "libsim/brick_grid.h"

#include "libsim/volume.h"

#include <algorithm>

namespace trephine {

namespace {

int floorDiv(int a, int b) {
    return a >= 0 ? a / b : -((-a + b - 1) / b);
}

} // namespace

void BrickGrid::build(const Volume& volume) {
    glm::ivec3 n = volume.dims();
    m_volumeDims = n;
    m_dims = (n + (kSize - 1)) / kSize;
    const glm::ivec3 B = m_dims;
    const uint8_t* d = volume.densityData();

    // Separable maximum: along x per voxel row, then y, then z, each over a brick plus apron.
    auto range = [](int b, int limit) {
        return std::pair{std::max(0, b * kSize - kApronLo),
                         std::min(limit, b * kSize + kSize + kApronHi)};
    };
    std::vector<uint8_t> mx(size_t(B.x) * n.y * n.z);
    for (int z = 0; z < n.z; ++z)
        for (int y = 0; y < n.y; ++y) {
            const uint8_t* row = d + volume.index(0, y, z);
            uint8_t* out = &mx[(size_t(z) * n.y + y) * B.x];
            for (int bx = 0; bx < B.x; ++bx) {
                auto [x0, x1] = range(bx, n.x);
                out[bx] = *std::max_element(row + x0, row + x1);
            }
        }
    std::vector<uint8_t> mxy(size_t(B.x) * B.y * n.z);
    for (int z = 0; z < n.z; ++z)
        for (int by = 0; by < B.y; ++by) {
            auto [y0, y1] = range(by, n.y);
            uint8_t* out = &mxy[(size_t(z) * B.y + by) * B.x];
            std::fill(out, out + B.x, uint8_t(0));
            for (int y = y0; y < y1; ++y) {
                const uint8_t* in = &mx[(size_t(z) * n.y + y) * B.x];
                for (int bx = 0; bx < B.x; ++bx)
                    out[bx] = std::max(out[bx], in[bx]);
            }
        }
    m_max.assign(size_t(B.x) * B.y * B.z, 0);
    for (int bz = 0; bz < B.z; ++bz) {
        auto [z0, z1] = range(bz, n.z);
        uint8_t* out = &m_max[size_t(bz) * B.y * B.x];
        for (int z = z0; z < z1; ++z) {
            const uint8_t* in = &mxy[size_t(z) * B.y * B.x];
            for (size_t i = 0; i < size_t(B.y) * B.x; ++i)
                out[i] = std::max(out[i], in[i]);
        }
    }
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

uint8_t BrickGrid::brickMax(const Volume& volume, glm::ivec3 b) const {
    glm::ivec3 lo = glm::max(b * kSize - kApronLo, glm::ivec3(0));
    glm::ivec3 hi = glm::min(b * kSize + kSize + kApronHi, m_volumeDims);
    const uint8_t* d = volume.densityData();
    uint8_t m = 0;
    for (int z = lo.z; z < hi.z; ++z)
        for (int y = lo.y; y < hi.y; ++y) {
            const uint8_t* row = d + volume.index(0, y, z);
            for (int x = lo.x; x < hi.x; ++x)
                m = std::max(m, row[x]);
        }
    return m;
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
    bool gained = false;
    for (int z = b0.z; z <= b1.z; ++z)
        for (int y = b0.y; y <= b1.y; ++y)
            for (int x = b0.x; x <= b1.x; ++x) {
                size_t i = index({x, y, z});
                uint8_t m = brickMax(volume, {x, y, z});
                bool was = m_max[i] >= kSurfaceDensity;
                bool now = m >= kSurfaceDensity;
                m_max[i] = m;
                m_cells[i] = now ? computeCellMask(volume, {x, y, z}) : 0;
                if (now && !was)
                    gained = true;
                else if (was && !now)
                    m_distance[i] = 1; // empty itself; neighbours unknown, so no larger claim
            }
    if (gained)
        computeDistances();
    return gained;
}

void BrickGrid::computeDistances() {
    // Two-pass chamfer transform with the 26-neighbourhood and unit weights: exact Chebyshev
    // (chessboard) distance to the nearest occupied brick.
    ++m_distancePasses;
    const glm::ivec3 B = m_dims;
    m_distance.assign(m_max.size(), kMaxDistance);
    for (size_t i = 0; i < m_max.size(); ++i)
        if (m_max[i] >= kSurfaceDensity)
            m_distance[i] = 0;
    auto pass = [&](int sign) {
        int zs = sign > 0 ? 0 : B.z - 1, ze = sign > 0 ? B.z : -1;
        int ys = sign > 0 ? 0 : B.y - 1, ye = sign > 0 ? B.y : -1;
        int xs = sign > 0 ? 0 : B.x - 1, xe = sign > 0 ? B.x : -1;
        for (int z = zs; z != ze; z += sign)
            for (int y = ys; y != ye; y += sign)
                for (int x = xs; x != xe; x += sign) {
                    uint8_t& d = m_distance[index({x, y, z})];
                    if (d == 0)
                        continue;
                    int best = d;
                    // Neighbours already visited in this scan order: the previous z slice, the
                    // previous row of this slice, and the previous brick of this row.
                    for (int dz = -1; dz <= 0; ++dz)
                        for (int dy = -1; dy <= 1; ++dy)
                            for (int dx = -1; dx <= 1; ++dx) {
                                if (dz == 0 && (dy > 0 || (dy == 0 && dx >= 0)))
                                    continue;
                                int nx = x + sign * dx, ny = y + sign * dy, nz = z + sign * dz;
                                if (nx < 0 || ny < 0 || nz < 0 || nx >= B.x || ny >= B.y ||
                                    nz >= B.z)
                                    continue;
                                best = std::min(best, m_distance[index({nx, ny, nz})] + 1);
                            }
                    d = uint8_t(std::min(best, int(kMaxDistance)));
                }
    };
    pass(+1);
    pass(-1);
}

} // namespace trephine

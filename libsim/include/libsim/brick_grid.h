// Empty-space skipping for the ray caster: the largest density each 4^3 brick of voxels (plus an
// apron) can show a trilinear sample, the Chebyshev distance, in bricks, to the nearest brick
// that may hold surface, and per brick a bit per trilinear cell that may reach the iso-value.
// Built once; after erosion only the bricks near the changed box update.
#pragma once

#include "libsim/box.h"

#include <array>
#include <cstdint>
#include <glm/vec3.hpp>
#include <vector>

namespace trephine {

class Volume;

class BrickGrid {
public:
    static constexpr int kShift = 2;          // 4^3 bricks: 8^3 measured no faster, and skips less
    static constexpr int kSize = 1 << kShift; // voxels per brick edge
    // A brick's maximum covers voxels [kSize*b - kApronLo, kSize*b + kSize + kApronHi) per axis.
    // A sample whose floor lies in the brick reads voxels floor and floor + 1 (trilinear), so one
    // voxel on the high side is needed. Float rounding of sample positions near a brick face needs
    // no more: a position off by d voxels changes the field by at most 765 d, well under 1 for
    // the rounding the renderer allows, and an empty brick's field is at most 127 (see
    // docs/rendering.md).
    static constexpr int kApronLo = 0;
    static constexpr int kApronHi = 1;
    static constexpr uint8_t kMaxDistance = 255;
    // After erosion, distances are recomputed at most out to the emptied bricks' box grown by half
    // its widest extent plus 2, at most this many bricks.
    static constexpr int kMaxRegionGrowth = 32;

    BrickGrid() = default;
    explicit BrickGrid(const Volume& volume) { build(volume); }

    // Computes every brick from scratch.
    void build(const Volume& volume);
    // Recomputes the bricks whose apron overlaps `changed` (voxels whose density changed). When
    // bricks only empty out (drilling), only the distances that went through an emptied brick are
    // recomputed: over the box of bricks whose distance may have grown, cut to the emptied
    // bricks' box grown by half its widest extent plus 2: exact there as far as that reaches, and
    // valid lower bounds everywhere. A brick that gains surface triggers a full distance pass.
    // Returns true when some brick gained surface (or the grid was rebuilt): not erosion.
    bool update(const Volume& volume, const Box3i& changed);

    glm::ivec3 dims() const { return m_dims; } // bricks per axis
    bool empty() const { return m_max.empty(); }
    size_t index(glm::ivec3 b) const {
        return size_t(b.x) + size_t(m_dims.x) * (size_t(b.y) + size_t(m_dims.y) * size_t(b.z));
    }
    // Largest density of the brick with its apron.
    uint8_t maxDensity(glm::ivec3 b) const { return m_max[index(b)]; }
    bool occupied(glm::ivec3 b) const { return m_distance[index(b)] == 0; }
    // 0 for a brick that may hold surface; d > 0: every brick within Chebyshev distance d - 1
    // is empty. Exact after build(); after update() a lower bound, exact near the emptied bricks.
    uint8_t distance(glm::ivec3 b) const { return m_distance[index(b)]; }
    const uint8_t* distanceData() const { return m_distance.data(); }
    // Bit (x + 4 y + 16 z) is set when the trilinear cell whose lowest corner is voxel
    // 4 b + (x, y, z) has a corner at or above kSurfaceDensity (voxels outside the volume are
    // air): a sample in a clear cell is below the iso-value without reading the volume.
    uint64_t cellMask(glm::ivec3 b) const { return m_cells[index(b)]; }
    const uint64_t* cellData() const { return m_cells.data(); }
    const std::vector<uint8_t>& maxData() const { return m_max; }
    // Runs of empty bricks along an axis: how many bricks from b on, b included, going along
    // `axis` (0 x, 1 y, 2 z) towards + (`positive`) or -, are empty in a row (0 when b may hold
    // surface; saturating at kMaxDistance). A ray moving mostly along that axis can leap to the
    // end of its column of empty bricks, where the distance cube ends sooner (beside a wall along
    // the ray). Exact after build() and update() (erosion only ever lengthens runs, and update()
    // recomputes the lines through the bricks that emptied).
    uint8_t run(glm::ivec3 b, int axis, bool positive) const {
        return m_runs[size_t(2 * axis + positive)][index(b)];
    }
    const uint8_t* runData(int axis, bool positive) const {
        return m_runs[size_t(2 * axis + positive)].data();
    }
    int64_t fullDistancePasses() const { return m_distancePasses; }

    // Largest density of each brick of [b0, b1] (brick coordinates, inclusive) of `volume` with
    // its apron, x fastest: the maximum maxDensity() holds (a GPU ray caster's skipping uses it
    // too, ui/volume_view.cpp).
    static void regionMax(const Volume& volume, glm::ivec3 b0, glm::ivec3 b1,
                          std::vector<uint8_t>& out);

private:
    // A full distance pass over the grid.
    void computeDistances();
    // After the bricks in [e0, e1] (some of them) emptied out: a box [lo, hi] outside of which no
    // distance can change, or where that reaches beyond [cap0, cap1], cut to it.
    void affectedBox(glm::ivec3 e0, glm::ivec3 e1, glm::ivec3 cap0, glm::ivec3 cap1, glm::ivec3& lo,
                     glm::ivec3& hi) const;
    // Recomputes the distances of the bricks [lo, hi] (inclusive) from the bricks that may hold
    // surface there and the stored distances of the bricks just outside.
    void sweepDistances(glm::ivec3 lo, glm::ivec3 hi);
    uint64_t computeCellMask(const Volume& volume, glm::ivec3 b) const;
    // The runs of every line along each axis through the bricks [lo, hi] (inclusive), whole.
    void computeRuns(glm::ivec3 lo, glm::ivec3 hi);

    glm::ivec3 m_dims{0};
    glm::ivec3 m_volumeDims{0};
    std::vector<uint8_t> m_max;
    std::vector<uint8_t> m_distance;
    std::vector<uint64_t> m_cells;
    std::array<std::vector<uint8_t>, 6> m_runs; // [2 axis + positive]
    int64_t m_distancePasses = 0;
};

} // namespace trephine

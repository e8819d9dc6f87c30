// Distance fields of the critical structures (dura, sinus, artery, ...): for any point, how far
// (mm) the nearest voxel of a structure lies. Built once at load by an exact Euclidean distance
// transform and stored in 8^3 bricks, uniform bricks as one value, so the server can grade every
// tool state's closest approach in well under a microsecond per structure. docs/assessment.md.
#pragma once

#include "libsim/thread_pool.h"
#include "libsim/tool.h"
#include "libsim/volume.h"

#include <cstddef>
#include <cstdint>
#include <glm/vec3.hpp>
#include <string>
#include <vector>

namespace trephine {

// A structure a craniotomy must spare: a name and the material labels it is made of (a bit per
// Material).
struct CriticalStructure {
    std::string name;
    uint32_t materials = 0;
    bool has(Material m) const { return (materials >> unsigned(m)) & 1u; }
};

// Every soft-tissue label is a structure, named after its material, so a new label needs no
// change here; the brain lies below the dura and counts as dura (a cutter in the brain has gone
// through the dura).
std::vector<CriticalStructure> criticalStructures();

// One structure's distance field: the exact Euclidean distance (mm, anisotropic spacing honoured)
// from each voxel centre to the nearest voxel centre of the structure, clamped at clampMm and kept
// in 1/256 mm. Between voxel centres it is interpolated trilinearly (within a voxel diagonal of
// exact); outside the volume it is the distance to the volume's edge combined with the edge's
// value (a lower bound: the structures lie inside).
class DistanceField {
public:
    static constexpr float kDefaultClampMm = 20.0f;
    static constexpr float kMaxClampMm = 255.0f;
    static constexpr int kBrick = 8;

    DistanceField() = default;
    // `materials`: a bit per Material that belongs to the structure. clampMm in (0, kMaxClampMm].
    // `pool` (optional) spreads the transform's rows over its threads.
    DistanceField(const Volume& volume, uint32_t materials, float clampMm = kDefaultClampMm,
                  ThreadPool* pool = nullptr);

    // Distance (mm) from an object-space point to the structure, at most clampMm().
    float at(glm::vec3 pMm) const;
    // At a voxel centre (inside the volume).
    float atVoxel(glm::ivec3 v) const;

    float clampMm() const { return m_clampMm; }
    // No voxel of the structure in the volume: every value is the clamp.
    bool empty() const { return m_empty; }
    glm::ivec3 dims() const { return m_dims; }
    // Bytes held: the brick table and the dense bricks.
    size_t bytes() const { return m_table.size() * sizeof(uint32_t) + m_pool.size() * 2; }
    size_t denseBricks() const { return m_pool.size() / (kBrick * kBrick * kBrick); }
    size_t brickCount() const { return m_table.size(); }

private:
    uint16_t raw(int x, int y, int z) const;
    float interpolate(glm::vec3 v) const;

    glm::ivec3 m_dims{0};
    glm::ivec3 m_bricks{0};
    glm::vec3 m_spacing{1.0f};
    float m_clampMm = kDefaultClampMm;
    bool m_empty = true;
    // Per brick: kUniform | value, or the offset of its 512 values in m_pool.
    std::vector<uint32_t> m_table;
    std::vector<uint16_t> m_pool;
};

// Every critical structure present in a volume with its field, built at load.
class StructureFields {
public:
    StructureFields() = default;
    StructureFields(const Volume& volume, float clampMm = DistanceField::kDefaultClampMm,
                    ThreadPool* pool = nullptr);

    size_t size() const { return m_structures.size(); }
    const CriticalStructure& structure(size_t i) const { return m_structures[i]; }
    const DistanceField& field(size_t i) const { return m_fields[i]; }
    // Index of the structure holding material m, or -1.
    int structureOf(Material m) const;

    // The cutter's closest approach to structure i (mm; <= 0 where it reaches a voxel centre of
    // it). A burr's is the field at its centre less its radius (exact to the interpolation). The
    // perforator's is the least, over points along its axis half a millimetre apart, of the field
    // there less the cutter's radius near that height and a quarter millimetre: a lower bound,
    // loose by up to that radius (it warns early, never late).
    float closestApproach(size_t i, const ToolShape& shape, const ToolPose& pose) const;

    double buildMs() const { return m_buildMs; }
    size_t bytes() const;

private:
    std::vector<CriticalStructure> m_structures;
    std::vector<DistanceField> m_fields;
    double m_buildMs = 0.0;
};

} // namespace trephine

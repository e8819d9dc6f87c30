// The voxel volume: a density byte and a material byte per voxel, with dimensions and spacing in
// millimetres, centred on its local origin. This is the only copy of the skull the server holds.
#pragma once

#include "libsim/box.h"

#include <cassert>
#include <cstddef>
#include <cstdint>
#include <glm/vec3.hpp>
#include <string>
#include <string_view>
#include <vector>

namespace trephine {

// Material labels. Bone materials (cortical, diploe) can be drilled; the soft tissues below them
// (dura, brain and the critical structures a craniotomy must spare) cannot, and report a violation
// when a cutter touches them. Every label from Dura up is soft tissue.
enum class Material : uint8_t {
    Air = 0,
    Cortical = 1, // outer and inner tables
    Diploe = 2,   // porous cancellous bone between the tables
    Dura = 3,
    Brain = 4,
    Sinus = 5,  // the superior sagittal sinus, in the midline under the inner table
    Artery = 6, // the middle meningeal artery and its branches, in grooves of the inner table
    Count
};
inline constexpr int kMaterialCount = int(Material::Count);
std::string_view materialName(Material m);
inline bool isBone(Material m) {
    return m == Material::Cortical || m == Material::Diploe;
}
inline bool isSoftTissue(Material m) {
    return m >= Material::Dura && m < Material::Count;
}

// Density at or above which a voxel is solid: the iso-value of the rendered surface and of haptic
// contact.
inline constexpr uint8_t kSurfaceDensity = 128;

class Volume {
public:
    Volume() = default;
    // All voxels start as air (density 0). Dimensions must be positive; spacing in mm per voxel.
    Volume(glm::ivec3 dims, glm::vec3 spacingMm);
    // Takes the voxels (x fastest, dims.x * dims.y * dims.z of each; material labels below
    // kMaterialCount) without copying them: a loader's buffers become the volume.
    Volume(glm::ivec3 dims, glm::vec3 spacingMm, std::vector<uint8_t> density,
           std::vector<uint8_t> material);

    glm::ivec3 dims() const { return m_dims; }
    glm::vec3 spacing() const { return m_spacing; }
    void setSpacing(glm::vec3 s) { m_spacing = s; }
    size_t voxelCount() const { return m_density.size(); }
    bool empty() const { return m_density.empty(); }
    // Physical extent in mm (dims * spacing).
    glm::vec3 extentMm() const { return glm::vec3(m_dims) * m_spacing; }
    Box3i bounds() const { return {glm::ivec3(0), m_dims}; }

    bool inside(glm::ivec3 v) const {
        return v.x >= 0 && v.y >= 0 && v.z >= 0 && v.x < m_dims.x && v.y < m_dims.y &&
               v.z < m_dims.z;
    }
    // Linear index, x fastest: x + nx * (y + ny * z).
    size_t index(int x, int y, int z) const {
        assert(inside({x, y, z}) && "voxel index out of the volume");
        return size_t(x) + size_t(m_dims.x) * (size_t(y) + size_t(m_dims.y) * size_t(z));
    }
    size_t index(glm::ivec3 v) const { return index(v.x, v.y, v.z); }

    uint8_t density(int x, int y, int z) const { return m_density[index(x, y, z)]; }
    Material material(int x, int y, int z) const { return Material(m_material[index(x, y, z)]); }
    void set(int x, int y, int z, uint8_t density, Material m) {
        size_t i = index(x, y, z);
        m_density[i] = density;
        m_material[i] = uint8_t(m);
    }
    // Sets every voxel of `box` (clipped to the volume) to density and material, row by row.
    void fill(const Box3i& box, uint8_t density, Material m);
    // The density and material bytes of every voxel of `box` (inside the volume), x fastest: what
    // putting the box back takes (SessionServer::submitVoxels).
    void copyBox(const Box3i& box, std::vector<uint8_t>& density,
                 std::vector<uint8_t>& material) const;

    uint8_t* densityData() { return m_density.data(); }
    const uint8_t* densityData() const { return m_density.data(); }
    uint8_t* materialData() { return m_material.data(); }
    const uint8_t* materialData() const { return m_material.data(); }

    // Object-space position (mm) of a voxel centre: (v + 0.5 - dims / 2) * spacing. The volume is
    // centred on its local origin; voxel axes map to +x, +y, +z.
    glm::vec3 voxelCenter(glm::ivec3 v) const {
        return (glm::vec3(v) + 0.5f - glm::vec3(m_dims) * 0.5f) * m_spacing;
    }
    // Continuous voxel coordinate of an object-space point (voxel centres sit at integers).
    glm::vec3 toVoxel(glm::vec3 pMm) const {
        return pMm / m_spacing + glm::vec3(m_dims) * 0.5f - 0.5f;
    }

    // Number of voxels per material label (drilled-out voxels are relabelled air).
    std::vector<int64_t> materialCounts() const;

    bool operator==(const Volume& o) const {
        return m_dims == o.m_dims && m_spacing == o.m_spacing && m_density == o.m_density &&
               m_material == o.m_material;
    }

private:
    glm::ivec3 m_dims{0};
    glm::vec3 m_spacing{1.0f};
    std::vector<uint8_t> m_density;
    std::vector<uint8_t> m_material;
};

} // namespace trephine

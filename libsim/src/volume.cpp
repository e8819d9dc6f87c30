#include "libsim/volume.h"

#include <cstring>

namespace trephine {

std::string_view materialName(Material m) {
    switch (m) {
    case Material::Air:
        return "air";
    case Material::Cortical:
        return "cortical";
    case Material::Diploe:
        return "diploe";
    case Material::Dura:
        return "dura";
    case Material::Brain:
        return "brain";
    case Material::Sinus:
        return "sinus";
    case Material::Artery:
        return "artery";
    default:
        return "unknown";
    }
}

Volume::Volume(glm::ivec3 dims, glm::vec3 spacingMm) : m_dims(dims), m_spacing(spacingMm) {
    assert(dims.x > 0 && dims.y > 0 && dims.z > 0 && "Volume dimensions must be positive");
    size_t n = size_t(dims.x) * size_t(dims.y) * size_t(dims.z);
    m_density.assign(n, 0);
    m_material.assign(n, uint8_t(Material::Air));
}

Volume::Volume(glm::ivec3 dims, glm::vec3 spacingMm, std::vector<uint8_t> density,
               std::vector<uint8_t> material)
    : m_dims(dims), m_spacing(spacingMm), m_density(std::move(density)),
      m_material(std::move(material)) {
    assert(dims.x > 0 && dims.y > 0 && dims.z > 0 && "Volume dimensions must be positive");
    assert(m_density.size() == size_t(dims.x) * size_t(dims.y) * size_t(dims.z) &&
           m_material.size() == m_density.size() && "Volume: one density and label a voxel");
}

std::vector<int64_t> Volume::materialCounts() const {
    // Labels past the known ones are counted as air; loaders never produce them.
    std::vector<int64_t> counts(kMaterialCount, 0);
    for (uint8_t m : m_material)
        counts[m < kMaterialCount ? m : 0]++;
    return counts;
}

void Volume::copyBox(const Box3i& box, std::vector<uint8_t>& density,
                     std::vector<uint8_t>& material) const {
    assert(box.intersect(bounds()) == box && "Volume::copyBox: the box must lie inside the volume");
    density.clear();
    material.clear();
    density.reserve(size_t(box.count()));
    material.reserve(size_t(box.count()));
    for (int z = box.lo.z; z < box.hi.z; ++z)
        for (int y = box.lo.y; y < box.hi.y; ++y) {
            const size_t i = index(box.lo.x, y, z), row = size_t(box.hi.x - box.lo.x);
            density.insert(density.end(), m_density.begin() + ptrdiff_t(i),
                           m_density.begin() + ptrdiff_t(i + row));
            material.insert(material.end(), m_material.begin() + ptrdiff_t(i),
                            m_material.begin() + ptrdiff_t(i + row));
        }
}

void Volume::fill(const Box3i& box, uint8_t density, Material m) {
    const Box3i b = box.intersect(bounds());
    if (b.empty())
        return;
    const size_t row = size_t(b.hi.x - b.lo.x);
    for (int z = b.lo.z; z < b.hi.z; ++z)
        for (int y = b.lo.y; y < b.hi.y; ++y) {
            const size_t i = index(b.lo.x, y, z);
            std::memset(m_density.data() + i, density, row);
            std::memset(m_material.data() + i, uint8_t(m), row);
        }
}

} // namespace trephine

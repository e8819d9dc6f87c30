#include "libsim/distance_field.h"

#include "libsim/error.h"

#include <algorithm>
#include <cassert>
#include <chrono>
#include <cmath>
#include <limits>

namespace trephine {

namespace {

constexpr float kUnitsPerMm = 256.0f;
constexpr uint32_t kUniform = 0x80000000u;
constexpr float kFar = 1e20f; // "no site here" for the transform (squared mm)

// The Felzenszwalb-Huttenlocher 1D transform: d[q] = min_p (w (q - p))^2 + f[p], the lower
// envelope of parabolas in linear time. f and d are `n` samples `stride` apart in `data` (in
// place, through the scratch `f`); v and z are scratch.
void transform1d(float* data, size_t stride, int n, float w2, std::vector<float>& f,
                 std::vector<int>& v, std::vector<double>& z) {
    f.resize(size_t(n));
    v.resize(size_t(n));
    z.resize(size_t(n) + 1);
    for (int i = 0; i < n; ++i)
        f[size_t(i)] = data[size_t(i) * stride];
    int k = 0;
    v[0] = 0;
    z[0] = -std::numeric_limits<double>::infinity();
    z[1] = std::numeric_limits<double>::infinity();
    auto meet = [&](int q, int p) {
        return ((double(f[size_t(q)]) + double(w2) * q * q) -
                (double(f[size_t(p)]) + double(w2) * p * p)) /
               (2.0 * double(w2) * (q - p));
    };
    for (int q = 1; q < n; ++q) {
        // z[0] is -infinity and every meeting point finite (kFar, not infinity, marks no site),
        // so k never drops below 0.
        double s = meet(q, v[size_t(k)]);
        while (s <= z[size_t(k)])
            s = meet(q, v[size_t(--k)]);
        ++k;
        v[size_t(k)] = q;
        z[size_t(k)] = s;
        z[size_t(k) + 1] = std::numeric_limits<double>::infinity();
    }
    k = 0;
    for (int q = 0; q < n; ++q) {
        while (z[size_t(k) + 1] < q)
            ++k;
        const int p = v[size_t(k)];
        data[size_t(q) * stride] = std::min(kFar, w2 * float((q - p) * (q - p)) + f[size_t(p)]);
    }
}

void forItems(ThreadPool* pool, int count, const std::function<void(int)>& fn) {
    if (pool)
        pool->parallelFor(count, fn);
    else
        for (int i = 0; i < count; ++i)
            fn(i);
}

} // namespace

std::vector<CriticalStructure> criticalStructures() {
    std::vector<CriticalStructure> out;
    for (int m = 0; m < kMaterialCount; ++m) {
        const Material mat = Material(m);
        if (!isSoftTissue(mat) || mat == Material::Brain)
            continue;
        CriticalStructure s{std::string(materialName(mat)), 1u << unsigned(m)};
        if (mat == Material::Dura)
            s.materials |= 1u << unsigned(Material::Brain);
        out.push_back(std::move(s));
    }
    return out;
}

// [SECTION] DistanceField

DistanceField::DistanceField(const Volume& volume, uint32_t materials, float clampMm,
                             ThreadPool* pool)
    : m_dims(volume.dims()), m_spacing(volume.spacing()), m_clampMm(clampMm) {
    if (!(clampMm > 0.0f && clampMm <= kMaxClampMm))
        throw Error("distance field: the clamp must be in (0, 255] mm, not " +
                    std::to_string(clampMm));
    const glm::ivec3 d = m_dims;
    const size_t nx = size_t(d.x), nxy = size_t(d.x) * size_t(d.y);
    std::vector<float> g(volume.voxelCount());
    const uint8_t* mat = volume.materialData();
    m_empty = true;
    for (size_t i = 0; i < g.size(); ++i) {
        const bool site = (materials >> mat[i]) & 1u;
        g[i] = site ? 0.0f : kFar;
        m_empty = m_empty && !site;
    }
    if (!m_empty) {
        const float wx = m_spacing.x * m_spacing.x, wy = m_spacing.y * m_spacing.y,
                    wz = m_spacing.z * m_spacing.z;
        // Along x, then y (each slice on its own), then z (columns, a row of them an item).
        forItems(pool, d.z, [&](int z) {
            std::vector<float> f;
            std::vector<int> v;
            std::vector<double> zs;
            for (int y = 0; y < d.y; ++y)
                transform1d(&g[size_t(z) * nxy + size_t(y) * nx], 1, d.x, wx, f, v, zs);
            for (int x = 0; x < d.x; ++x)
                transform1d(&g[size_t(z) * nxy + size_t(x)], nx, d.y, wy, f, v, zs);
        });
        forItems(pool, d.y, [&](int y) {
            std::vector<float> f;
            std::vector<int> v;
            std::vector<double> zs;
            for (int x = 0; x < d.x; ++x)
                transform1d(&g[size_t(y) * nx + size_t(x)], nxy, d.z, wz, f, v, zs);
        });
    }
    // Bricks: uniform ones (inside the structure, or beyond the clamp) keep one value.
    const auto clampUnits = uint16_t(std::lround(clampMm * kUnitsPerMm));
    m_bricks = (d + kBrick - 1) / kBrick;
    m_table.assign(size_t(m_bricks.x) * size_t(m_bricks.y) * size_t(m_bricks.z), 0);
    std::vector<uint16_t> brick(kBrick * kBrick * kBrick);
    size_t b = 0;
    for (int bz = 0; bz < m_bricks.z; ++bz)
        for (int by = 0; by < m_bricks.y; ++by)
            for (int bx = 0; bx < m_bricks.x; ++bx, ++b) {
                bool uniform = true;
                for (int k = 0; k < kBrick; ++k)
                    for (int j = 0; j < kBrick; ++j)
                        for (int i = 0; i < kBrick; ++i) {
                            // Beyond the volume's edge a brick repeats the edge voxel.
                            const int x = std::min(bx * kBrick + i, d.x - 1),
                                      y = std::min(by * kBrick + j, d.y - 1),
                                      z = std::min(bz * kBrick + k, d.z - 1);
                            const float dist =
                                std::sqrt(g[size_t(z) * nxy + size_t(y) * nx + size_t(x)]);
                            const uint16_t u = dist >= clampMm
                                                   ? clampUnits
                                                   : uint16_t(std::lround(dist * kUnitsPerMm));
                            const size_t at = size_t(i + kBrick * (j + kBrick * k));
                            brick[at] = std::min(u, clampUnits);
                            uniform = uniform && brick[at] == brick[0];
                        }
                if (uniform) {
                    m_table[b] = kUniform | brick[0];
                } else {
                    m_table[b] = uint32_t(m_pool.size());
                    m_pool.insert(m_pool.end(), brick.begin(), brick.end());
                }
            }
    m_pool.shrink_to_fit();
}

uint16_t DistanceField::raw(int x, int y, int z) const {
    const size_t b =
        size_t(x / kBrick) +
        size_t(m_bricks.x) * (size_t(y / kBrick) + size_t(m_bricks.y) * size_t(z / kBrick));
    const uint32_t e = m_table[b];
    if (e & kUniform)
        return uint16_t(e);
    return m_pool[e + size_t(x % kBrick + kBrick * (y % kBrick + kBrick * (z % kBrick)))];
}

float DistanceField::atVoxel(glm::ivec3 v) const {
    assert(v.x >= 0 && v.y >= 0 && v.z >= 0 && v.x < m_dims.x && v.y < m_dims.y && v.z < m_dims.z &&
           "distance field: voxel outside the volume");
    if (m_table.empty())
        return m_clampMm;
    return float(raw(v.x, v.y, v.z)) / kUnitsPerMm;
}

float DistanceField::interpolate(glm::vec3 v) const {
    const glm::vec3 hi = glm::vec3(m_dims - 1);
    v = glm::clamp(v, glm::vec3(0.0f), hi);
    const glm::ivec3 i0 = glm::min(glm::ivec3(v), m_dims - 1);
    const glm::ivec3 i1 = glm::min(i0 + 1, m_dims - 1);
    const glm::vec3 t = v - glm::vec3(i0);
    auto at = [&](int x, int y, int z) { return float(raw(x, y, z)); };
    const float c00 = glm::mix(at(i0.x, i0.y, i0.z), at(i1.x, i0.y, i0.z), t.x);
    const float c10 = glm::mix(at(i0.x, i1.y, i0.z), at(i1.x, i1.y, i0.z), t.x);
    const float c01 = glm::mix(at(i0.x, i0.y, i1.z), at(i1.x, i0.y, i1.z), t.x);
    const float c11 = glm::mix(at(i0.x, i1.y, i1.z), at(i1.x, i1.y, i1.z), t.x);
    return glm::mix(glm::mix(c00, c10, t.y), glm::mix(c01, c11, t.y), t.z) / kUnitsPerMm;
}

float DistanceField::at(glm::vec3 pMm) const {
    if (m_table.empty() || m_empty)
        return m_clampMm;
    // Voxel coordinates (centres at integers), as Volume::toVoxel.
    const glm::vec3 v = pMm / m_spacing + glm::vec3(m_dims) * 0.5f - 0.5f;
    if (!(std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z)))
        return m_clampMm;
    const glm::vec3 inside = glm::clamp(v, glm::vec3(0.0f), glm::vec3(m_dims - 1));
    const float edge = interpolate(inside);
    if (inside == v)
        return edge;
    // Outside: the structure lies in the box of voxel centres, so |p - s|^2 >= |q - s|^2 +
    // |p - q|^2 for the box point q nearest p.
    const float out = glm::length((v - inside) * m_spacing);
    return std::min(m_clampMm, std::sqrt(edge * edge + out * out));
}

// [SECTION] StructureFields

StructureFields::StructureFields(const Volume& volume, float clampMm, ThreadPool* pool) {
    const auto t0 = std::chrono::steady_clock::now();
    const std::vector<int64_t> counts = volume.materialCounts();
    for (CriticalStructure& s : criticalStructures()) {
        bool present = false;
        for (int m = 0; m < kMaterialCount; ++m)
            present = present || (s.has(Material(m)) && counts[size_t(m)] > 0);
        if (!present)
            continue;
        m_fields.emplace_back(volume, s.materials, clampMm, pool);
        m_structures.push_back(std::move(s));
    }
    m_buildMs =
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

int StructureFields::structureOf(Material m) const {
    for (size_t i = 0; i < m_structures.size(); ++i)
        if (m_structures[i].has(m))
            return int(i);
    return -1;
}

size_t StructureFields::bytes() const {
    size_t n = 0;
    for (const DistanceField& f : m_fields)
        n += f.bytes();
    return n;
}

float StructureFields::closestApproach(size_t i, const ToolShape& shape,
                                       const ToolPose& pose) const {
    const DistanceField& f = m_fields[i];
    const float r = 0.5f * shape.diameterMm;
    if (shape.sphere())
        return f.at(pose.position) - r;
    // A tipped cylinder: axis points from the apex up the cutting length, half a millimetre apart, each
    // less the cutter's largest radius within a quarter millimetre of it plus that quarter: every
    // point of the cutter lies within that of a sample, so this is a lower bound.
    const float t = shape.tipLengthMm, h = shape.tipLengthMm + shape.cutLengthMm;
    const glm::vec3 axis = pose.axis();
    float best = std::numeric_limits<float>::max();
    for (float s = 0.0f; s < h + 0.25f; s += 0.5f) {
        const float top = std::min(s + 0.25f, h);
        const float radius = top < t ? r * top / t : r;
        best = std::min(best, f.at(pose.position + s * axis) - radius - 0.25f);
    }
    return best;
}

} // namespace trephine

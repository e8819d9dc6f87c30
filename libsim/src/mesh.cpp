#include "libsim/mesh.h"

#include "libsim/skull.h"
#include "libsim/volume.h"

#include <cmath>
#include <glm/geometric.hpp>
#include <glm/gtc/constants.hpp>
#include <glm/gtx/rotate_vector.hpp>

namespace trephine {

namespace {
constexpr glm::vec4 kScalp{0.86f, 0.63f, 0.53f, 1.0f};
constexpr glm::vec4 kCutEdge{0.58f, 0.16f, 0.15f, 1.0f};
constexpr glm::vec4 kDrape{0.22f, 0.50f, 0.52f, 1.0f};
} // namespace

void MeshData::addLathe(const std::vector<glm::vec2>& profile, glm::vec4 color, int segments) {
    const float twoPi = glm::two_pi<float>();
    for (size_t i = 0; i + 1 < profile.size(); ++i) {
        glm::vec2 a = profile[i], b = profile[i + 1];
        glm::vec2 d = b - a;
        if (glm::length(d) <= 0.0f)
            continue;
        glm::vec2 n2 = glm::normalize(glm::vec2(d.y, -d.x)); // outward in the (r, z) plane
        auto base = uint32_t(vertices.size());
        for (int s = 0; s <= segments; ++s) {
            float ang = twoPi * float(s) / float(segments);
            float c = std::cos(ang), si = std::sin(ang);
            glm::vec3 n{c * n2.x, si * n2.x, n2.y};
            vertices.push_back({{c * a.x, si * a.x, a.y}, n, color});
            vertices.push_back({{c * b.x, si * b.x, b.y}, n, color});
        }
        for (int s = 0; s < segments; ++s) {
            uint32_t i0 = base + uint32_t(2 * s);
            indices.insert(indices.end(), {i0, i0 + 2, i0 + 1, i0 + 1, i0 + 2, i0 + 3});
        }
    }
}

void MeshData::addSphere(glm::vec3 centre, float radius, glm::vec4 color, int segments) {
    auto base = uint32_t(vertices.size());
    const int rings = segments / 2;
    for (int r = 0; r <= rings; ++r) {
        float th = glm::pi<float>() * float(r) / float(rings);
        for (int s = 0; s <= segments; ++s) {
            float ph = glm::two_pi<float>() * float(s) / float(segments);
            glm::vec3 n{std::sin(th) * std::cos(ph), std::sin(th) * std::sin(ph), -std::cos(th)};
            vertices.push_back({centre + radius * n, n, color});
        }
    }
    const uint32_t row = uint32_t(segments + 1);
    for (int r = 0; r < rings; ++r)
        for (int s = 0; s < segments; ++s) {
            uint32_t i0 = base + uint32_t(r) * row + uint32_t(s);
            indices.insert(indices.end(), {i0, i0 + 1, i0 + row, i0 + 1, i0 + row + 1, i0 + row});
        }
}

namespace {
// Distance (mm) from the origin to the outermost bone along `dir`, or -1.
float surfaceRadius(const Volume& v, glm::vec3 dir, float maxR) {
    for (float t = maxR; t > 0.0f; t -= 0.5f) {
        glm::ivec3 q = glm::ivec3(glm::round(v.toVoxel(dir * t)));
        if (v.inside(q) && v.density(q.x, q.y, q.z) >= kSurfaceDensity)
            return t;
    }
    return -1.0f;
}
} // namespace

MeshData makeSurgicalField(const Volume& volume, const SurfaceSite& site, float openingMm,
                           float drapeMm, float scalpGapMm) {
    MeshData m;
    const float maxR = 0.5f * glm::length(volume.extentMm());
    const float r0 = glm::length(site.position);
    if (r0 <= 0.0f)
        return m;
    const glm::vec3 u0 = site.position / r0;
    glm::vec3 e1 = glm::normalize(
        glm::cross(u0, std::abs(u0.z) < 0.9f ? glm::vec3(0, 0, 1) : glm::vec3(1, 0, 0)));
    glm::vec3 e2 = glm::cross(u0, e1);
    const int segments = 72;
    // Rings: (arc distance from the site along the surface, gap above the bone, colour).
    struct Ring {
        float s, gap;
        glm::vec4 color;
    };
    std::vector<Ring> rings;
    rings.push_back({openingMm, 0.0f, kCutEdge}); // the cut edge of the retracted scalp
    for (int i = 0; i <= 5; ++i)
        rings.push_back({openingMm + (drapeMm - openingMm) * float(i) / 5.0f, scalpGapMm, kScalp});
    rings.push_back({drapeMm, scalpGapMm + 3.0f, kDrape});
    const float sMax = r0 * 1.9f; // about 110 degrees around the vault
    for (int i = 1; i <= 14; ++i)
        rings.push_back({drapeMm + (sMax - drapeMm) * float(i) / 14.0f, scalpGapMm + 3.0f, kDrape});

    std::vector<float> lastR(size_t(segments), r0);
    const size_t nk = rings.size(), nj = size_t(segments);
    std::vector<std::vector<glm::vec3>> dirs(nk, std::vector<glm::vec3>(nj));
    std::vector<std::vector<float>> rad(nk, std::vector<float>(nj));
    for (size_t k = 0; k < nk; ++k) {
        float theta = rings[k].s / r0;
        for (size_t j = 0; j < nj; ++j) {
            float phi = glm::two_pi<float>() * float(j) / float(segments);
            glm::vec3 axis = std::cos(phi) * e1 + std::sin(phi) * e2;
            glm::vec3 dir = glm::rotate(u0, theta, axis);
            float r = surfaceRadius(volume, dir, maxR);
            if (r < 0.0f)
                r = lastR[j];
            lastR[j] = r;
            dirs[k][j] = dir;
            rad[k][j] = r;
        }
    }
    // The surface is found to the nearest voxel: smooth the radii around each ring and across
    // rings so that the cloth drapes instead of showing voxel terraces.
    for (int pass = 0; pass < 3; ++pass) {
        auto src = rad;
        for (size_t k = 0; k < nk; ++k)
            for (size_t j = 0; j < nj; ++j) {
                float around =
                    (src[k][(j + nj - 1) % nj] + 2.0f * src[k][j] + src[k][(j + 1) % nj]);
                float across = k > 0 && k + 1 < nk
                                   ? src[k - 1][j] + 2.0f * src[k][j] + src[k + 1][j]
                                   : 4.0f * src[k][j];
                rad[k][j] = (around + across) / 8.0f;
            }
    }
    std::vector<std::vector<glm::vec3>> pos(nk, std::vector<glm::vec3>(nj));
    for (size_t k = 0; k < nk; ++k)
        for (size_t j = 0; j < nj; ++j)
            pos[k][j] = dirs[k][j] * (rad[k][j] + rings[k].gap);
    // Each band between consecutive rings gets its own vertices (flat colour per band), normals
    // from the face normals, turned outward.
    for (size_t k = 0; k + 1 < rings.size(); ++k) {
        glm::vec4 color = rings[k + 1].color;
        if (rings[k].color == kCutEdge)
            color = kCutEdge;
        if (rings[k + 1].color == kDrape && rings[k].color == kScalp)
            color = glm::vec4(0.16f, 0.38f, 0.40f, 1.0f); // the drape's folded edge
        auto base = uint32_t(m.vertices.size());
        for (int j = 0; j < segments; ++j) {
            size_t jn = size_t((j + 1) % segments), jp = size_t((j + segments - 1) % segments);
            for (size_t kk : {k, k + 1}) {
                glm::vec3 p = pos[kk][size_t(j)];
                glm::vec3 t1 = pos[kk][jn] - pos[kk][jp];
                glm::vec3 t2 = pos[k + 1][size_t(j)] - pos[k][size_t(j)];
                glm::vec3 n = glm::cross(t1, t2);
                n = glm::length(n) > 0 ? glm::normalize(n) : glm::normalize(p);
                if (glm::dot(n, p) < 0.0f)
                    n = -n;
                m.vertices.push_back({p, n, color});
            }
        }
        for (int j = 0; j < segments; ++j) {
            uint32_t a = base + uint32_t(2 * j), b = base + uint32_t(2 * ((j + 1) % segments));
            m.indices.insert(m.indices.end(), {a, b, a + 1, a + 1, b, b + 1});
        }
    }
    return m;
}

} // namespace trephine

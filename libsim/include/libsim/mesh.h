// Triangle meshes with per-vertex colour, and the patient geometry a client draws over the DBI
// (the surgical field: scalp rim and drape around the craniotomy site). The server builds the
// field once from its volume and sends it in the scene (net/scene.h); no GL here, so tests check
// the meshes headless.
#pragma once

#include <cstdint>
#include <glm/vec2.hpp>
#include <glm/vec3.hpp>
#include <glm/vec4.hpp>
#include <vector>

namespace trephine {

class Volume;
struct SurfaceSite;

struct MeshVertex {
    glm::vec3 position;
    glm::vec3 normal;
    glm::vec4 color; // alpha 0: take the owner's colour (a uniform) instead
};

struct MeshData {
    std::vector<MeshVertex> vertices;
    std::vector<uint32_t> indices; // triangles

    // A solid of revolution about +z through the profile (radius, z) points, bottom to top; a
    // radius of 0 closes the end.
    void addLathe(const std::vector<glm::vec2>& profile, glm::vec4 color, int segments = 32);
    void addSphere(glm::vec3 centre, float radius, glm::vec4 color, int segments = 24);
    size_t triangleCount() const { return indices.size() / 3; }
};

// Scalp (skin-coloured, `scalpGapMm` above the bone, retracted `openingMm` from the site) and a
// surgical drape beyond `drapeMm` from the site, following the outer surface of `volume` found by
// casting rays from its centre. Empty when the volume holds no bone.
MeshData makeSurgicalField(const Volume& volume, const SurfaceSite& site, float openingMm = 32.0f,
                           float drapeMm = 52.0f, float scalpGapMm = 4.0f);

} // namespace trephine

// Built-in volumes, so nothing must be downloaded: the procedural skull (`skull:N`) and analytic
// test volumes (`sphere:N`, `box:N`). All are deterministic: same arguments, same bytes.
#pragma once

#include "libsim/volume.h"

#include <cstdint>
#include <glm/vec3.hpp>

namespace trephine {

inline constexpr uint32_t kDefaultSkullSeed = 1;

// Cranial vault (outer table, porous diploe, inner table; about 6-8 mm of bone) over a dura and
// brain region. Axes: +z superior (vertex of the head), +y anterior (forehead), +x to the
// patient's left. The physical size does not depend on n; the spacing is the field of view / n.
// n from 32 to 512.
Volume makeSkull(int n, uint32_t seed = kDefaultSkullSeed);

// Where a trainee drills the default burr hole on makeSkull(n, ...): a point on the outer table
// surface (mm, object space) and the outward surface normal there.
struct SurfaceSite {
    glm::vec3 position;
    glm::vec3 normal;
};
SurfaceSite defaultBurrSite(const Volume& skull);

// Solid cortical sphere of radius sphereRadiusMm(n) centred in an n^3 volume of 1 mm spacing, with
// density falling linearly across one voxel at the surface so that the iso-surface at
// kSurfaceDensity is exactly the analytic sphere (for depth tests).
Volume makeSphere(int n);
float sphereRadiusMm(int n);

// Solid cortical axis-aligned box filling the middle half of an n^3 volume (1 mm spacing): voxels
// with index in [n/4, 3n/4) on every axis.
Volume makeBox(int n);

} // namespace trephine

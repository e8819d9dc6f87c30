// A burr hole drilled offline along a ray (`trephine render --drill-at`), and what a drilling
// removed, material by material (the headless demo's summary).
#pragma once

#include "libsim/box.h"
#include "libsim/volume.h"

#include <glm/vec3.hpp>

#include <cstdint>
#include <vector>

namespace trephine {

struct HoleResult {
    Box3i changed;            // voxels the burr changed (BB_volume)
    bool touchedDura = false; // the hole ends where the burr first touched dura
};

// A burr of `diameterMm` drills a hole whose deepest point is `depthMm` below `surface` along the
// unit `direction` (into the bone): its centre moves from one radius above the surface to
// (depth - radius) below it in quarter-voxel steps, drilling at full speed at each until nothing
// more changes. Dura never erodes; touching it ends the hole there.
HoleResult drillHoleAlong(Volume& volume, glm::vec3 surface, glm::vec3 direction, float depthMm,
                          float diameterMm);

// Voxels of each material (by Material index) that are Air in `after` and were that material in
// `before` (same dims).
std::vector<int64_t> removedByMaterial(const Volume& before, const Volume& after);

} // namespace trephine

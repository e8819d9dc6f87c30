// BB_volume -> BB_screen: the window rectangle whose pixels can change when the voxels of a box
// change (paper, section 3.4.2). Only this rectangle is re-rendered and re-sent.
#pragma once

#include "libsim/box.h"
#include "libsim/camera.h"
#include "libsim/dbi.h"

namespace trephine {

class Volume;

// How far (in voxels, beyond the faces of the changed voxels) a change can reach a pixel's colour
// or depth: a trilinear sample reads voxels within 1 of its position and the shading gradient
// (central differences at the eight voxels around the hit) reads voxels within 2 of the hit, so a
// changed voxel centre influences points within 2 voxels of it, i.e. 1.5 voxels beyond its faces.
// The extra half voxel is margin for rounding. (Tested: 1 fails, 1.5 passes.)
inline constexpr float kDirtyStencilVoxels = 2.0f;

// The changed box's faces grown by stencilVoxels, as an object-space (mm) box of the volume.
struct BoxMm {
    glm::dvec3 lo;
    glm::dvec3 hi;
};
BoxMm dirtyBoxMm(const Volume& volume, const Box3i& changed,
                 float stencilVoxels = kDirtyStencilVoxels);

// BB_screen (row 0 at the bottom): every pixel whose centre ray passes through the grown box.
// The eight corners are projected with the camera's matrices; pixels from floor(min) to
// ceil(max) are taken, clipped to the window. If a corner lies on or behind the eye plane the
// projection says nothing useful, so the whole window is returned. An empty box gives an empty
// rectangle.
PixelRect dirtyScreenRect(const Camera& camera, const Volume& volume, const Box3i& changed,
                          float stencilVoxels = kDirtyStencilVoxels);
// The same from precomputed matrices (what the benchmark times: projection only).
PixelRect dirtyScreenRect(const Camera& camera, const glm::dmat4& viewProj, const BoxMm& box);

} // namespace trephine

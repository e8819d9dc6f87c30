// Built-in volumes, so nothing must be downloaded: the procedural skull (`skull:N`) and analytic
// test volumes (`sphere:N`, `box:N`). All are deterministic: same arguments, same bytes.
#pragma once

#include "libsim/volume.h"

#include <cstdint>
#include <glm/vec2.hpp>
#include <glm/vec3.hpp>
#include <optional>

namespace trephine {

inline constexpr uint32_t kDefaultSkullSeed = 1;

// Skull constants (see docs/simulation.md). Lengths in mm, densities in bytes.
inline constexpr float kSkullFieldOfViewMm = 200.0f; // cube edge; spacing = FOV / n
inline constexpr float kSkullOuterTableMm = 1.8f;    // mean; varies +-0.2 over the vault
inline constexpr float kSkullDiploeMm = 3.7f;        // mean; varies +-0.35
inline constexpr float kSkullInnerTableMm = 1.3f;    // mean; varies +-0.15
inline constexpr float kSkullDuraMm = 1.0f;          // at least one voxel at coarse n
inline constexpr uint8_t kSkullCorticalDensity = 240;
inline constexpr uint8_t kSkullDuraDensity = 180;  // >= kSurfaceDensity: exposed dura is visible
inline constexpr uint8_t kSkullBrainDensity = 100; // < kSurfaceDensity: never rendered
inline constexpr uint8_t kSkullSinusDensity = 190; // blood-filled: visible once exposed
inline constexpr uint8_t kSkullArteryDensity = 200;
// Kocher's point on the patient's right (+x is the patient's left): 3 cm from the midline, about
// 1 cm anterior to the coronal suture.
inline constexpr float kKocherPointXMm = -30.0f;
inline constexpr float kKocherPointYMm = 35.0f;
// makeSphere's density ramp: 128 + 127 * (r - dist) / kSphereRampMm, clamped to 0..255.
inline constexpr float kSphereRampMm = 2.0f;

// Cranial vault (outer table, porous diploe, inner table; about 6-8 mm of bone) over a dura and
// brain region, with the critical structures a craniotomy must spare: the superior sagittal sinus
// in the midline under the inner table, and the middle meningeal artery with its frontal and
// parietal branches in grooves of the inner table on both temporal-parietal walls. Axes: +z
// superior (vertex of the head), +y anterior (forehead), +x to the patient's left. The physical
// size does not depend on n; the spacing is the field of view / n. n from 32 to 512; other n throw
// Error.
Volume makeSkull(int n, uint32_t seed = kDefaultSkullSeed);

// Where a trainee drills the default burr hole on makeSkull(n, ...): a point on the outer table
// surface (mm, object space) and the outward surface normal there. Found by marching down a
// vertical ray through (kKocherPointXMm, kKocherPointYMm) in the volume itself (then through the
// vertex, for other volumes) to the first trilinear crossing of kSurfaceDensity. Throws Error
// when neither ray meets a surface.
struct SurfaceSite {
    glm::vec3 position;
    glm::vec3 normal;
};
SurfaceSite defaultBurrSite(const Volume& skull);
// The first trilinear crossing of kSurfaceDensity on the vertical ray down through `column` (x, y
// in mm) from the top of the volume, with its outward normal; nothing when the ray meets none.
std::optional<SurfaceSite> surfaceSiteBelow(const Volume& volume, glm::vec2 column);

// The study's cut (the paper's experiment): an n^3 box centred on the volume's middle column
// (shifted `shift` voxels along x) whose top face lies one voxel above the topmost bone voxel of
// that column, i.e. at the surface the paper camera on +z looks at. Clipped to the volume.
Box3i surfaceBox(const Volume& volume, int n, int shift = 0);

// Solid cortical sphere of radius sphereRadiusMm(n) = 0.35 n centred in an n^3 volume of 1 mm
// spacing, with density falling linearly with distance across +-kSphereRampMm of the surface so
// that the trilinear iso-surface at kSurfaceDensity is the analytic sphere to ~0.01 mm (for depth
// tests). n from 4 to 512.
Volume makeSphere(int n);
float sphereRadiusMm(int n);

// Solid cortical axis-aligned box filling the middle half of an n^3 volume (1 mm spacing): voxels
// with index in [n/4, 3n/4) on every axis, density 255; air elsewhere. n from 4 to 512.
Volume makeBox(int n);
// The middle of a makeBox volume's top face (+z), on its iso-surface, and its outward normal.
SurfaceSite boxTopSite(const Volume& box);

} // namespace trephine

// Loading and saving volumes: one spec string names a built-in volume (skull:N, sphere:N, box:N),
// a NRRD or NIfTI-1 file, or raw voxels with given dimensions. docs/volumes.md is the reference.
#pragma once

#include "libsim/volume.h"

#include <cstdint>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace trephine {

// [Density window] Scalar data other than uint8 (CT in Hounsfield units, usually) maps to density
// linearly: lo -> 0, hi -> 255, clamped, rounded to nearest. The default puts the iso-surface
// density (128) at 300 HU, a common threshold for bone in CT: soft tissue (~40 HU) stays below the
// surface and cortical bone (>= 900 HU) saturates. A spec overrides it with `?window=lo,hi`.
struct DensityWindow {
    double lo = -300.0;
    double hi = 900.0;
};
inline constexpr DensityWindow kDefaultWindow{};

// Density of value v through the window (NaN maps to 0).
uint8_t windowDensity(double v, DensityWindow w);

// [Material labels] Files other than our own NRRD carry no labels; they are derived from density.
// At or above kSurfaceDensity is bone; at or above kCorticalDensity (about 800 HU through the
// default window) is cortical bone, below it diploe; everything else is air. CT cannot tell dura
// or brain from scalp or muscle, so no loaded scan has dura or brain voxels.
inline constexpr uint8_t kCorticalDensity = 234;
Material materialFromDensity(uint8_t density);

// Refused beyond this many voxels (1024^3) before anything is allocated.
inline constexpr uint64_t kMaxVolumeVoxels = uint64_t(1) << 30;

// Loads the volume a spec names; see volumeSpecHelp(). Every bad spec or file throws Error with
// one line that names it. A folder of image slices needs sim_image (openVolume in
// libsim_image/volume_slices.h); here it throws Error saying so.
Volume loadVolume(const std::string& spec);

struct SaveOptions {
    // gzip the voxel data (.nrrd, .nhdr); .nii.gz is always compressed and .nii never.
    bool compress = true;
};

// Writes by extension: .nrrd (attached data) or .nhdr (+ detached .raw or .raw.gz beside it) keep
// density and materials; .nii / .nii.gz keep density only (uint8), so materials come back derived
// from density. Throws Error when the path cannot be written or its extension is unknown.
// The bytes go to temporary files beside the targets, renamed over them only once complete: a
// failure leaves what was there untouched. A .nhdr's detached OUT.raw[.gz] is replaced only when
// it is that header's own data (an earlier save of it): any other file of that name is left alone
// and the save fails.
void saveVolume(const Volume& volume, const std::string& path, const SaveOptions& options = {});
// What saveVolume would refuse before writing anything: an unknown extension, a folder that takes
// no new file, a detached data file that is not the header's own. Throws Error; writes nothing.
void checkSaveTarget(const std::string& path, const SaveOptions& options = {});
// Whether saveVolume(path) keeps the materials (.nrrd, .nhdr; case-insensitive); .nii and .nii.gz
// keep density only.
bool savesMaterials(const std::string& path);

// The spec grammar, for --help texts.
std::string volumeSpecHelp();

// [Spec parsing] Shared with sim_image. `name?key=v&key=v`: when the whole spec names an existing
// file it is all name (a file may have '?' in its name); otherwise the query starts at the last
// '?'. Keys not in `allowedKeys` (comma separated) throw Error naming the spec.
struct VolumeSpecQuery {
    std::string name;
    std::vector<std::pair<std::string, std::string>> options;
    // The value of key, or "" when absent.
    std::string get(const std::string& key) const;
    bool has(const std::string& key) const;
};
VolumeSpecQuery parseVolumeSpecQuery(const std::string& spec, const std::string& allowedKeys);
// `?window=lo,hi` (nullopt when absent), `?spacing=a,b,c` (fallback when absent); both throw Error
// naming `what` when malformed.
std::optional<DensityWindow> parseWindowOption(const VolumeSpecQuery& q, const std::string& what);
glm::vec3 parseSpacingOption(const VolumeSpecQuery& q, const std::string& what, glm::vec3 fallback);

// Voxel spacings Trephine works with, in mm: from 1 um to 1 m, and no axis more than
// kMaxSpacingRatio times another's (a ray caster and the burr-site search step by the smallest
// spacing across the largest extent; a zero or vanishing spacing made them run forever).
inline constexpr double kMinSpacingMm = 1e-3, kMaxSpacingMm = 1e3, kMaxSpacingRatio = 1e3;
// Throws Error naming `what` unless `spacing` is such a spacing (as float, the way it is kept).
void checkSpacing(const std::string& what, glm::dvec3 spacing);

} // namespace trephine

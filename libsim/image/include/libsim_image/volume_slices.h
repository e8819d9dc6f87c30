// Volumes from folders of 2D image slices (OpenImageIO), and openVolume: every volume spec,
// folders included. The core's loadVolume handles everything but folders (libsim/volume_io.h).
#pragma once

#include "libsim/volume.h"
#include "libsim/volume_io.h"

#include <optional>
#include <string>

namespace trephine {

// Loads any volume spec: a folder or `slices:FOLDER[?spacing=a,b,c&window=lo,hi]` is read here,
// anything else goes to loadVolume. Throws Error with one line naming the spec or file.
Volume openVolume(const std::string& spec);

// Reads every image file in folder (extensions OpenImageIO knows; hidden files skipped) in natural
// filename order ("2.png" before "10.png") as slices z = 0, 1, ...; pixel (column, row) is voxel
// (x, y), row 0 being the top row of the file. The first channel is used. 8-bit data passes
// through as density unless a window is given; 16-bit, 32-bit and float data go through the
// window (kDefaultWindow when none). All slices must share size and pixel type.
Volume loadVolumeSlices(const std::string& folder, glm::vec3 spacingMm,
                        const std::optional<DensityWindow>& window = std::nullopt);

// Writes density as 8-bit greyscale slices `slice_0000.EXT`, ... into folder (created if needed),
// readable by loadVolumeSlices. Materials are not kept.
void saveVolumeSlices(const Volume& volume, const std::string& folder,
                      const std::string& extension = "png");

} // namespace trephine

// sim_image: image-file support (OpenImageIO) kept out of the simulation core.
#pragma once

namespace trephine {

// The OpenImageIO version this target was built against, for `trephine --version`.
const char* openImageIoVersion();

} // namespace trephine

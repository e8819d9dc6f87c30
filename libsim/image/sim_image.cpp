// Anchor for the sim_image target: reports the OpenImageIO version it was built against.
#include "libsim_image/sim_image.h"

#include <OpenImageIO/oiioversion.h>

namespace trephine {

const char* openImageIoVersion() { return OIIO_VERSION_STRING; }

} // namespace trephine

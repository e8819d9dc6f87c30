// writeScreenshot (declared in ui/window.h) has a file of its own: it is ui's only use of
// OpenImageIO besides the trainer app's volume loading, so a program that opens windows but never
// writes a PNG links no sim_image object and (with --as-needed) loads none of OpenImageIO's ~250
// shared libraries.
#include "libsim_image/dbi_io.h"
#include "ui/window.h"

namespace trephine::ui {

void writeScreenshot(const std::string& path, const Dbi& framebuffer) {
    writeColorPng(path, framebuffer); // flips to top-down
}

} // namespace trephine::ui

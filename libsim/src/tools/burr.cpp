// The spherical burr: thins and widens a hole.
#include "libsim/tool_catalogue.h"

namespace trephine {

extern const ToolType kBurrTool = {
    .kind = ToolKind::Burr,
    .name = "burr",
    .key = "B",
    .tip = "A spherical burr, 1-6 mm: thins and widens a hole.",
    .cutter = Cutter::Sphere,
    .minDiameterMm = 1.0f,
    .maxDiameterMm = 6.0f,
    .defaultDiameterMm = 5.0f,
    .stepMm = 0.5f,
    .tipLengthPerDiameter = 0.0f,
    .cutLengthMm = 0.0f,
    .erosionRate = 1700.0, // solid cortical (255) in 0.15 s
    .clutch = false,
    .colour = {0.86f, 0.74f, 0.42f},
};

} // namespace trephine

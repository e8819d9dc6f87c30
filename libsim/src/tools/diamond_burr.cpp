// The diamond burr: a small sphere coated with diamond grit, for fine work near the dura. It
// abrades rather than cuts, a third as fast as a fluted burr, so a trainee can thin the inner
// table without plunging through it.
#include "libsim/tool_catalogue.h"

namespace trephine {

extern const ToolType kDiamondBurrTool = {
    .kind = ToolKind::DiamondBurr,
    .name = "diamond",
    .key = "D",
    .tip =
        "A diamond burr, 1-4 mm: cuts a third as fast and polishes, for fine work near the dura.",
    .cutter = Cutter::Sphere,
    .minDiameterMm = 1.0f,
    .maxDiameterMm = 4.0f,
    .defaultDiameterMm = 2.0f,
    .stepMm = 0.5f,
    .tipLengthPerDiameter = 0.0f,
    .cutLengthMm = 0.0f,
    .erosionRate = 1700.0 / 3.0,
    .clutch = false,
    .colour = {0.80f, 0.82f, 0.86f},
};

} // namespace trephine

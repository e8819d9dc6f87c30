// The cranial perforator: opens a burr hole and stops at the inner table (its clutch rule,
// drill.cpp). Its proportions follow a 14 mm adult perforator (libsim/tool.h).
#include "libsim/tool_catalogue.h"

namespace trephine {

extern const ToolType kPerforatorTool = {
    .kind = ToolKind::Perforator,
    .name = "perforator",
    .key = "P",
    .tip = "The cranial perforator, 6-16 mm: opens a burr hole and stops at the inner table.",
    .cutter = Cutter::TippedCylinder,
    .minDiameterMm = 6.0f,
    .maxDiameterMm = 16.0f,
    .defaultDiameterMm = 14.0f,
    .stepMm = 1.0f,
    .tipLengthPerDiameter = 4.0f / 14.0f, // a blunt tip 4 mm long at 14 mm
    .cutLengthMm = 12.0f,
    .erosionRate = 425.0, // solid cortical in 0.6 s
    .clutch = true,
    .colour = {0.86f, 0.74f, 0.42f},
};

} // namespace trephine

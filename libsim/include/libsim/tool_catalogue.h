// The tool catalogue: all that tells one kind of tool from another, one entry per kind. Drilling,
// forces, the wire, the window's mesh and controls and the reports ask it and never compare kinds.
// A new tool is one file in libsim/src/tools/ that defines its ToolType, and one line in the
// registry (libsim/src/tool_catalogue.cpp). docs/simulation.md ("Tools") lists the entries.
#pragma once

#include "libsim/tool.h"

#include <glm/vec3.hpp>

#include <optional>
#include <span>
#include <string_view>

namespace trephine {

// The cutter's geometry, in the tool-local frame (libsim/tool.h).
enum class Cutter : uint8_t {
    Sphere,         // a ball of the diameter; the reference point is its centre
    TippedCylinder, // a blunt conical tip under a cutting cylinder; the reference point is the apex
};

struct ToolType {
    ToolKind kind;    // also its id on the wire and in session logs
    const char* name; // in text, files and flags: "burr", "perforator", "diamond"
    const char* key;  // the window's key that selects it
    const char* tip;  // the window's one-line description
    Cutter cutter;
    float minDiameterMm, maxDiameterMm, defaultDiameterMm;
    float stepMm; // one step of the window's [ and ]
    // TippedCylinder: the tip's length per mm of diameter, and the cutting length above it.
    float tipLengthPerDiameter, cutLengthMm;
    // Density units removed per second at full speed from solid cortical bone (drill.cpp).
    double erosionRate;
    bool clutch;      // stops cutting once through the inner table (the perforator's rule)
    glm::vec3 colour; // the cutting head in the window
};

inline constexpr uint8_t kToolKindCount = 3;

// The entry of `kind` (a kind from the wire is checked against kToolKindCount first).
const ToolType& toolType(ToolKind kind);
// Every entry, in the order of their ids.
std::span<const ToolType* const> toolTypes();
// The kind called `name` (ToolType::name), if any.
std::optional<ToolKind> toolKindNamed(std::string_view name);

} // namespace trephine

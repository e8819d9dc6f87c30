// The wire's tool and force messages as libsim's types, in one place: the server's drill and force
// model, the trainee core's local forces and the window's tool meshes all read a tool state the
// same way.
#pragma once

#include "libsim/haptics.h"
#include "libsim/tool.h"
#include "net/protocol.h"

namespace trephine::net {

// The cutter a tool of `kind` and `diameterMm` is (ToolShape::of: throws Error for a diameter
// the kind refuses).
inline ToolShape toolShape(ToolKind kind, float diameterMm) {
    return ToolShape::of(kind, diameterMm);
}

inline ToolShape shapeOf(const ToolState& t) {
    return toolShape(ToolKind(t.toolKind), t.diameterMm);
}

// The fields of a force model the haptic loop extrapolates (the rest are timing).
inline HapticModelData toModelData(const HapticModel& m) {
    HapticModelData d;
    d.position = m.position;
    d.force = m.force;
    d.gradient = m.gradient;
    d.contact = m.contact;
    d.toolSequence = m.toolSequence;
    return d;
}

} // namespace trephine::net

// Conversions between the wire's ViewSpec and libsim's Camera: both ends build the same GL
// matrices from them, so a client depth-tests against exactly the depth the server rendered.
#pragma once

#include "libsim/camera.h"
#include "net/protocol.h"

#include <algorithm>

namespace trephine::net {

inline Camera toCamera(const ViewSpec& v) {
    Camera c;
    c.eye = v.eye;
    c.target = v.target;
    c.up = v.up;
    c.fovYDeg = v.fovYDeg;
    c.nearMm = v.nearMm;
    c.farMm = v.farMm;
    c.width = v.width;
    c.height = v.height;
    return c;
}

// Throws nothing; the window size is clamped to what the wire carries (1..kMaxWindowSize).
inline ViewSpec toViewSpec(const Camera& c) {
    ViewSpec v;
    v.eye = c.eye;
    v.target = c.target;
    v.up = c.up;
    v.fovYDeg = c.fovYDeg;
    v.nearMm = c.nearMm;
    v.farMm = c.farMm;
    v.width = uint16_t(std::clamp(c.width, 1, int(kMaxWindowSize)));
    v.height = uint16_t(std::clamp(c.height, 1, int(kMaxWindowSize)));
    return v;
}

} // namespace trephine::net

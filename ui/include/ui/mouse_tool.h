// The mouse as a drilling device (no GL, tested headless): the point of bone under the cursor,
// from the DBI's depth and the camera it was rendered with, and the tool pose placed there.
#pragma once

#include "libsim/camera.h"
#include "libsim/dbi.h"
#include "libsim/tool.h"

#include <optional>

namespace trephine::ui {

// The object-space point shown at DBI pixel (px, py) (row 0 at the bottom), or nothing where the
// pixel shows no bone (depth 1) or lies outside the image.
std::optional<glm::vec3> pickSurface(const Dbi& dbi, const Camera& camera, int px, int py);

// The tool touching `surface` from the eye's side, its shaft toward the eye, pushed `pushMm`
// further along the line of sight (negative: lifted off). A burr's centre sits one radius out so
// that the sphere touches the point; the perforator's apex sits on it.
ToolPose toolPoseAt(glm::vec3 surface, const Camera& camera, const ToolShape& shape, float pushMm);

} // namespace trephine::ui

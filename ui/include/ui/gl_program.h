// Shader programs for the window's GL passes: compile and link with a one-line error naming the
// program, and the vertex shader every fullscreen pass shares.
#pragma once

#include "ui/gl.h"

namespace trephine::ui {

// One triangle covering the viewport, from gl_VertexID alone (draw 3 vertices, no buffer).
extern const char* const kFullscreenTriangleVs;

// Compiles and links a vertex + fragment program; throws trephine::Error with the GL log and
// `what` (e.g. "volume") on failure. Needs a current GL 3.3 core context.
GLuint linkProgram(const char* vertexSource, const char* fragmentSource, const char* what);

} // namespace trephine::ui

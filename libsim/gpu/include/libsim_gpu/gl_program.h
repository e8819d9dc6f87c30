// GL helpers every pass shares, the window's and the server's: compile and link with a one-line
// error naming the program, the vertex shader every fullscreen pass uses, and an offscreen
// colour + depth target.
#pragma once

#include "libsim_gpu/gl.h"

#include <string>

namespace trephine::gpu {

// One triangle covering the viewport, from gl_VertexID alone (draw 3 vertices, no buffer).
extern const char* const kFullscreenTriangleVs;

// Compiles and links a vertex + fragment program; throws trephine::Error with the GL log and
// `what` (e.g. "volume") on failure. Needs a current GL 3.3 core context.
GLuint linkProgram(const char* vertexSource, const char* fragmentSource, const char* what);
// The same for a compute program; needs a GL 4.3 core context.
GLuint linkComputeProgram(const char* source, const char* what);

// Allocations GL may refuse (out of memory, a size it does not take) without a throw: clear the
// errors of earlier, unrelated calls first, then throwIfGlRefused(what) throws trephine::Error
// "gpu: OpenGL refused <what> (error 0x...[: out of memory])" if any call since raised one.
void clearGlErrors();
void throwIfGlRefused(const std::string& what);

// (Re)allocates `color` (RGBA8, nearest) and `depth` (32-bit float renderbuffer) at width x
// height and attaches them to `fbo`, creating any of the three that is 0. Leaves the default
// framebuffer bound; throws trephine::Error naming `what` if the size is over the GL's limits,
// GL refuses the memory, or the framebuffer is incomplete.
void makeColorDepthTarget(GLuint& fbo, GLuint& color, GLuint& depth, int width, int height,
                          const char* what);

} // namespace trephine::gpu

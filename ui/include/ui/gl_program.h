// GL helpers the window's passes share (compile and link, the fullscreen triangle, an offscreen
// colour + depth target): sim_gpu's, which the server's GPU renderer uses too.
#pragma once

#include "libsim_gpu/gl_program.h"
#include "ui/gl.h"

namespace trephine::ui {

using gpu::kFullscreenTriangleVs;
using gpu::linkProgram;
using gpu::makeColorDepthTarget;

} // namespace trephine::ui

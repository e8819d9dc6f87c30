// The replicated-volume client's local renderer (issue 7): sim_gpu's ray caster, which follows
// the CPU Renderer step by step (libsim_gpu/volume_raycaster.h). The server's GPU renderer casts
// with the same shader, so the window and the server draw the same picture.
#pragma once

#include "libsim_gpu/volume_raycaster.h"
#include "ui/gl.h"

namespace trephine::ui {

using VolumeView = gpu::VolumeRaycaster;
using VolumeUpdateStats = gpu::VolumeUpdateStats;

} // namespace trephine::ui

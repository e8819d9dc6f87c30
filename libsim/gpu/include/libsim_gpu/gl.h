// The one place sim_gpu (and ui through it) includes OpenGL: core-profile prototypes straight
// from libOpenGL (GLVND, no loader).
#pragma once

#ifndef GL_GLEXT_PROTOTYPES
#define GL_GLEXT_PROTOTYPES 1
#endif
#include <GL/glcorearb.h>

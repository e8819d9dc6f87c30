// A GPU ray caster over 3D textures that renders a libsim Volume for a Camera with the CPU
// Renderer's conventions (first hit of density 128, the same sample grid and refinement, gradient
// shading, material colours) and writes the GL window depth of the hit with gl_FragDepth (1.0
// where no bone), so tools depth-test against it exactly as they do against a DBI. After drilling
// only the changed box is re-uploaded. The replicated-volume client's window draws with it
// (ui::VolumeView) and the server's GPU renderer renders DBIs with it (libsim_gpu/gpu_renderer.h).
#pragma once

#include "libsim/box.h"
#include "libsim/camera.h"
#include "libsim/dbi.h"
#include "libsim/volume.h"
#include "libsim_gpu/gl.h"

#include <cstdint>
#include <glm/vec2.hpp>
#include <glm/vec3.hpp>

namespace trephine::gpu {

// What one VolumeRaycaster::updateBox did: the client's "apply" stage of a volume update.
struct VolumeUpdateStats {
    int64_t voxels = 0;         // density + material voxels re-uploaded (the box, clipped)
    int64_t gradientVoxels = 0; // gradients recomputed and re-uploaded (the box grown by 1)
    double voxelUploadMs = 0;   // glTexSubImage3D of density and material
    double gradientMs = 0;      // CPU recomputation plus glTexSubImage3D of the gradients
};

class VolumeRaycaster {
public:
    // The same ray in either pipeline. Fragment: draw() into the bound framebuffer (the window's
    // VolumeView), and the offscreen render() below through a fullscreen triangle; needs a GL
    // 3.3 core context. Compute: the offscreen render() alone, one invocation a pixel (the
    // server's GPU renderer: compute GPUs run fragment shaders on a few multiprocessors only);
    // needs GL 4.3 core.
    enum class Pipeline { Fragment, Compute };
    explicit VolumeRaycaster(Pipeline pipeline = Pipeline::Fragment);
    ~VolumeRaycaster();
    VolumeRaycaster(const VolumeRaycaster&) = delete;
    VolumeRaycaster& operator=(const VolumeRaycaster&) = delete;

    // (Re)creates the textures for `volume` and uploads all of it (density, material, gradients).
    void upload(const Volume& volume);
    // Re-uploads only `box` (voxels, half-open; clipped to the volume) of density and material,
    // and recomputes and re-uploads the gradients of the box grown by one voxel (the central
    // differences that read a changed voxel). `volume` must have the uploaded dimensions.
    VolumeUpdateStats updateBox(const Volume& volume, const Box3i& box);
    bool empty() const { return m_dims.x == 0; }
    Pipeline pipeline() const { return m_pipeline; }
    glm::ivec3 dims() const { return m_dims; }

    // Ray casts the view into the currently bound framebuffer over the current viewport, which
    // must be camera.width x camera.height pixels (pixel (x, y) is the ray through its centre;
    // the fragment pipeline only):
    // colour (alpha 1 on bone, kBackgroundRgba elsewhere) and gl_FragDepth, depth test ALWAYS.
    // Restores the program, vertex array and depth function it found, so it can replace the
    // Compositor's pass 1: `comp.begin(camera); view.draw(camera); comp.draw(tool, ...)`.
    void draw(const Camera& camera);

    // Own offscreen target (RGBA8 + 32-bit float depth: a framebuffer for the fragment pipeline,
    // buffers of the rectangle's size for the compute one): renders the view there; readBack
    // returns it (row 0 at the bottom) like Renderer::render's Dbi. Nothing is cast, nor read
    // back, before a volume is uploaded.
    void render(const Camera& camera);
    Dbi readBack();
    // The pixels of `rect` only (row 0 at the bottom, inside the window), into the own target:
    // each pixel is computed from its window position alone, so they are bit for bit those of
    // the full render. readBack(frame) writes them into `frame` (camera-sized) at their place.
    void render(const Camera& camera, const PixelRect& rect);
    void readBack(Dbi& frame);

    // Sample step along a ray in voxels of the smallest spacing (RenderOptions::stepVoxels).
    void setStepVoxels(float step) { m_stepVoxels = step; }
    // Empty-space skipping over 4^3 bricks (on by default; the pixels are the same without, as
    // RenderOptions::skipEmpty for the CPU renderer).
    void setSkipEmpty(bool on) { m_skipEmpty = on; }

private:
    void ensureTarget(int width, int height);
    void sizeOutput(int64_t pixels);
    void setUniforms(const Camera& camera, glm::vec2 viewportOrigin);
    void bindVolume();
    void readInto(Dbi& out, int x, int y);
    void uploadGradients(const Volume& volume, const Box3i& gradientBox);
    void uploadBricks(const Volume& volume, const Box3i& bricks);

    glm::ivec3 m_dims{0};
    glm::vec3 m_spacing{1.0f};
    float m_stepVoxels = 0.5f;
    bool m_skipEmpty = true;
    glm::ivec3 m_brickDims{0};
    GLuint m_densityTex = 0, m_materialTex = 0, m_gradientTex = 0, m_brickTex = 0;
    Pipeline m_pipeline;
    GLuint m_program = 0, m_emptyVao = 0;
    // The offscreen target: a framebuffer (fragment), or buffers the shader stores to (compute).
    GLuint m_fbo = 0, m_fboColor = 0, m_fboDepth = 0;
    GLuint m_outColor = 0, m_outDepth = 0;
    int64_t m_outPixels = 0;             // the buffers' size: the last rectangle's
    int m_fboWidth = 0, m_fboHeight = 0; // grows to the largest rectangle rendered
    PixelRect m_rendered;                // the last render's rectangle, at the target's corner
};

} // namespace trephine::gpu

// The server's Graphics Renderer: a CPU ray caster that turns the volume into a depth-buffered
// image whose depth is exactly what an OpenGL depth buffer would hold for the bone surface under
// the client's own matrices, so a client depth-tests its tools against it pixel for pixel.
#pragma once

#include "libsim/brick_grid.h"
#include "libsim/camera.h"
#include "libsim/dbi.h"
#include "libsim/volume.h"

#include <glm/vec3.hpp>

namespace trephine {

class ThreadPool;

struct RenderOptions {
    // Sample spacing along a ray, in voxels of the smallest spacing. Samples sit at fixed
    // multiples of the step from the eye, so skipping never moves them.
    float stepVoxels = 0.5f;
    bool skipEmpty = true; // empty-space skipping with the brick grid (bit-identical either way)
    int tileSize = 16;     // pixels per tile edge handed to one worker (claimed dynamically)
};

// Shading uses the density gradient from central differences at the eight voxels around the hit,
// trilinearly interpolated: it reads voxels within 2 of the hit (see kDirtyStencilVoxels).
// Regula falsi steps (one sample each) between the last sample outside and the first inside,
// before the final secant.
inline constexpr int kRefineSteps = 1;

// Base colours (sRGB 8 bit) per material; shading scales them.
glm::vec3 materialColor(Material m);

// What the ray through one pixel centre sees.
struct RayHit {
    bool hit = false;
    glm::dvec3 position{0.0}; // object space, mm
    glm::vec3 normal{0.0f};   // unit, pointing out of the bone
    Material material = Material::Air;
    float depth = kBackgroundDepth; // GL window depth
    double distanceMm = 0.0;        // from the eye along the ray
    glm::vec3 direction{0.0f};      // unit ray direction, object space
};

class Renderer {
public:
    // The renderer reads `volume` (which must outlive it) and builds its brick grid. After
    // changing voxels call volumeChanged with the changed box before the next render. `pool`
    // may be null (render on the calling thread).
    explicit Renderer(const Volume& volume, ThreadPool* pool = nullptr, RenderOptions options = {});

    // Keeps the brick grid in step with erosion: only bricks near `changed` are recomputed.
    void volumeChanged(const Box3i& changed);
    // Rebuilds the brick grid from scratch (after replacing the volume's contents wholesale).
    void rebuild();

    const BrickGrid& bricks() const { return m_bricks; }
    const RenderOptions& options() const { return m_options; }
    void setOptions(const RenderOptions& options) { m_options = options; }
    void setPool(ThreadPool* pool) { m_pool = pool; }

    // A full camera.width x camera.height image.
    Dbi render(const Camera& camera) const;
    // Renders the pixels of `rect` (row 0 at the bottom, clipped to the window) into `frame`, a
    // camera-sized image, at the same place; the pixels are bit for bit those a full render
    // gives there.
    void render(const Camera& camera, const PixelRect& rect, Dbi& frame) const;
    // The pixels of `rect` as an image of the rectangle's size; rect must lie inside the window.
    Dbi renderRect(const Camera& camera, const PixelRect& rect) const;

    // The ray through pixel (x, y) (row 0 at the bottom), exactly as render() traces it.
    RayHit castRay(const Camera& camera, int x, int y) const;

private:
    void renderInto(const Camera& camera, const PixelRect& rect, Dbi& out, int outX,
                    int outY) const;

    const Volume* m_volume;
    ThreadPool* m_pool;
    RenderOptions m_options;
    BrickGrid m_bricks;
};

} // namespace trephine

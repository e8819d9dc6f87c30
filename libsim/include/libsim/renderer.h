// The server's Graphics Renderer: a CPU ray caster that turns the volume into a depth-buffered
// image whose depth is exactly what an OpenGL depth buffer would hold for the bone surface under
// the client's own matrices, so a client depth-tests its tools against it pixel for pixel.
#pragma once

#include "libsim/brick_grid.h"
#include "libsim/camera.h"
#include "libsim/dbi.h"
#include "libsim/unset_allocator.h"
#include "libsim/volume.h"

#include <cstdint>
#include <functional>
#include <glm/vec3.hpp>
#include <vector>

namespace trephine {

class ThreadPool;

struct RenderOptions {
    // Sample spacing along a ray, in voxels of the smallest spacing. Samples sit at fixed
    // multiples of the step from the eye, so skipping never moves them.
    float stepVoxels = 0.5f;
    bool skipEmpty = true; // empty-space skipping with the brick grid (bit-identical either way)
    int tileSize = 16;     // pixels per tile edge handed to one worker (claimed dynamically)
    // Refine and differentiate hits eight at a time in vectors (bit-identical either way).
    bool batchHits = true;
    // Run the tile loop's AVX2 build where the CPU has AVX2 (bit-identical either way: the same
    // operations, no FMA); false keeps baseline x86-64.
    bool avx2 = true;
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

class Renderer;

// Per view: where each pixel's ray first reached the iso-value last time, as an index on the
// ray's fixed sample grid (sample k at t = k * step from the eye). Erosion only lowers densities
// and the trilinear sample is monotone in its corners, so no sample before that index can be
// inside after erosion: a re-render of a dirty rectangle resumes there instead of at the eye,
// bit for bit the same pixels. Keep one per view (camera and window size) and pass it to every
// render of that view. A cache made for another camera, another sample step, another volume or
// before Renderer::rebuild() is never used: the render that finds it so starts it afresh.
// One render call at a time may use a cache; distinct caches may be used concurrently.
class HitCache {
public:
    // Pixels whose ray can never reach the iso-value (no hit, and erosion cannot make one).
    static constexpr int32_t kNever = INT32_MAX;

    HitCache() = default;
    // Forgets everything; the next render starts every ray at the eye again.
    void clear();
    // True when the cache holds resume indices for `camera` under `renderer`'s current volume.
    bool validFor(const Renderer& renderer, const Camera& camera) const;
    // The resume index of pixel (x, y) (row 0 at the bottom): 0 when unknown, kNever for a ray
    // that cannot hit.
    int32_t resumeIndex(int x, int y) const {
        return m_rowKnown[size_t(y)] ? m_resume[size_t(y) * size_t(m_camera.width) + size_t(x)] : 0;
    }
    // Pixels rendered since the cache was (re)started whose resume index was known.
    int64_t resumed() const { return m_resumed; }
    // Pixels Renderer::renderChanged left as they were since the cache was (re)started.
    int64_t kept() const { return m_kept; }

private:
    friend class Renderer;
    Camera m_camera{};
    uint64_t m_generation = 0; // Renderer generation the indices were computed under; 0: none
    float m_stepVoxels = 0.0f;
    glm::vec3 m_spacing{0.0f};
    // Per pixel, row 0 at the bottom; rows are zeroed as renders reach them (m_rowKnown), so a
    // new cache's arrays are left unset: zeroing a new 1920 x 1080 view's 10 MB held the
    // simulation step up to 10 ms.
    std::vector<int32_t, UnsetAllocator<int32_t>> m_resume;
    // Per pixel: 1 when m_resume is a hit after the first sample of the ray's span (so a re-render
    // that finds it still inside needs neither the span nor a brick look-up).
    std::vector<uint8_t, UnsetAllocator<uint8_t>> m_inside;
    // Per row: 1 once the row's entries above are this start's (zeroed, then rendered). A restart
    // clears these only, and a render zeroes the rows it reaches, so a new 2048² view's start
    // costs its first pieces microseconds, not a 20 MB clear.
    std::vector<uint8_t> m_rowKnown;
    int64_t m_resumed = 0;
    int64_t m_kept = 0;
};

class Renderer {
public:
    // The renderer reads `volume` (which must outlive it) and builds its brick grid. After
    // changing voxels call volumeChanged with the changed box before the next render. `pool`
    // may be null (render on the calling thread).
    explicit Renderer(const Volume& volume, ThreadPool* pool = nullptr, RenderOptions options = {});

    // Keeps the brick grid in step with erosion: only bricks near `changed` are recomputed.
    // Promises that densities in `changed` only went down (drilling, cutting): hit caches stay
    // valid. Should a brick gain surface all the same, caches are invalidated (a safety net, not
    // a licence: a rise inside a brick that already held surface cannot be seen here).
    void volumeChanged(const Box3i& changed);
    // Rebuilds the brick grid from scratch (after replacing the volume's contents wholesale, or
    // any change that may raise a density) and invalidates every HitCache.
    void rebuild();
    // Identifies the volume state hit caches were computed under; changes on rebuild(). Unique
    // across renderers.
    uint64_t generation() const { return m_generation; }

    const Volume& volume() const { return *m_volume; }
    const BrickGrid& bricks() const { return m_bricks; }
    const RenderOptions& options() const { return m_options; }
    void setOptions(const RenderOptions& options) { m_options = options; }
    void setPool(ThreadPool* pool) { m_pool = pool; }
    // renderBulk's pool (ThreadPool's background kind); null: the pool above.
    void setBulkPool(ThreadPool* pool) { m_bulkPool = pool; }

    // A full camera.width x camera.height image.
    Dbi render(const Camera& camera) const;
    // Renders the pixels of `rect` (row 0 at the bottom, clipped to the window) into `frame`, a
    // camera-sized image, at the same place; the pixels are bit for bit those a full render
    // gives there.
    void render(const Camera& camera, const PixelRect& rect, Dbi& frame) const;
    // The same, resuming each ray at its cached first hit and storing the new ones (see
    // HitCache). Pixels are bit for bit those of the render without a cache. A cache that is not
    // valid for this camera is restarted first (then this render costs what an uncached one
    // does, and fills the cache for the pixels of `rect`). `cache` may be null.
    void render(const Camera& camera, const PixelRect& rect, Dbi& frame, HitCache* cache) const;
    // A re-render after erosion: as render(camera, rect, frame, &cache), but a pixel whose
    // cached first hit lies clear of `changed` (farther than a hit reads, kDirtyStencilVoxels),
    // or whose ray can never hit, keeps its values in `frame`: erosion cannot move that hit. The
    // caller promises that `frame`'s pixels in `rect` were rendered through `cache` (or are
    // unknown to it) and that every voxel changed since lies in `changed`. Bit for bit a full
    // render's pixels; a drilling step's rectangle keeps its corners (docs/rendering.md).
    void renderChanged(const Camera& camera, const PixelRect& rect, Dbi& frame, HitCache& cache,
                       const Box3i& changed) const;
    // A full frame that also fills `cache`.
    Dbi render(const Camera& camera, HitCache* cache) const;
    // A piece of bulk work (a new view's rows) that gives way to others' updates within one
    // tile's time: as render(camera, rect, frame, cache), on the bulk pool if there is one, in
    // columns of tiles from the left (each the rect's height), asking `stop` before each column
    // past the first `atLeast` pixels' worth: once it says so, no more start. Returns the width
    // done from rect.x (all of it when never stopped).
    int renderBulk(const Camera& camera, const PixelRect& rect, Dbi& frame, HitCache* cache,
                   const std::function<bool()>& stop, int atLeast = 0) const;
    // The pixels of `rect` as an image of the rectangle's size; rect must lie inside the window.
    Dbi renderRect(const Camera& camera, const PixelRect& rect) const;

    // The ray through pixel (x, y) (row 0 at the bottom), exactly as render() traces it.
    RayHit castRay(const Camera& camera, int x, int y) const;

private:
    // Tiles of `tile` pixels square; with `stop` (renderBulk's) columns of the rect's height on
    // `pool`, and the tiles done are returned.
    struct Tiling {
        ThreadPool* pool = nullptr; // else m_pool
        const std::function<bool()>* stop = nullptr;
        int atLeast = 0;
    };
    // render()'s first step: `rect` inside the frame and the camera's window, and `cache`
    // restarted if it is not valid for the camera.
    PixelRect prepare(const Camera& camera, const PixelRect& rect, const Dbi& frame,
                      HitCache* cache) const;
    // `changed`: renderChanged's box (with a cache), else every pixel is rendered.
    int renderInto(const Camera& camera, const PixelRect& rect, Dbi& out, int outX, int outY,
                   HitCache* cache, const Tiling& tiling, const Box3i* changed = nullptr) const;

    const Volume* m_volume;
    ThreadPool* m_pool;
    ThreadPool* m_bulkPool = nullptr;
    RenderOptions m_options;
    BrickGrid m_bricks;
    uint64_t m_generation;
};

} // namespace trephine

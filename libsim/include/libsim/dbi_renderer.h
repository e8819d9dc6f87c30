// What the server renders DBIs through: the CPU ray caster (CpuDbiRenderer, the default) or the
// GPU one (libsim_gpu/gpu_renderer.h). Both give the same pictures within the tolerance
// docs/rendering.md states, and each gives a rectangle bit for bit as its full frame.
#pragma once

#include "libsim/box.h"
#include "libsim/camera.h"
#include "libsim/dbi.h"
#include "libsim/renderer.h"

#include <functional>
#include <memory>
#include <string>

namespace trephine {

class ThreadPool;

class DbiRenderer {
public:
    virtual ~DbiRenderer() = default;
    // Densities in `changed` only went down (erosion): see Renderer::volumeChanged.
    virtual void volumeChanged(const Box3i& changed) = 0;
    // Anything else changed the volume (voxels written wholesale).
    virtual void rebuild() = 0;
    // The pixels of `rect` (row 0 at the bottom, clipped to the window) into the camera-sized
    // `frame` at their place. `cache` is the view's HitCache, which only the CPU renderer reads.
    virtual void render(const Camera& camera, const PixelRect& rect, Dbi& frame,
                        HitCache* cache) = 0;
    // A re-render of `rect` after erosion inside `changed` since the frame's pixels there were
    // rendered through `cache` (Renderer::renderChanged): a renderer that can tell which pixels
    // erosion cannot reach keeps them; the rest render it all.
    virtual void renderChanged(const Camera& camera, const PixelRect& rect, Dbi& frame,
                               HitCache& cache, const Box3i& changed) {
        (void)changed;
        render(camera, rect, frame, &cache);
    }
    // Bulk work: as render(), but may stop early once `stop` says so after `atLeast` pixels'
    // worth, and runs on the bulk pool if one is set (Renderer::renderBulk); returns the width
    // done from rect.x, all its rows. A renderer that cannot stop part-way renders all of it.
    virtual int renderBulk(const Camera& camera, const PixelRect& rect, Dbi& frame, HitCache* cache,
                           const std::function<bool()>& stop, int atLeast) {
        (void)stop;
        (void)atLeast;
        render(camera, rect, frame, cache);
        return rect.w;
    }
    // renderBulk's threads (ThreadPool's background kind), for a renderer with a pool.
    virtual void setBulkPool(ThreadPool* pool) { (void)pool; }
    // A full frame.
    virtual Dbi render(const Camera& camera) = 0;
    // One line for people: "CPU, 2 threads", "GPU: <GL renderer>".
    virtual std::string describe() const = 0;
};

// Makes the renderer of a volume (which outlives it); `pool` is the CPU renderer's tile pool.
using DbiRendererFactory =
    std::function<std::unique_ptr<DbiRenderer>(const Volume& volume, ThreadPool* pool)>;

// The CPU ray caster behind the interface.
class CpuDbiRenderer final : public DbiRenderer {
public:
    CpuDbiRenderer(const Volume& volume, ThreadPool* pool);
    void volumeChanged(const Box3i& changed) override { m_renderer.volumeChanged(changed); }
    void rebuild() override { m_renderer.rebuild(); }
    void render(const Camera& camera, const PixelRect& rect, Dbi& frame, HitCache* cache) override {
        m_renderer.render(camera, rect, frame, cache);
    }
    void renderChanged(const Camera& camera, const PixelRect& rect, Dbi& frame, HitCache& cache,
                       const Box3i& changed) override {
        m_renderer.renderChanged(camera, rect, frame, cache, changed);
    }
    int renderBulk(const Camera& camera, const PixelRect& rect, Dbi& frame, HitCache* cache,
                   const std::function<bool()>& stop, int atLeast) override {
        return m_renderer.renderBulk(camera, rect, frame, cache, stop, atLeast);
    }
    void setBulkPool(ThreadPool* pool) override { m_renderer.setBulkPool(pool); }
    Dbi render(const Camera& camera) override { return m_renderer.render(camera); }
    std::string describe() const override;
    Renderer& renderer() { return m_renderer; }

private:
    Renderer m_renderer;
    int m_threads;
};

// Renders through the renderer `primary` makes until making it or a call of it throws, then
// through the renderer `fallback` makes (from the same volume, as it is then), from that call on:
// `onFallback` is told once, with the primary's error. The server runs a configured renderer (the
// GPU's) behind it, so a GPU that cannot hold the volume, or fails mid-session (out of memory, a
// lost device), costs the session its speed, not its drilling.
class FallbackDbiRenderer final : public DbiRenderer {
public:
    using Make = std::function<std::unique_ptr<DbiRenderer>()>;
    using Told = std::function<void(const std::string& primary, const std::string& error,
                                    const std::string& fallback)>;
    FallbackDbiRenderer(const Make& primary, Make fallback, Told onFallback);
    void volumeChanged(const Box3i& changed) override;
    void rebuild() override;
    void render(const Camera& camera, const PixelRect& rect, Dbi& frame, HitCache* cache) override;
    void renderChanged(const Camera& camera, const PixelRect& rect, Dbi& frame, HitCache& cache,
                       const Box3i& changed) override;
    int renderBulk(const Camera& camera, const PixelRect& rect, Dbi& frame, HitCache* cache,
                   const std::function<bool()>& stop, int atLeast) override;
    void setBulkPool(ThreadPool* pool) override;
    Dbi render(const Camera& camera) override;
    std::string describe() const override { return m_current->describe(); }

private:
    // f(renderer) on the current renderer; on the primary's first throw, on the fallback again.
    template <typename F>
    auto guarded(F&& f);
    void fallBack(const std::string& primary, const std::string& error);

    std::unique_ptr<DbiRenderer> m_current;
    Make m_fallback; // empty once used
    Told m_told;
    ThreadPool* m_bulkPool = nullptr;
};

} // namespace trephine

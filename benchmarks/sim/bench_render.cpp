// The server renderer's budgets, each printed beside its target (counters *_ms and target_ms):
//   full frame of skull:256, all cores and one thread  500x500 target 12 ms, 1920x1080 100 ms;
//                                                     speedup of all cores over one: 1.8 on 2
//   dirty rectangle 64^2 / 128^2 after a burr stroke  target 0.3 ms / 1 ms, without and with the
//                                                     view's hit cache (the server's path), and
//                                                     cached on one thread (ns_per_px)
//   one drilling step's BB_screen, render() against   (no target: changed_us, render_us, kept)
//   renderChanged(), 500^2 and 1920x1080
//   BB_volume -> BB_screen projection                 (no target: it should be negligible)
//   the paper's view: 128^3 at 330.2 mm, 60 deg, 500x500
//   the update study's cut in that view: an N^3 box (10, 40, 80) cut out at the surface, its
//   BB_screen re-rendered through the view's cache (frame_ms, ns_per_px), the full frame after
//   the cut, and the brick grid's update for the cut (update_us)
// Filter with --benchmark_filter=Render.
#include "libsim/camera.h"
#include "libsim/dirty_rect.h"
#include "libsim/drill.h"
#include "libsim/renderer.h"
#include "libsim/skull.h"
#include "libsim/stats.h"
#include "libsim/thread_pool.h"

#include <benchmark/benchmark.h>
#include <chrono>
#include <glm/gtx/quaternion.hpp>
#include <map>
#include <memory>
#include <span>

namespace trephine {
namespace {

using Clock = std::chrono::steady_clock;

// One skull:256 with a burr stroke at the default site, shared by the benchmarks (building it
// takes most of a second).
struct Scene {
    Volume volume;
    SurfaceSite site;
    Box3i stroke; // BB_volume of the burr stroke
    std::unique_ptr<ThreadPool> pool;
    std::unique_ptr<Renderer> renderer;
    Camera camera;
    // The working view's hit cache as a full render before the stroke left it: what the server
    // holds when the stroke's dirty rectangle is re-rendered.
    HitCache cacheBeforeStroke;

    explicit Scene(int n) : volume(makeSkull(n)) {
        site = defaultBurrSite(volume);
        pool = std::make_unique<ThreadPool>();
        renderer = std::make_unique<Renderer>(volume, pool.get());
        camera = cameraPreset("working", volume, {500, 500});
        renderer->render(camera, &cacheBeforeStroke);
        // A 4 mm burr pressed 2 mm into the bone along the normal, then moved 3 mm sideways.
        Driller driller(ToolShape::burr(4.0f));
        ToolPose pose;
        pose.orientation = glm::rotation(glm::vec3(0, 0, 1), site.normal);
        glm::vec3 side = glm::normalize(glm::cross(site.normal, glm::vec3(0, 0, 1)));
        for (int i = 0; i <= 30; ++i) {
            pose.position = site.position - site.normal * 2.0f * std::min(1.0f, i / 10.0f) +
                            side * (0.1f * std::max(0, i - 10) * 1.5f);
            for (int k = 0; k < 4; ++k)
                stroke.merge(driller.drill(volume, pose, 1.0f, 0.02f).changed);
        }
        renderer->volumeChanged(stroke);
    }
};

Scene& skull256() {
    static Scene scene(256);
    return scene;
}

void reportMs(benchmark::State& state, double totalMs, double targetMs, double floorMs = 0.0) {
    double per = state.iterations() ? totalMs / double(state.iterations()) : 0.0;
    state.counters["frame_ms"] = per;
    state.counters["target_ms"] = targetMs;
    if (floorMs > 0.0)
        state.counters["floor_ms"] = floorMs;
    state.counters["threads"] = skull256().pool->size();
}

// Nanoseconds per pixel of a rectangle rendered in `ms`.
double rectNsPerPixel(double ms, const PixelRect& rect) {
    return rect.area() ? ms * 1e6 / double(rect.area()) : 0.0;
}

// A full working-view frame of skull:256 as a user waits for it (a join, a view change, a
// resize): width x height from the arguments. Each iteration renders the frame once on all cores
// and once on the calling thread alone, interleaved, so the two figures and their ratio come from
// one run on the same machine state. frame_ms / p50_ms: all cores (the time, target_ms beside it);
// one_thread_ms: the median on one thread; speedup: one_thread_ms / p50_ms (target 1.8 on 2 cores).
void BM_RenderFullFrameSkull256(benchmark::State& state) {
    Scene& s = skull256();
    const glm::ivec2 size(int(state.range(0)), int(state.range(1)));
    const Camera camera = cameraPreset("working", s.volume, size);
    ThreadPool pool(0);
    Renderer all(s.volume, &pool), one(s.volume, nullptr);
    Dbi frame(size.x, size.y);
    double total = 0.0;
    SampleWindow allCores(1 << 12), oneThread(1 << 12);
    for (auto _ : state) {
        auto t0 = Clock::now();
        all.render(camera, frame.bounds(), frame);
        const double ms = std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
        total += ms;
        allCores.add(ms);
        benchmark::DoNotOptimize(frame.depth());
        state.PauseTiming();
        t0 = Clock::now();
        one.render(camera, frame.bounds(), frame);
        oneThread.add(std::chrono::duration<double, std::milli>(Clock::now() - t0).count());
        benchmark::DoNotOptimize(frame.depth());
        state.ResumeTiming();
    }
    const bool small = size.x * size.y <= 500 * 500;
    reportMs(state, total, small ? 12.0 : 100.0);
    const double p50 = allCores.percentile(50), p50One = oneThread.percentile(50);
    state.counters["p50_ms"] = p50;
    state.counters["one_thread_ms"] = p50One;
    state.counters["speedup"] = p50 > 0.0 ? p50One / p50 : 0.0;
    state.counters["target_speedup"] = 1.8; // on 2 cores (issue 34)
    state.counters["threads"] = pool.size();
    state.SetItemsProcessed(state.iterations() * size.x * size.y);
}
BENCHMARK(BM_RenderFullFrameSkull256)
    ->Args({500, 500})
    ->Args({1920, 1080})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

// A square of `size` pixels centred on the burr stroke's screen position, as re-rendered after
// drilling.
void BM_RenderDirtyRect(benchmark::State& state) {
    Scene& s = skull256();
    const int size = int(state.range(0));
    PixelRect screen = dirtyScreenRect(s.camera, s.volume, s.stroke);
    int cx = screen.x + screen.w / 2, cy = screen.y + screen.h / 2;
    PixelRect rect = intersect({cx - size / 2, cy - size / 2, size, size}, {0, 0, 500, 500});
    Dbi frame(500, 500);
    double total = 0.0;
    for (auto _ : state) {
        auto t0 = Clock::now();
        s.renderer->render(s.camera, rect, frame);
        total += std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
        benchmark::DoNotOptimize(frame.depth());
    }
    reportMs(state, total, size <= 64 ? 0.3 : 1.0);
    state.SetItemsProcessed(state.iterations() * rect.area());
}
BENCHMARK(BM_RenderDirtyRect)->Arg(64)->Arg(128)->Unit(benchmark::kMicrosecond)->UseRealTime();

// The same rectangles re-rendered through the view's hit cache, each time from the cache as it was
// before the stroke (the copy is not timed), as the server's first re-render after a stroke.
// `pool`: the renderer's pool for the run (null: the calling thread alone).
void renderDirtyRectCached(benchmark::State& state, ThreadPool* pool) {
    Scene& s = skull256();
    const int size = int(state.range(0));
    PixelRect screen = dirtyScreenRect(s.camera, s.volume, s.stroke);
    int cx = screen.x + screen.w / 2, cy = screen.y + screen.h / 2;
    PixelRect rect = intersect({cx - size / 2, cy - size / 2, size, size}, {0, 0, 500, 500});
    Dbi frame(500, 500);
    HitCache cache;
    double total = 0.0;
    // Per render, for the median and the 90th percentile: with two threads a render's time
    // depends on how soon the second core's worker wakes, and the mean mixes both cases.
    SampleWindow perRender(1 << 16);
    // The scene's renderer: the cache belongs to it (another renderer would restart the cache).
    s.renderer->setPool(pool);
    for (auto _ : state) {
        state.PauseTiming();
        cache = s.cacheBeforeStroke;
        state.ResumeTiming();
        auto t0 = Clock::now();
        s.renderer->render(s.camera, rect, frame, &cache);
        const double ms = std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
        total += ms;
        perRender.add(ms);
        benchmark::DoNotOptimize(frame.depth());
    }
    s.renderer->setPool(s.pool.get());
    reportMs(state, total, size <= 64 ? 0.3 : 1.0);
    state.counters["p50_ms"] = perRender.percentile(50);
    state.counters["p90_ms"] = perRender.percentile(90);
    state.counters["threads"] = pool ? pool->size() : 1;
    double per = state.iterations() ? total / double(state.iterations()) : 0.0;
    state.counters["ns_per_px"] = rectNsPerPixel(per, rect);
    // Every pixel should have resumed (a cache the renderer rejected would show 0).
    state.counters["resumed"] =
        state.iterations() ? double(cache.resumed()) / double(rect.area()) : 0.0;
    state.SetItemsProcessed(state.iterations() * rect.area());
}

void BM_RenderDirtyRectCached(benchmark::State& state) {
    renderDirtyRectCached(state, skull256().pool.get());
}
BENCHMARK(BM_RenderDirtyRectCached)
    ->Arg(64)
    ->Arg(128)
    ->Unit(benchmark::kMicrosecond)
    ->UseRealTime();

// On the calling thread alone: the per-pixel cost of the renderer without the pool's hand-off,
// and much steadier than the pooled figure on a shared 2-core machine (compare builds with this).
void BM_RenderDirtyRectCachedOneThread(benchmark::State& state) {
    renderDirtyRectCached(state, nullptr);
}
BENCHMARK(BM_RenderDirtyRectCachedOneThread)
    ->Arg(64)
    ->Arg(128)
    ->Unit(benchmark::kMicrosecond)
    ->UseRealTime();

// One drilling step as the server re-renders it: a 4 mm burr 1 mm into the bone, 0.2 mm along
// the groove it has cut, in the working view of width x height (Args 0, 1) on the scene's pool
// (Arg 2 = 0) or the calling thread (1). Each iteration re-renders the step's BB_screen through
// the view's cache as it was before the step, once with render() and once with renderChanged()
// (the server's path; the time), interleaved, so their ratio comes from one run. render_us /
// changed_us: medians; kept: the share of the rectangle renderChanged left as it was.
struct DrillStep {
    Scene scene{256}; // its own skull: the shared one carries the stroke already
    Camera camera;
    HitCache cacheBefore;
    Dbi frameBefore;
    Box3i step;
    PixelRect rect;
};

DrillStep& drillStep(glm::ivec2 size) {
    static std::map<std::pair<int, int>, std::unique_ptr<DrillStep>> steps;
    std::unique_ptr<DrillStep>& d = steps[{size.x, size.y}];
    if (d)
        return *d;
    d = std::make_unique<DrillStep>();
    Scene& s = d->scene;
    d->camera = cameraPreset("working", s.volume, {size.x, size.y});
    Driller driller(ToolShape::burr(4.0f));
    ToolPose pose;
    pose.orientation = glm::rotation(glm::vec3(0, 0, 1), s.site.normal);
    const glm::vec3 side = glm::normalize(glm::cross(s.site.normal, glm::vec3(0, 0, 1)));
    auto at = [&](int i) { return s.site.position - s.site.normal * 1.0f + side * (0.2f * i); };
    for (int i = 0; i < 10; ++i) { // the groove so far
        pose.position = at(i);
        s.renderer->volumeChanged(driller.drill(s.volume, pose, 1.0f, 0.01f).changed);
    }
    d->frameBefore = s.renderer->render(d->camera, &d->cacheBefore);
    pose.position = at(10);
    d->step = driller.drill(s.volume, pose, 1.0f, 0.01f).changed;
    s.renderer->volumeChanged(d->step);
    d->rect = dirtyScreenRect(d->camera, s.volume, d->step);
    return *d;
}

void BM_RenderDrillStep(benchmark::State& state) {
    DrillStep& d = drillStep({int(state.range(0)), int(state.range(1))});
    Scene& s = d.scene;
    const Camera& camera = d.camera;
    const PixelRect& rect = d.rect;
    const Box3i& step = d.step;
    const Dbi& frameBefore = d.frameBefore;
    const HitCache& cacheBefore = d.cacheBefore;
    ThreadPool* pool = state.range(2) ? nullptr : s.pool.get();
    s.renderer->setPool(pool);
    HitCache cache;
    Dbi frame = frameBefore;
    SampleWindow plain(1 << 16), changed(1 << 16);
    int64_t kept = 0;
    for (auto _ : state) {
        state.PauseTiming();
        cache = cacheBefore;
        auto t0 = Clock::now();
        s.renderer->render(camera, rect, frame, &cache);
        plain.add(std::chrono::duration<double, std::micro>(Clock::now() - t0).count());
        benchmark::DoNotOptimize(frame.depth());
        cache = cacheBefore;
        frame.apply(frameBefore.extract(rect), rect.x, rect.y);
        state.ResumeTiming();
        t0 = Clock::now();
        s.renderer->renderChanged(camera, rect, frame, cache, step);
        changed.add(std::chrono::duration<double, std::micro>(Clock::now() - t0).count());
        benchmark::DoNotOptimize(frame.depth());
        kept = cache.kept();
    }
    s.renderer->setPool(s.pool.get());
    const double p50 = changed.percentile(50), p50Plain = plain.percentile(50);
    state.counters["render_us"] = p50Plain;
    state.counters["changed_us"] = p50;
    state.counters["speedup"] = p50 > 0.0 ? p50Plain / p50 : 0.0;
    state.counters["kept"] = rect.area() ? double(kept) / double(rect.area()) : 0.0;
    state.counters["w"] = rect.w;
    state.counters["h"] = rect.h;
    state.counters["threads"] = pool ? pool->size() : 1;
    state.SetItemsProcessed(state.iterations() * rect.area());
}
BENCHMARK(BM_RenderDrillStep)
    ->ArgsProduct({{500}, {500}, {0, 1}})
    ->ArgsProduct({{1920}, {1080}, {0, 1}})
    ->Unit(benchmark::kMicrosecond)
    ->UseRealTime();

// The stroke's own BB_screen, whatever its size (reported as w, h).
void BM_RenderStrokeBBScreen(benchmark::State& state) {
    Scene& s = skull256();
    PixelRect rect = dirtyScreenRect(s.camera, s.volume, s.stroke);
    Dbi frame(500, 500);
    double total = 0.0;
    for (auto _ : state) {
        auto t0 = Clock::now();
        s.renderer->render(s.camera, rect, frame);
        total += std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
    }
    double per = state.iterations() ? total / double(state.iterations()) : 0.0;
    state.counters["frame_ms"] = per;
    state.counters["w"] = rect.w;
    state.counters["h"] = rect.h;
    state.SetItemsProcessed(state.iterations() * rect.area());
}
BENCHMARK(BM_RenderStrokeBBScreen)->Unit(benchmark::kMicrosecond)->UseRealTime();

// Projection only: eight corners through precomputed matrices, min/max, clip.
void BM_RenderBBScreenProjection(benchmark::State& state) {
    Scene& s = skull256();
    glm::dmat4 vp = viewProjection(s.camera);
    BoxMm box = dirtyBoxMm(s.volume, s.stroke);
    for (auto _ : state) {
        benchmark::DoNotOptimize(box);
        PixelRect r = dirtyScreenRect(s.camera, vp, box);
        benchmark::DoNotOptimize(r);
    }
}
BENCHMARK(BM_RenderBBScreenProjection);

// Including building the matrices from the camera (what a caller without a cache pays).
void BM_RenderBBScreenFromCamera(benchmark::State& state) {
    Scene& s = skull256();
    for (auto _ : state) {
        PixelRect r = dirtyScreenRect(s.camera, s.volume, s.stroke);
        benchmark::DoNotOptimize(r);
    }
}
BENCHMARK(BM_RenderBBScreenFromCamera);

// Keeping the brick grid in step with the stroke's BB_volume.
void BM_RenderBrickGridUpdate(benchmark::State& state) {
    Scene& s = skull256();
    BrickGrid grid(s.volume);
    for (auto _ : state)
        grid.update(s.volume, s.stroke);
    state.counters["bricks"] = double(grid.dims().x) * grid.dims().y * grid.dims().z;
}
BENCHMARK(BM_RenderBrickGridUpdate)->Unit(benchmark::kMicrosecond);

// The paper's experiment: a 128^3 volume at 330.2 mm, 60 degrees, 500x500, spanning 300 px.
void BM_RenderPaperFrame128(benchmark::State& state) {
    static Volume volume = [] {
        Volume v = makeSkull(128);
        v.setSpacing(glm::vec3(paperSpacingMm(128)));
        return v;
    }();
    Renderer renderer(volume, skull256().pool.get());
    Camera camera = cameraPreset("paper", volume, {500, 500});
    Dbi frame(500, 500);
    double total = 0.0;
    for (auto _ : state) {
        auto t0 = Clock::now();
        renderer.render(camera, frame.bounds(), frame);
        total += std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
    }
    reportMs(state, total, 15.0);
    state.SetItemsProcessed(state.iterations() * 500 * 500);
}
BENCHMARK(BM_RenderPaperFrame128)->Unit(benchmark::kMillisecond)->UseRealTime();

// The update study's case (surfaceBox, trephine study updates): the paper's view of skull:128
// at the paper's spacing, an N^3 box centred on the middle column with its top face at the bone
// surface facing the camera, cut to air. The hole's BB_screen is re-rendered through the view's hit
// cache as it was before the cut (the server's path); the brick grid's update for the cut is timed
// on its own (the server counts it in its render stage, as grid_ms).
struct PaperHole {
    Volume volume;
    Box3i box;
    PixelRect rect;
    Camera camera;
    std::unique_ptr<Renderer> renderer;
    HitCache cacheBeforeCut;
    BrickGrid gridBeforeCut;
};

const Volume& paperSkull128() {
    static Volume volume = [] {
        Volume v = makeSkull(128);
        v.setSpacing(glm::vec3(paperSpacingMm(128)));
        return v;
    }();
    return volume;
}

PaperHole& paperHole(int n) {
    static std::map<int, std::unique_ptr<PaperHole>> holes;
    std::unique_ptr<PaperHole>& h = holes[n];
    if (!h) {
        h = std::make_unique<PaperHole>();
        h->volume = paperSkull128();
        h->camera = cameraPreset("paper", h->volume, {500, 500});
        h->renderer = std::make_unique<Renderer>(h->volume, skull256().pool.get());
        h->renderer->render(h->camera, &h->cacheBeforeCut);
        h->gridBeforeCut = h->renderer->bricks();
        h->box = surfaceBox(h->volume, n);
        h->volume.fill(h->box, 0, Material::Air);
        h->renderer->volumeChanged(h->box);
        h->rect = dirtyScreenRect(h->camera, h->volume, h->box);
    }
    return *h;
}

// Renders `rects` of the hole's view through the cache as it was before the cut, per iteration;
// returns the mean milliseconds an iteration, and the last iteration's cache in `cache`.
double renderCachedRects(benchmark::State& state, PaperHole& h, std::span<const PixelRect> rects,
                         HitCache& cache) {
    Dbi frame(500, 500);
    double total = 0.0;
    for (auto _ : state) {
        state.PauseTiming();
        cache = h.cacheBeforeCut;
        state.ResumeTiming();
        auto t0 = Clock::now();
        for (const PixelRect& r : rects)
            h.renderer->render(h.camera, r, frame, &cache);
        total += std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
        benchmark::DoNotOptimize(frame.depth());
    }
    return state.iterations() ? total / double(state.iterations()) : 0.0;
}

void BM_RenderPaperHoleCached(benchmark::State& state) {
    PaperHole& h = paperHole(int(state.range(0)));
    HitCache cache;
    double per = renderCachedRects(state, h, {&h.rect, 1}, cache);
    state.counters["frame_ms"] = per;
    state.counters["ns_per_px"] = rectNsPerPixel(per, h.rect);
    state.counters["w"] = h.rect.w;
    state.counters["h"] = h.rect.h;
    state.counters["threads"] = skull256().pool->size();
    state.counters["resumed"] =
        state.iterations() ? double(cache.resumed()) / double(h.rect.area()) : 0.0;
    state.SetItemsProcessed(state.iterations() * h.rect.area());
}
BENCHMARK(BM_RenderPaperHoleCached)
    ->Arg(10)
    ->Arg(40)
    ->Arg(80)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

// The full frame of the same view after the cut, for the cost per pixel of a whole frame: from
// the eye (Arg 2 = 0), or resuming every ray at its first hit before the cut (1): the
// replicated-volume client's re-render of its view (SessionClient keeps a HitCache as the DBI
// server does).
void BM_RenderPaperHoleFullFrame(benchmark::State& state) {
    PaperHole& h = paperHole(int(state.range(0)));
    const bool cached = state.range(1) != 0;
    Dbi frame(500, 500);
    HitCache cache;
    double total = 0.0;
    for (auto _ : state) {
        if (cached) {
            state.PauseTiming();
            cache = h.cacheBeforeCut;
            state.ResumeTiming();
        }
        auto t0 = Clock::now();
        h.renderer->render(h.camera, frame.bounds(), frame, cached ? &cache : nullptr);
        total += std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
        benchmark::DoNotOptimize(frame.depth());
    }
    double per = state.iterations() ? total / double(state.iterations()) : 0.0;
    state.counters["frame_ms"] = per;
    state.counters["ns_per_px"] = rectNsPerPixel(per, frame.bounds());
    state.counters["threads"] = skull256().pool->size();
    state.SetItemsProcessed(state.iterations() * 500 * 500);
}
BENCHMARK(BM_RenderPaperHoleFullFrame)
    ->ArgsProduct({{10, 80}, {0, 1}})
    ->ArgNames({"box", "cached"})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

// The replicated-volume client's view less the hole's BB_screen (the four rectangles around it),
// through the cache as BM_RenderPaperHoleFullFrame/cached:1 does: with BM_RenderPaperHoleCached
// (BB_screen alone) it splits the volume client's re-render into the rays the DBI server casts
// too and the rest. The two add up to the full frame (80^3, one thread: 2.25 + 3.88 ms against
// 6.14 ms), so the server's rays cost the volume client what they cost the server, and
// `study updates` takes them out of both cycles for its free-ray-casting ceiling.
void BM_RenderPaperHoleOutsideRect(benchmark::State& state) {
    PaperHole& h = paperHole(int(state.range(0)));
    const PixelRect& r = h.rect;
    const PixelRect parts[4] = {
        PixelRect(0, 0, 500, r.y), PixelRect(0, r.y + r.h, 500, 500 - r.y - r.h),
        PixelRect(0, r.y, r.x, r.h), PixelRect(r.x + r.w, r.y, 500 - r.x - r.w, r.h)};
    HitCache cache;
    state.counters["frame_ms"] = renderCachedRects(state, h, parts, cache);
    state.counters["threads"] = skull256().pool->size();
}
BENCHMARK(BM_RenderPaperHoleOutsideRect)->Arg(80)->Unit(benchmark::kMillisecond)->UseRealTime();

// Keeping the brick grid in step with the cut (one thread; part of the server's render stage, as
// grid_ms).
void BM_RenderPaperHoleGridUpdate(benchmark::State& state) {
    PaperHole& h = paperHole(int(state.range(0)));
    BrickGrid grid;
    double total = 0.0;
    for (auto _ : state) {
        state.PauseTiming();
        grid = h.gridBeforeCut;
        state.ResumeTiming();
        auto t0 = Clock::now();
        grid.update(h.volume, h.box);
        total += std::chrono::duration<double, std::micro>(Clock::now() - t0).count();
        benchmark::DoNotOptimize(grid.distanceData());
    }
    state.counters["update_us"] = state.iterations() ? total / double(state.iterations()) : 0.0;
}
BENCHMARK(BM_RenderPaperHoleGridUpdate)
    ->Arg(10)
    ->Arg(40)
    ->Arg(80)
    ->Unit(benchmark::kMicrosecond)
    ->UseRealTime();

} // namespace
} // namespace trephine

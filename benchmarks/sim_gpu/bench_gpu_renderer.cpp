// The server's GPU renderer (OpenGL through EGL, no display), each figure beside its target
// (frame_ms, target_ms) and labelled with the GL renderer that ran it:
//   full 1920x1080 working-view frame of skull:512     target 5 ms on a GPU (issue 34)
//   full 500x500 working-view frame of skull:256        beside the CPU renderer's, same run
//   a 64^2 dirty rectangle of skull:256 (the server's path after drilling: render + read back)
//   the 1080p frame's parts (cast to glFinish, read back) in either pipeline and the frame in bands
//   of rows, as the server's step renders a new view (StepConfig::chunkPixels pixels a band)
// On llvmpipe (no GPU) the figures only say that it works. Filter with --benchmark_filter=Gpu.
#include "libsim_gpu/gl.h"
#include "libsim_gpu/gpu_renderer.h"
#include "libsim_gpu/volume_raycaster.h"

#include "libsim/camera.h"
#include "libsim/renderer.h"
#include "libsim/skull.h"
#include "libsim/thread_pool.h"

#include <benchmark/benchmark.h>

#include <algorithm>
#include <chrono>
#include <map>
#include <memory>
#include <string>

namespace trephine {
namespace {

using Clock = std::chrono::steady_clock;

// One skull per size, made once (skull:512 takes several seconds).
const Volume& skull(int n) {
    static std::map<int, std::unique_ptr<Volume>> made;
    auto& v = made[n];
    if (!v)
        v = std::make_unique<Volume>(makeSkull(n));
    return *v;
}

void report(benchmark::State& state, double totalMs, double targetMs, const PixelRect& rect) {
    state.counters["frame_ms"] = state.iterations() ? totalMs / double(state.iterations()) : 0.0;
    if (targetMs > 0)
        state.counters["target_ms"] = targetMs;
    state.SetItemsProcessed(state.iterations() * rect.area());
}

// The process's EGL context, or null with the benchmark skipped saying why.
std::shared_ptr<gpu::EglContext> context(benchmark::State& state) {
    std::string why;
    auto egl = gpu::EglContext::shared(&why);
    if (!egl)
        state.SkipWithError(("no OpenGL through EGL: " + why).c_str());
    return egl;
}

// Renders `rect` of the working view of skull:n at width x height on the GPU, as the server does:
// the whole frame (rectSize 0), a centred rectSize^2 rectangle, or the frame in bands of rows of
// about bandPixels each, as the server's step renders a new view.
void gpuRender(benchmark::State& state, int n, int width, int height, int rectSize, double targetMs,
               int64_t bandPixels = 0) {
    const auto egl = context(state);
    if (!egl)
        return;
    const Volume& volume = skull(n);
    gpu::GpuRenderer renderer(volume, egl);
    const Camera camera = cameraPreset("working", volume, {width, height});
    Dbi frame(width, height);
    PixelRect rect = frame.bounds();
    if (rectSize > 0) // centred on the view, where the burr site is
        rect = {width / 2 - rectSize / 2, height / 2 - rectSize / 2, rectSize, rectSize};
    const int rows = bandPixels > 0 ? int(std::clamp<int64_t>(bandPixels / width, 1, height)) : 0;
    renderer.render(camera, rect, frame, nullptr); // shader compile and first use outside
    double total = 0.0;
    for (auto _ : state) {
        const auto t0 = Clock::now();
        if (rows == 0)
            renderer.render(camera, rect, frame, nullptr);
        for (int y = 0; rows > 0 && y < height; y += rows)
            renderer.render(camera, {0, y, width, std::min(rows, height - y)}, frame, nullptr);
        total += std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
        benchmark::DoNotOptimize(frame.depth());
    }
    if (rows > 0)
        state.counters["bands"] = double((height + rows - 1) / rows);
    report(state, total, targetMs, rect);
    state.SetLabel(renderer.describe());
}

void BM_GpuFrameSkull512At1080p(benchmark::State& state) {
    gpuRender(state, 512, 1920, 1080, 0, 5.0);
}
BENCHMARK(BM_GpuFrameSkull512At1080p)->Unit(benchmark::kMillisecond)->UseRealTime();

void BM_GpuFrameSkull256At500(benchmark::State& state) {
    gpuRender(state, 256, 500, 500, 0, 0.0);
}
BENCHMARK(BM_GpuFrameSkull256At500)->Unit(benchmark::kMillisecond)->UseRealTime();

void BM_GpuDirtyRectSkull256(benchmark::State& state) {
    gpuRender(state, 256, 500, 500, int(state.range(0)), 0.0);
}
BENCHMARK(BM_GpuDirtyRectSkull256)->Arg(64)->Unit(benchmark::kMicrosecond)->UseRealTime();

// The 1080p frame of skull:512 in its two parts, the cast (to glFinish) and the read back, in
// the fragment pipeline (arg 0, the window's) and the compute one (arg 1, the server's).
void BM_GpuFrameSkull512At1080pParts(benchmark::State& state) {
    const auto egl = context(state);
    if (!egl)
        return;
    if (state.range(0) && !egl->info().compute) {
        state.SkipWithError(("OpenGL " + egl->info().version + ": no compute shaders").c_str());
        return;
    }
    const Volume& volume = skull(512);
    gpu::EglContext::Current current(*egl);
    gpu::VolumeRaycaster caster(state.range(0) ? gpu::VolumeRaycaster::Pipeline::Compute
                                               : gpu::VolumeRaycaster::Pipeline::Fragment);
    caster.upload(volume);
    const Camera camera = cameraPreset("working", volume, {1920, 1080});
    Dbi frame(1920, 1080);
    caster.render(camera, frame.bounds());
    caster.readBack(frame);
    double draw = 0.0, read = 0.0;
    for (auto _ : state) {
        const auto t0 = Clock::now();
        caster.render(camera, frame.bounds());
        glFinish();
        const auto t1 = Clock::now();
        caster.readBack(frame);
        const auto t2 = Clock::now();
        draw += std::chrono::duration<double, std::milli>(t1 - t0).count();
        read += std::chrono::duration<double, std::milli>(t2 - t1).count();
        benchmark::DoNotOptimize(frame.depth());
    }
    const double n = std::max<double>(1.0, double(state.iterations()));
    state.counters["cast_ms"] = draw / n;
    state.counters["read_ms"] = read / n;
    report(state, draw + read, 5.0, frame.bounds());
    state.SetLabel((state.range(0) ? "compute, " : "fragment, ") + egl->info().renderer);
}
BENCHMARK(BM_GpuFrameSkull512At1080pParts)
    ->Arg(0)
    ->Arg(1)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

// The 1080p frame of skull:512 rendered and read back in bands of rows of about range(0)
// pixels each, as the server's step renders a new view (8192: StepConfig's chunkPixels).
void BM_GpuFrameSkull512At1080pInBands(benchmark::State& state) {
    gpuRender(state, 512, 1920, 1080, 0, 5.0, state.range(0));
}
BENCHMARK(BM_GpuFrameSkull512At1080pInBands)
    ->Arg(8192)
    ->Arg(65536)
    ->Arg(1 << 19)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

// The CPU renderer's frame of the same view in the same run, for the ratio (all cores).
void BM_CpuFrameSkull256At500(benchmark::State& state) {
    const Volume& volume = skull(256);
    ThreadPool pool;
    Renderer renderer(volume, &pool);
    const Camera camera = cameraPreset("working", volume, {500, 500});
    Dbi frame(500, 500);
    double total = 0.0;
    for (auto _ : state) {
        const auto t0 = Clock::now();
        renderer.render(camera, frame.bounds(), frame);
        total += std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
        benchmark::DoNotOptimize(frame.depth());
    }
    report(state, total, 0.0, frame.bounds());
    state.counters["threads"] = pool.size();
}
BENCHMARK(BM_CpuFrameSkull256At500)->Unit(benchmark::kMillisecond)->UseRealTime();

} // namespace
} // namespace trephine

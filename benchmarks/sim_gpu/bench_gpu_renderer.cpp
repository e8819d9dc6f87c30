// The server's GPU renderer (OpenGL through EGL, no display), each figure beside its target
// (frame_ms, target_ms) and labelled with the GL renderer that ran it:
//   full 1920x1080 working-view frame of skull:512     target 5 ms on a GPU (issue 34)
//   full 500x500 working-view frame of skull:256        beside the CPU renderer's, same run
//   a 64^2 dirty rectangle of skull:256 (the server's path after drilling: render + read back)
// On llvmpipe (no GPU) the figures only say that it works. Filter with --benchmark_filter=Gpu.
#include "libsim_gpu/gpu_renderer.h"

#include "libsim/camera.h"
#include "libsim/renderer.h"
#include "libsim/skull.h"
#include "libsim/thread_pool.h"

#include <benchmark/benchmark.h>

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

// Renders `rect` of the working view of skull:n at width x height on the GPU, as the server does.
void gpuRender(benchmark::State& state, int n, int width, int height, int rectSize,
               double targetMs) {
    std::string why;
    auto egl = gpu::EglContext::shared(&why);
    if (!egl) {
        state.SkipWithError(("no OpenGL through EGL: " + why).c_str());
        return;
    }
    const Volume& volume = skull(n);
    gpu::GpuRenderer renderer(volume, egl);
    const Camera camera = cameraPreset("working", volume, {width, height});
    Dbi frame(width, height);
    PixelRect rect = frame.bounds();
    if (rectSize > 0) // centred on the view, where the burr site is
        rect = {width / 2 - rectSize / 2, height / 2 - rectSize / 2, rectSize, rectSize};
    renderer.render(camera, rect, frame, nullptr); // shader compile and first use outside
    double total = 0.0;
    for (auto _ : state) {
        const auto t0 = Clock::now();
        renderer.render(camera, rect, frame, nullptr);
        total += std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
        benchmark::DoNotOptimize(frame.depth());
    }
    report(state, total, targetMs, rect);
    state.SetLabel(egl->info().renderer);
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

// The brick grid on its own, one thread (the server counts it in its render stage, as grid_ms,
// before the render of BB_screen): update() after the update study's N^3 surface cut (N = 10, 40,
// 80) on skull:128 and skull:256, and build() of a whole grid. Each iteration starts from the grid
// as it was before the cut (copied outside the timed part). Counters: update_us / build_ms per
// call, and the bricks whose distance the update changed. Filter with --benchmark_filter=BrickGrid.
#include "libsim/brick_grid.h"
#include "libsim/skull.h"
#include "libsim/volume.h"

#include <benchmark/benchmark.h>
#include <chrono>
#include <map>
#include <memory>

namespace trephine {
namespace {

using Clock = std::chrono::steady_clock;

struct Cut {
    Volume volume;
    Box3i box;
    BrickGrid before;
    int changedDistances = 0;
};

// The update study's cut (surfaceBox), cut to air.
Box3i cutSurfaceBox(Volume& v, int n) {
    const Box3i box = surfaceBox(v, n);
    v.fill(box, 0, Material::Air);
    return box;
}

const Volume& skull(int size) {
    static std::map<int, Volume> skulls;
    auto it = skulls.find(size);
    if (it == skulls.end())
        it = skulls.emplace(size, makeSkull(size)).first;
    return it->second;
}

Cut& cut(int size, int n) {
    static std::map<std::pair<int, int>, std::unique_ptr<Cut>> cuts;
    std::unique_ptr<Cut>& c = cuts[{size, n}];
    if (!c) {
        c = std::make_unique<Cut>();
        c->volume = skull(size);
        c->before.build(c->volume);
        c->box = cutSurfaceBox(c->volume, n);
        BrickGrid after = c->before;
        after.update(c->volume, c->box);
        for (size_t i = 0; i < after.maxData().size(); ++i)
            c->changedDistances += after.distanceData()[i] != c->before.distanceData()[i];
    }
    return *c;
}

void runCut(benchmark::State& state, int size) {
    Cut& c = cut(size, int(state.range(0)));
    BrickGrid grid;
    double total = 0.0;
    for (auto _ : state) {
        state.PauseTiming();
        grid = c.before;
        state.ResumeTiming();
        auto t0 = Clock::now();
        grid.update(c.volume, c.box);
        total += std::chrono::duration<double, std::micro>(Clock::now() - t0).count();
        benchmark::DoNotOptimize(grid.distanceData());
    }
    state.counters["update_us"] = state.iterations() ? total / double(state.iterations()) : 0.0;
    state.counters["changed"] = c.changedDistances;
}

void BM_BrickGridCutSkull128(benchmark::State& state) {
    runCut(state, 128);
}
BENCHMARK(BM_BrickGridCutSkull128)
    ->Arg(10)
    ->Arg(40)
    ->Arg(80)
    ->Unit(benchmark::kMicrosecond)
    ->UseRealTime();

void BM_BrickGridCutSkull256(benchmark::State& state) {
    runCut(state, 256);
}
BENCHMARK(BM_BrickGridCutSkull256)
    ->Arg(10)
    ->Arg(40)
    ->Arg(80)
    ->Unit(benchmark::kMicrosecond)
    ->UseRealTime();

void BM_BrickGridBuild(benchmark::State& state) {
    const Volume& v = skull(int(state.range(0)));
    BrickGrid grid;
    double total = 0.0;
    for (auto _ : state) {
        auto t0 = Clock::now();
        grid.build(v);
        total += std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
        benchmark::DoNotOptimize(grid.distanceData());
    }
    state.counters["build_ms"] = state.iterations() ? total / double(state.iterations()) : 0.0;
}
BENCHMARK(BM_BrickGridBuild)->Arg(128)->Arg(256)->Unit(benchmark::kMillisecond)->UseRealTime();

} // namespace
} // namespace trephine

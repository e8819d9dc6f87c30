// The critical structures' distance fields (libsim/distance_field.h): the cost of the queries the
// server makes per applied tool state (issue 24's target: at most 20 us a state on skull:256), and
// the fields' build time and memory at load. Timings on the shared machines wobble by 30-50 %.
#include "libsim/distance_field.h"
#include "libsim/skull.h"

#include <benchmark/benchmark.h>
#include <glm/geometric.hpp>
#include <random>

using namespace trephine;

namespace {

const Volume& skull256() {
    static const Volume v = makeSkull(256);
    return v;
}

const StructureFields& fields256() {
    static const StructureFields f(skull256());
    return f;
}

// Tool states around the default burr site: within 15 mm of it, where a trainee drills.
std::vector<ToolPose> posesNearSite(int count) {
    const SurfaceSite site = defaultBurrSite(skull256());
    std::mt19937 rng(3);
    std::uniform_real_distribution<float> d(-15.0f, 15.0f);
    std::vector<ToolPose> poses;
    for (int i = 0; i < count; ++i)
        poses.push_back(
            ToolPose::fromAxis(site.position + glm::vec3(d(rng), d(rng), d(rng)), site.normal));
    return poses;
}

// Per applied tool state the server asks every structure for the cutter's closest approach.
void queryPerState(benchmark::State& state, ToolShape shape) {
    const StructureFields& f = fields256();
    const std::vector<ToolPose> poses = posesNearSite(4096);
    size_t i = 0;
    for (auto _ : state) {
        const ToolPose& p = poses[i++ & 4095];
        for (size_t s = 0; s < f.size(); ++s)
            benchmark::DoNotOptimize(f.closestApproach(s, shape, p));
    }
    state.counters["structures"] = double(f.size());
    state.counters["target_us"] = 20.0;
    state.SetLabel("skull:256, per tool state (target <= 20 us)");
}
void BM_DistanceQueriesBurr(benchmark::State& state) {
    queryPerState(state, ToolShape::burr(4.0f));
}
void BM_DistanceQueriesPerforator(benchmark::State& state) {
    queryPerState(state, ToolShape::perforator());
}
BENCHMARK(BM_DistanceQueriesBurr)->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_DistanceQueriesPerforator)->Unit(benchmark::kMicrosecond);

// Building every structure's field at load, on one thread and on a pool of two.
void BM_DistanceFieldsBuild(benchmark::State& state) {
    const Volume& v = skull256();
    ThreadPool pool(int(state.range(0)));
    size_t bytes = 0, dense = 0, bricks = 0, structures = 0;
    for (auto _ : state) {
        StructureFields f(v, DistanceField::kDefaultClampMm, &pool);
        bytes = f.bytes();
        structures = f.size();
        dense = bricks = 0;
        for (size_t s = 0; s < f.size(); ++s) {
            dense += f.field(s).denseBricks();
            bricks += f.field(s).brickCount();
        }
    }
    state.counters["structures"] = double(structures);
    state.counters["MiB"] = double(bytes) / (1 << 20);
    state.counters["dense_bricks_pct"] = bricks ? 100.0 * double(dense) / double(bricks) : 0.0;
    state.counters["volume_MiB"] = double(v.voxelCount()) * 2 / (1 << 20);
    state.SetLabel("skull:256 at load; threads = arg");
}
BENCHMARK(BM_DistanceFieldsBuild)
    ->Arg(1)
    ->Arg(2)
    ->Iterations(2)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

} // namespace

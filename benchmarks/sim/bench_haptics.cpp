// Haptics micro-benchmarks: force + gradient per update for each cutter at the default burr site of
// the 256^3 skull (the server's work per tool state), and one blended 1 kHz tick on the client.
// Timings on the shared machines wobble by 30-50 %; compare figures taken in one run.
#include "libsim/force_model.h"
#include "libsim/haptics.h"
#include "libsim/skull.h"

#include <benchmark/benchmark.h>

using namespace trephine;

namespace {

const Volume& hapticsSkull() {
    static const Volume v = makeSkull(256);
    return v;
}

// The cutter's lowest point pressed depthMm into the bone, nudged each update as a hand would be.
void forceUpdate(benchmark::State& state, ToolShape shape, float depthMm, double targetMs) {
    const Volume& skull = hapticsSkull();
    const SurfaceSite site = defaultBurrSite(skull);
    const ForceModel model(shape);
    const float lift = (shape.kind == ToolKind::Burr ? 0.5f * shape.diameterMm : 0.0f) - depthMm;
    ToolPose pose = ToolPose::fromAxis(site.position + site.normal * lift, site.normal);
    int i = 0;
    int contacts = 0;
    for (auto _ : state) {
        pose.position += site.normal * ((i++ & 1) ? 1e-3f : -1e-3f);
        ForceResult r = model.compute(skull, pose);
        benchmark::DoNotOptimize(r);
        contacts = r.contactPoints;
    }
    state.counters["target_ms"] = targetMs;
    state.counters["shell_points"] = double(model.shell().size());
    state.counters["contact_points"] = contacts;
}

void BM_ForceBurr2(benchmark::State& s) {
    forceUpdate(s, ToolShape::burr(2.0f), 1.0f, 0.1);
}
void BM_ForceBurr6(benchmark::State& s) {
    forceUpdate(s, ToolShape::burr(6.0f), 1.0f, 0.1);
}
void BM_ForcePerforator(benchmark::State& s) {
    forceUpdate(s, ToolShape::perforator(), 3.0f, 0.5);
}
// Deep in the hole: most of the shell in bone, the most work an update does.
void BM_ForcePerforatorDeep(benchmark::State& s) {
    forceUpdate(s, ToolShape::perforator(), 8.0f, 0.5);
}
BENCHMARK(BM_ForceBurr2)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_ForceBurr6)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_ForcePerforator)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_ForcePerforatorDeep)->Unit(benchmark::kMillisecond);

// The client's share of a 1 ms haptic tick: extrapolate and blend (a new model every 10 ticks).
void BM_BlenderTick(benchmark::State& state) {
    ModelBlender blender;
    HapticModelData m;
    m.position = {0, 0, 10};
    m.force = {0, 0, 2};
    m.gradient = glm::mat3(-5.0f);
    double t = 0.0;
    int i = 0;
    for (auto _ : state) {
        if (i++ % 10 == 0) {
            m.force.z = 2.0f + 0.1f * float(i % 7);
            blender.setModel(m, t);
        }
        benchmark::DoNotOptimize(blender.update({0.01f, 0.0f, 9.9f}, t));
        t += 1e-3;
    }
}
BENCHMARK(BM_BlenderTick);

} // namespace

// What a device plugin costs the haptic loop per tick (read + write): the simulated device's C
// functions called directly, then through PluginDevice (a worker thread per plugin, so a hang
// cannot stall the loop), then with the DeviceGuard on top. "Paced" runs tick once a millisecond
// as the loop does, so the worker sleeps between ticks and each tick pays its wake-up; the
// counters give that wake-up's median and 99th percentile.
#include "libsim/device_guard.h"
#include "libsim_devices/devices.h"
#include "libsim_devices/plugin_device.h"
#include "libsim_devices/trephine_device_abi.h"

#include <benchmark/benchmark.h>

#include <algorithm>
#include <chrono>
#include <dlfcn.h>
#include <string>
#include <thread>
#include <vector>

using namespace trephine;

namespace {

const std::string kSim = std::string(TREPHINE_PLUGIN_DIR) + "/trephine_sim_device.so";

std::unique_ptr<PluginDevice> openSim() {
    PluginOptions o;
    o.deadlineS = 1.0; // the benchmark measures the call, not the cut-off
    std::string error;
    auto d = openPlugin(kSim, o, error);
    if (!d)
        throw std::runtime_error(error);
    return d;
}

// Runs tick() per iteration; paced: once a millisecond, timing each tick by hand.
template <typename Tick>
void run(benchmark::State& state, Tick tick) {
    const bool paced = state.range(0) != 0;
    std::vector<double> us;
    double t = 0.0;
    for (auto _ : state) {
        const auto start = std::chrono::steady_clock::now();
        tick(t += 0.001);
        const auto end = std::chrono::steady_clock::now();
        const double s = std::chrono::duration<double>(end - start).count();
        if (paced) {
            state.SetIterationTime(s);
            us.push_back(s * 1e6);
            std::this_thread::sleep_until(start + std::chrono::milliseconds(1));
        }
    }
    if (!us.empty()) {
        std::sort(us.begin(), us.end());
        state.counters["p50_us"] = us[us.size() / 2];
        state.counters["p99_us"] = us[std::min(us.size() - 1, us.size() * 99 / 100)];
    }
}

void BM_SimDeviceDirect(benchmark::State& state) {
    void* lib = dlopen(kSim.c_str(), RTLD_NOW | RTLD_LOCAL);
    auto entry = reinterpret_cast<TrephineDeviceEntry>(dlsym(lib, TREPHINE_DEVICE_ENTRY));
    const TrephineDeviceApi* api = entry(TREPHINE_DEVICE_ABI_VERSION);
    char error[128];
    TrephineDevice* d = api->open("", error, sizeof error);
    const double f[3] = {0.0, 0.0, 1.0};
    run(state, [&](double now) {
        TrephineDevicePose p;
        api->read(d, now, &p);
        api->write_force(d, f);
        benchmark::DoNotOptimize(p);
    });
    api->close(d);
    dlclose(lib);
}

void BM_PluginDevice(benchmark::State& state) {
    auto d = openSim();
    run(state, [&](double now) {
        benchmark::DoNotOptimize(d->read(now));
        d->setForce({0, 0, 1});
    });
    state.counters["missed"] = double(d->missedTicks());
}

void BM_GuardedPluginDevice(benchmark::State& state) {
    auto d = openSim();
    DeviceGuard guard(*d);
    run(state, [&](double now) {
        benchmark::DoNotOptimize(guard.read(now));
        guard.setForce({0, 0, 1});
    });
}

void BM_GuardAlone(benchmark::State& state) {
    ScriptedDevice device({{0.0, ToolPose{}, 0}});
    DeviceGuard guard(device);
    run(state, [&](double now) {
        benchmark::DoNotOptimize(guard.read(now));
        guard.setForce({0, 0, 1});
    });
}

} // namespace

BENCHMARK(BM_SimDeviceDirect)->Arg(0);
BENCHMARK(BM_GuardAlone)->Arg(0);
BENCHMARK(BM_PluginDevice)->Arg(0);
BENCHMARK(BM_PluginDevice)->Arg(1)->UseManualTime()->Iterations(2000);
BENCHMARK(BM_GuardedPluginDevice)->Arg(1)->UseManualTime()->Iterations(2000);

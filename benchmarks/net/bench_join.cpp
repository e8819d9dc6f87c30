// The join of a thin DBI client: bytes received from connect to the first full picture of its
// view (the welcome, the scene with its surgical field, the roster and the full DBI; never
// voxels), against the volume's bytes, and the time to that picture, over loopback and through
// the link emulator at 50 ms one-way latency and 20 Mbit/s. The client knows only the address: its
// view is the scene's `working` preset at 500 x 500. Target (issue 21): at most 5 % of the volume's
// bytes (1 byte a voxel, the paper's volume) for a skull:256 server.
#include "libsim/skull.h"
#include "net/link_emulator.h"
#include "net/scene.h"
#include "net/session_client.h"
#include "net/session_server.h"
#include "net/view.h"

#include <benchmark/benchmark.h>

#include <map>
#include <memory>

using namespace trephine;
using namespace trephine::net;

namespace {

constexpr double kTargetPercent = 5.0;
constexpr int kView = 500;

SessionServer& serverFor(int n) {
    static std::map<int, std::unique_ptr<SessionServer>> servers;
    auto& s = servers[n];
    if (!s) {
        ServerConfig config;
        config.port = 0;
        config.volumeName = "skull:" + std::to_string(n);
        s = std::make_unique<SessionServer>(makeSkull(n), config);
        s->start();
    }
    return *s;
}

uint64_t bytesIn(const SessionClient& c) {
    uint64_t sum = 0;
    for (size_t ch = 0; ch < size_t(Channel::Count); ++ch)
        sum += c.stats().totalBytesIn(Channel(ch));
    return sum;
}

// Arguments: skull size, link (0 loopback, 1 the emulator at 50 ms and 20 Mbit/s).
void BM_DbiJoin(benchmark::State& state) {
    const int n = int(state.range(0));
    const bool link = state.range(1) != 0;
    SessionServer& server = serverFor(n);
    std::unique_ptr<LinkEmulator> emulator;
    ENetAddress address = parseAddress("127.0.0.1:" + std::to_string(server.port()));
    if (link) {
        LinkConditions c;
        c.latencyMs = 50.0;
        c.rateMbps = 20.0;
        emulator = std::make_unique<LinkEmulator>(0, address, c);
        address = parseAddress("127.0.0.1:" + std::to_string(emulator->port()));
    }
    double bytes = 0, sceneBytes = 0, ms = 0;
    int joins = 0;
    for (auto _ : state) {
        ClientConfig cc;
        cc.view.width = cc.view.height = 1; // the view comes from the scene
        SessionClient client(cc);
        const uint64_t t0 = steadyNowUs();
        client.connect(address);
        const uint64_t deadline = t0 + 60000000;
        while (!client.scene() && !client.closed() && steadyNowUs() < deadline)
            client.poll(1);
        if (!client.scene()) {
            state.SkipWithError("no scene from the server");
            return;
        }
        const Camera camera = *presetCamera(client.scene()->scene, "working", {kView, kView});
        client.requestView(toViewSpec(camera));
        while (!client.hasFullImage() && !client.closed() && steadyNowUs() < deadline)
            client.poll(1);
        if (!client.hasFullImage()) {
            state.SkipWithError("no picture from the server");
            return;
        }
        ms += double(steadyNowUs() - t0) * 1e-3;
        bytes += double(bytesIn(client));
        Scene s = client.scene()->scene;
        sceneBytes += double(encodeMessage(s).size());
        ++joins;
        client.disconnect(200);
    }
    const double volumeBytes = double(n) * n * n;
    state.counters["join_bytes"] = bytes / joins;
    state.counters["scene_bytes"] = sceneBytes / joins;
    state.counters["volume_bytes"] = volumeBytes;
    state.counters["join_pct_of_volume"] = 100.0 * bytes / joins / volumeBytes;
    state.counters["target_pct"] = kTargetPercent;
    state.counters["first_picture_ms"] = ms / joins;
}

BENCHMARK(BM_DbiJoin)
    ->ArgNames({"skull", "link50ms20Mbit"})
    ->Args({256, 0})
    ->Args({256, 1})
    ->Iterations(3)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

} // namespace

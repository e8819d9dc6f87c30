// Loopback session benchmarks: end-to-end image-update latency of a burr stroke (tool state sent
// -> rectangle applied at the client) and bytes per update for each codec against the raw size;
// full-view refresh time (view change). Server and client in one process, one steady clock.
// Figures print beside the targets (p50 <= 2 ms, p99 <= 5 ms at BB_volume ~40^3).
#include "libsim/skull.h"
#include "libsim/stats.h"
#include "net/session_client.h"
#include "net/session_server.h"
#include "net/view.h"

#include <benchmark/benchmark.h>
#include <glm/gtx/quaternion.hpp>

#include <memory>

using namespace trephine;
using namespace trephine::net;

namespace {

struct Session {
    Volume skull;
    std::unique_ptr<SessionServer> server;
    std::unique_ptr<SessionClient> client;
    SurfaceSite site;

    Session(Codec codec, const char* preset, int window) : skull(makeSkull(128)) {
        site = defaultBurrSite(skull);
        ServerConfig config;
        config.port = 0;
        config.volumeName = "skull:128";
        server = std::make_unique<SessionServer>(skull, config);
        server->start();
        ClientConfig cc;
        cc.codec = codec;
        cc.view = toViewSpec(cameraPreset(preset, skull, {window, window}));
        client = std::make_unique<SessionClient>(cc);
        client->connect(parseAddress("127.0.0.1:" + std::to_string(server->port())));
        uint64_t deadline = steadyNowUs() + 60000000;
        while (!client->hasFullImage() && steadyNowUs() < deadline)
            client->poll(1);
    }
    ~Session() {
        client->disconnect(50);
        server->stop();
    }
    // Waits until n more updates are applied; false after the guard.
    bool waitUpdates(uint64_t n, uint64_t guardUs = 2000000) {
        uint64_t target = client->updatesApplied() + n;
        uint64_t deadline = steadyNowUs() + guardUs;
        while (client->updatesApplied() < target && steadyNowUs() < deadline)
            client->poll(0);
        return client->updatesApplied() >= target;
    }
};

// One burr stroke across the default site, a tool state per iteration, 10 ms of drilling each.
void burrStroke(benchmark::State& state, Codec codec, float diameterMm) {
    Session s(codec, "paper", 500);
    glm::vec3 n = s.site.normal;
    glm::vec3 along = glm::normalize(glm::cross(n, glm::vec3(1, 0, 0)));
    uint64_t clientUs = 1000000;
    uint32_t seq = 0;
    int i = 0;
    int64_t timeouts = 0;
    for (auto _ : state) {
        ToolState t;
        t.sequence = ++seq;
        t.clientTimeUs = clientUs += 10000;
        t.diameterMm = diameterMm;
        t.position = s.site.position - n * 1.0f + along * (0.2f * float(i++ % 100) - 10.0f);
        t.orientation = glm::rotation(glm::vec3(0, 0, 1), n);
        t.speed = 1.0f;
        t.drilling = true;
        s.client->sendToolState(t);
        if (!s.waitUpdates(1, 200000))
            ++timeouts;
    }
    const NetStats& st = s.client->stats();
    state.counters["latency_p50_us"] = st.updateLatencyUs.percentile(50);
    state.counters["latency_p99_us"] = st.updateLatencyUs.percentile(99);
    state.counters["target_p50_us"] = 2000;
    state.counters["target_p99_us"] = 5000;
    state.counters["bytes_per_update"] = st.updateBytes.mean();
    state.counters["raw_bytes_per_update"] = st.updateRawBytes.mean();
    state.counters["no_update"] = double(timeouts);
}

void fullRefresh(benchmark::State& state, Codec codec) {
    Session s(codec, "paper", 500);
    ViewSpec a = toViewSpec(cameraPreset("paper", s.skull, {500, 500}));
    ViewSpec b = toViewSpec(cameraPreset("top", s.skull, {500, 500}));
    SampleWindow us;
    bool flip = false;
    for (auto _ : state) {
        flip = !flip;
        uint64_t t0 = steadyNowUs();
        uint32_t id = s.client->requestView(flip ? b : a);
        uint64_t deadline = t0 + 10000000;
        while (s.client->viewId() != id && steadyNowUs() < deadline)
            s.client->poll(0);
        us.add(double(steadyNowUs() - t0));
    }
    state.counters["refresh_p50_us"] = us.percentile(50);
    state.counters["refresh_p99_us"] = us.percentile(99);
    state.counters["bytes_full"] = s.client->stats().updateBytes.max();
}

} // namespace

BENCHMARK_CAPTURE(burrStroke, raw_burr5mm, Codec::Raw, 5.0f)->Iterations(200)->UseRealTime();
BENCHMARK_CAPTURE(burrStroke, lz4_burr5mm, Codec::Lz4, 5.0f)->Iterations(200)->UseRealTime();
BENCHMARK_CAPTURE(burrStroke, zstd_burr5mm, Codec::Zstd, 5.0f)->Iterations(200)->UseRealTime();
BENCHMARK_CAPTURE(fullRefresh, lz4, Codec::Lz4)->Iterations(10)->UseRealTime();

// Images over a long link (issue 32): a skull:128 server and one zstd DBI client with a 500 x 500
// view through the link emulator at 20 Mbit/s, with ENet's negotiated 64 KiB window
// (adaptive 0, as before) and the host's delay-sized bulk window (adaptive 1).
// Per link: the join, three 5-degree view changes (ask to full picture), the force answers to
// tool states sent while each view's full image is in flight, and a 3 s soak of 40^3 cuts and
// restores at 20 Hz (update latency, longest stall; the bytes of an applied update, the server's
// egress through the relay, repairs included, and the client's acknowledgements upstream).
// One iteration a case: seconds of real time.
//   benchmark_net --benchmark_filter=Transport
#include "libsim/skull.h"
#include "net/link_emulator.h"
#include "net/net_stats.h"
#include "net/session_client.h"
#include "net/session_server.h"
#include "net/view.h"

#include <benchmark/benchmark.h>
#include <glm/geometric.hpp>

#include <algorithm>
#include <chrono>
#include <functional>
#include <thread>
#include <vector>

using namespace trephine;
using namespace trephine::net;

namespace {

const Volume& skull128() {
    static const Volume v = makeSkull(128);
    return v;
}

double percentile(std::vector<double> v, double p) {
    if (v.empty())
        return -1;
    std::sort(v.begin(), v.end());
    return v[std::min(v.size() - 1, size_t(p / 100.0 * double(v.size())))];
}

// Pumps the client (the server runs its own threads) until done() or the guard passes.
bool pumpUntil(SessionClient& c, const std::function<bool()>& done, double guardS = 30) {
    const uint64_t deadline = steadyNowUs() + uint64_t(guardS * 1e6);
    while (!done()) {
        if (steadyNowUs() > deadline)
            return false;
        c.wait(1);
        c.pump(steadyNowUs());
    }
    return true;
}

void BM_TransportOverLink(benchmark::State& state) {
    const bool adaptive = state.range(0) != 0;
    const double rttMs = double(state.range(1)), lossPct = double(state.range(2));
    const Volume& skull = skull128();
    ServerConfig sc;
    sc.bulkWindow.adaptive = adaptive;
    sc.port = 0;
    sc.volumeName = "skull:128";
    SessionServer server(skull, sc);
    server.start();
    LinkConditions link;
    link.latencyMs = rttMs / 2;
    link.lossPercent = lossPct;
    link.rateMbps = 20;
    LinkEmulator relay(0, parseAddress("127.0.0.1:" + std::to_string(server.port())), link);

    const Camera camera = cameraPreset("paper", skull, {500, 500});
    ClientConfig cc;
    cc.name = "bench";
    cc.codec = Codec::Zstd;
    cc.view = toViewSpec(camera);
    SessionClient client(cc);
    std::vector<double> latencies, forceRtts;
    std::vector<uint64_t> appliedAt;
    double fullBytes = 0, updateBytes = 0;
    client.setRecordCallback([&](const UpdateRecord& r) {
        if (r.full)
            fullBytes = r.bytes;
        if (!r.full)
            updateBytes += r.bytes;
        if (!r.full && r.latencyUs >= 0) {
            latencies.push_back(r.latencyUs * 1e-3);
            appliedAt.push_back(r.appliedUs);
        }
    });
    client.setHapticCallback([&](const HapticModel& m, uint64_t arrivalUs) {
        forceRtts.push_back(double(arrivalUs - m.clientTimeUs) * 1e-3);
    });

    for (auto _ : state) {
        const uint64_t t0 = steadyNowUs();
        client.connect(parseAddress("127.0.0.1:" + std::to_string(relay.port())));
        if (!pumpUntil(
                client, [&] { return client.hasFullImage(); }, 60)) {
            state.SkipWithError("no join");
            break;
        }
        state.counters["join_ms"] = double(steadyNowUs() - t0) * 1e-3;

        // View changes: tool states every 10 ms while each full image is on its way.
        std::vector<double> viewMs;
        forceRtts.clear();
        const float dist = glm::distance(camera.eye, camera.target);
        for (int i = 0; i < 3; ++i) {
            const Camera turned =
                orbitCamera(camera, i % 2 ? -5.0f : 5.0f, 0.0f, dist, {500, 500}, skull);
            const uint64_t asked = steadyNowUs();
            const uint32_t id = client.requestView(toViewSpec(turned));
            uint64_t nextTool = asked;
            pumpUntil(client, [&] {
                if (steadyNowUs() >= nextTool) {
                    ToolState t;
                    t.position = glm::vec3(0, 0, 200); // above the skull: an answer, no cut
                    client.sendToolState(t);
                    nextTool += 10000;
                }
                return client.hasFullImage() && client.viewId() == id;
            });
            viewMs.push_back(double(steadyNowUs() - asked) * 1e-3);
        }
        state.counters["view_ms_p50"] = percentile(viewMs, 50);
        state.counters["view_kB"] = fullBytes * 1e-3;
        state.counters["force_rtt_p50"] = percentile(forceRtts, 50);
        state.counters["force_rtt_max"] = percentile(forceRtts, 100);

        // The soak: 40^3 cuts and restores at 20 Hz for 3 s.
        const Volume now = server.volumeSnapshot();
        const Box3i box = surfaceBox(now, 40);
        std::vector<uint8_t> density, material;
        now.copyBox(box, density, material);
        latencies.clear();
        appliedAt.clear();
        updateBytes = 0;
        const uint64_t down0 = relay.bytesDown(),
                       acks0 = client.stats().totalBytesOut(Channel::ImageLossy);
        const uint64_t start = steadyNowUs();
        uint64_t next = start;
        int submitted = 0;
        while (steadyNowUs() < start + 3000000 || submitted % 2) {
            if (steadyNowUs() >= next) {
                if (submitted++ % 2 == 0)
                    server.submitBoxCut(box);
                else
                    server.submitVoxels(box, density, material);
                next += 50000;
            }
            client.wait(1);
            client.pump(steadyNowUs());
        }
        const uint64_t end = steadyNowUs();
        pumpUntil(client, [&] { return steadyNowUs() > end + 2000000; });
        const double soakS = double(end - start) * 1e-6; // the drain's bytes are the soak's
        double stall = 0;
        uint64_t last = start;
        for (uint64_t at : appliedAt)
            if (at <= end) {
                stall = std::max(stall, double(at - last) * 1e-3);
                last = at;
            }
        stall = std::max(stall, double(end - last) * 1e-3);
        state.counters["update_p50"] = percentile(latencies, 50);
        state.counters["update_p99"] = percentile(latencies, 99);
        state.counters["max_stall_ms"] = stall;
        state.counters["updates"] = double(latencies.size());
        state.counters["update_kB"] =
            latencies.empty() ? 0 : updateBytes * 1e-3 / double(latencies.size());
        state.counters["down_kB_per_s"] = double(relay.bytesDown() - down0) * 1e-3 / soakS;
        state.counters["acks_B_per_s"] =
            double(client.stats().totalBytesOut(Channel::ImageLossy) - acks0) / soakS;
    }
    client.disconnect();
    server.stop();
}

} // namespace

BENCHMARK(BM_TransportOverLink)
    ->ArgNames({"adaptive", "rtt", "loss"})
    ->ArgsProduct({{0, 1}, {50, 100, 200}, {0, 1, 5}})
    ->Iterations(1)
    ->UseRealTime()
    ->Unit(benchmark::kMillisecond);

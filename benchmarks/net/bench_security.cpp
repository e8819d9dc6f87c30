// What sealing the session costs (docs/security.md), each figure beside its target, open and
// sealed sessions alternating in one run so the machine's wobble falls on both:
// - image-update latency p50 and p99 of the update study's dbi method at N = 80 (an 80^3 box cut
//   at the surface of the paper-spaced skull:128; target: sealed at most +5 %);
// - the force round trip (tool state out, HapticModel back, one in flight at 1 kHz);
// - the handshake: connect to sealed, and the code's argon2id hash alone;
// - sealing and opening one message of the sizes a session sends (a tool state, the lz4 image
//   update of an 80^3 cut, 31.7 kB in docs/session.md, and a full 500x500 view, 142 kB): the
//   crypto's own share of an update's latency, which load on the machine does not blur.
#include "libsim/skull.h"
#include "libsim/stats.h"
#include "net/force_round_trip.h"
#include "net/secure_channel.h"
#include "net/session_client.h"
#include "net/session_server.h"
#include "study/update_study.h"

#include <benchmark/benchmark.h>

#include <algorithm>
#include <array>

using namespace trephine;
using namespace trephine::net;
using namespace trephine::study;

namespace {

constexpr int kPairs = 9; // open, sealed, open, sealed, ...

double median(std::array<double, kPairs> v) {
    std::sort(v.begin(), v.end());
    return v[kPairs / 2];
}

double percentMore(double sealed, double open) {
    return open > 0 ? (sealed / open - 1.0) * 100.0 : 0.0;
}

const Volume& paperSkull() {
    static const Volume v = [] {
        Volume s = makeSkull(128);
        s.setSpacing(glm::vec3(paperSpacingMm(128)));
        return s;
    }();
    return v;
}

ServerConfig serverConfig(bool sealed) {
    ServerConfig c;
    c.port = 0;
    c.volumeName = "skull:128";
    if (sealed) {
        c.traineeCode = "BENCH-TRAINEE";
        c.instructorCode = "BENCH-TEACHER";
    }
    return c;
}

void sealedUpdateLatency(benchmark::State& state) {
    std::array<double, kPairs> p50[2], p99[2];
    for (auto _ : state)
        for (int pair = 0; pair < kPairs; ++pair)
            for (int k = 0; k < 2; ++k) {
                const int sealed = (pair + k) % 2; // each goes first in half the pairs
                UpdateStudyConfig config;
                config.sizes = {80};
                config.methods = {"dbi"};
                config.cycles = 24;
                config.sealed = sealed == 1;
                const UpdateStudyRow row = runUpdateStudy(paperSkull(), config).at(0);
                p50[sealed][size_t(pair)] = row.latencyP50Ms * 1e3;
                p99[sealed][size_t(pair)] = row.latencyP99Ms * 1e3;
            }
    state.counters["open_p50_us"] = median(p50[0]);
    state.counters["sealed_p50_us"] = median(p50[1]);
    state.counters["cost_p50_pct"] = percentMore(median(p50[1]), median(p50[0]));
    state.counters["open_p99_us"] = median(p99[0]);
    state.counters["sealed_p99_us"] = median(p99[1]);
    state.counters["cost_p99_pct"] = percentMore(median(p99[1]), median(p99[0]));
    state.counters["target_cost_pct"] = 5;
}

void sealedForceRoundTrip(benchmark::State& state) {
    const SurfaceSite site = defaultBurrSite(paperSkull());
    std::array<double, kPairs> p50[2], p99[2];
    for (auto _ : state)
        for (int pair = 0; pair < kPairs; ++pair)
            for (int k = 0; k < 2; ++k) {
                const int sealed = (pair + k) % 2;
                const ServerConfig sc = serverConfig(sealed == 1);
                SessionServer server(paperSkull(), sc);
                server.start();
                ForceRoundTripConfig fc;
                fc.shape = ToolShape::burr(2.0f);
                fc.pose = ToolPose::fromAxis(site.position, site.normal);
                fc.samples = 1000;
                fc.code = sc.traineeCode;
                const ForceRoundTripResult r = measureForceRoundTrip(
                    parseAddress("127.0.0.1:" + std::to_string(server.port())), fc);
                p50[sealed][size_t(pair)] = r.p50Us;
                p99[sealed][size_t(pair)] = r.p99Us;
                server.stop();
            }
    state.counters["open_p50_us"] = median(p50[0]);
    state.counters["sealed_p50_us"] = median(p50[1]);
    state.counters["cost_p50_pct"] = percentMore(median(p50[1]), median(p50[0]));
    state.counters["open_p99_us"] = median(p99[0]);
    state.counters["sealed_p99_us"] = median(p99[1]);
    state.counters["cost_p99_pct"] = percentMore(median(p99[1]), median(p99[0]));
}

// Connect to sealed (challenge, offer, answer, confirm over loopback, the client's argon2id hash
// included), 20 joins one after another; and the hash alone.
void sealedHandshake(benchmark::State& state) {
    Volume small = makeSkull(32);
    const ServerConfig sc = serverConfig(true);
    SessionServer server(small, sc);
    server.start();
    SampleWindow joins(64), hashes(64);
    for (auto _ : state)
        for (int i = 0; i < 20; ++i) {
            ClientConfig cc;
            cc.code = sc.traineeCode;
            cc.view.width = cc.view.height = 8;
            SessionClient client(cc);
            client.connect(parseAddress("127.0.0.1:" + std::to_string(server.port())));
            const uint64_t guard = steadyNowUs() + 10000000;
            while (!client.sealed() && !client.closed() && steadyNowUs() < guard)
                client.poll(1);
            if (client.sealed())
                joins.add(double(client.handshakeUs()));
            client.disconnect(50);
            Salt salt{};
            const uint64_t t0 = steadyNowUs();
            benchmark::DoNotOptimize(codeScalar("BENCHTRAINEE", salt));
            hashes.add(double(steadyNowUs() - t0));
        }
    server.stop();
    state.counters["handshake_p50_us"] = joins.percentile(50);
    state.counters["handshake_max_us"] = joins.max();
    state.counters["code_hash_p50_us"] = hashes.percentile(50);
    state.counters["joins"] = double(joins.size());
}

void sealOpen(benchmark::State& state) {
    const Salt salt{};
    const Bytes32 w = codeScalar("BENCHTRAINEE", salt);
    SpakeClient client(w, salt, Role::Trainee);
    const auto server = spakeAnswer(w, salt, Role::Trainee, Role::Trainee, client.share());
    SecureChannel sender(server->keys, true);
    SecureChannel receiver(*client.keys(server->share, Role::Trainee), false);
    const std::vector<uint8_t> message(size_t(state.range(0)), 0x5a);
    std::vector<uint8_t> plain;
    for (auto _ : state) {
        const std::vector<uint8_t> sealed = sender.seal(Channel::Image, message);
        if (receiver.open(Channel::Image, sealed, plain) != SecureChannel::Opened::Ok)
            state.SkipWithError("did not open");
    }
    state.SetBytesProcessed(int64_t(state.iterations()) * state.range(0));
}

} // namespace

BENCHMARK(sealOpen)->Arg(60)->Arg(31719)->Arg(142000)->Unit(benchmark::kMicrosecond);
BENCHMARK(sealedUpdateLatency)->Iterations(1)->UseRealTime()->Unit(benchmark::kMillisecond);
BENCHMARK(sealedForceRoundTrip)->Iterations(1)->UseRealTime()->Unit(benchmark::kMillisecond);
BENCHMARK(sealedHandshake)->Iterations(1)->UseRealTime()->Unit(benchmark::kMillisecond);

// Loopback session benchmarks: end-to-end image-update latency of a burr stroke (the tool state's
// arrival at the server -> rectangle applied at the client: the client-to-server leg, ~20 us here,
// is left out) and bytes per update of the stroke's rectangles for each codec against the raw size;
// full-view refresh time (view change). Server and client in one process, one steady clock.
// Figures print beside the targets (p50 <= 2 ms, p99 <= 5 ms at BB_volume ~40^3).
// The box sweep runs the update study's dbi method (30 cycles, each cutting fresh bone: an N^3 box,
// N = 10..80, at the surface facing the paper camera of a paper-spaced skull:128) and reports
// latency, BB_screen size, stage times and bytes per update against raw. Haptics: the loopback
// force round trip (target p50 <= 0.3 ms) and the 1 kHz haptic loop's achieved rate and lateness
// while the server streams DBI updates.
#include "libsim/device.h"
#include "libsim/haptics.h"
#include "libsim/skull.h"
#include "libsim/stats.h"
#include "net/force_round_trip.h"
#include "net/session_client.h"
#include "net/session_server.h"
#include "net/tool_model.h"
#include "net/view.h"
#include "study/update_study.h"

#include <benchmark/benchmark.h>
#include <glm/gtx/quaternion.hpp>

#include <atomic>
#include <deque>
#include <memory>
#include <mutex>
#include <thread>

using namespace trephine;
using namespace trephine::net;
using namespace trephine::study;

namespace {

struct Session {
    Volume skull;
    std::unique_ptr<SessionServer> server;
    std::unique_ptr<SessionClient> client;
    SurfaceSite site;

    Session(Codec codec, const char* preset, int window, Volume volume = makeSkull(128))
        : skull(std::move(volume)) {
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
    // The stroke's rectangles only: the client's stats also hold the full image of its join
    // (142 kB, 1.25 MB raw), which overstated bytes 1.8x and raw bytes 7.2x.
    double bytes = 0, rawBytes = 0;
    int64_t rects = 0;
    s.client->setRecordCallback([&](const UpdateRecord& r) {
        if (r.full)
            return;
        bytes += r.bytes;
        rawBytes += r.rawBytes;
        ++rects;
    });
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
    s.client->setRecordCallback({});
    state.counters["bytes_per_update"] = rects ? bytes / double(rects) : 0.0;
    state.counters["raw_bytes_per_update"] = rects ? rawBytes / double(rects) : 0.0;
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

// skull:128 at the paper's spacing (its 128 voxels project to the paper's size in a 500 px view).
const Volume& paperSkull() {
    static const Volume v = [] {
        Volume s = makeSkull(128);
        s.setSpacing(glm::vec3(paperSpacingMm(128)));
        return s;
    }();
    return v;
}

// The update study's dbi method (study/update_study.h): each cycle cuts fresh bone (the box's
// voxels are put back between cycles, unmeasured), cause -> rectangle applied at the client.
void boxSweep(benchmark::State& state, Codec codec) {
    const int n = int(state.range(0));
    UpdateStudyConfig config;
    config.sizes = {n};
    config.codec = codec;
    config.methods = {"dbi"};
    config.cycles = 30;
    UpdateStudyRow row;
    for (auto _ : state)
        row = runUpdateStudy(paperSkull(), config).at(0);
    state.counters["N"] = n;
    state.counters["latency_p50_us"] = row.latencyP50Ms * 1e3;
    state.counters["latency_p99_us"] = row.latencyP99Ms * 1e3;
    state.counters["target_p50_us"] = n == 40 ? 2000 : 0;
    state.counters["target_p99_us"] = n == 40 ? 5000 : 0;
    state.counters["bb_screen_px"] = row.bbScreenW * row.bbScreenH;
    state.counters["server_render_us"] = row.stages.render * 1e3;
    state.counters["server_encode_us"] = row.stages.encode * 1e3;
    state.counters["transmit_us"] = row.stages.transmit * 1e3;
    state.counters["client_apply_us"] = row.stages.clientApply * 1e3;
    state.counters["bytes_per_update"] = row.bytesPerUpdate;
    // Against the raw codec's 8 bytes a pixel (the reference) and the 5-byte planar layout.
    state.counters["raw_codec_bytes"] = 8.0 * row.bbScreenW * row.bbScreenH;
    state.counters["planar_over_bytes"] =
        row.bytesPerUpdate > 0 ? row.rawBytesPerUpdate / row.bytesPerUpdate : 0;
}

// Tool state out, HapticModel back, one in flight, at 1 kHz, a 2 mm burr pressed 1 mm into the
// bone at the default site (the paper: 0.82 ms over its LAN).
void forceRoundTrip(benchmark::State& state) {
    Session s(Codec::Lz4, "paper", 64);
    ForceRoundTripConfig fc;
    fc.shape = ToolShape::burr(2.0f);
    fc.pose = ToolPose::fromAxis(s.site.position + s.site.normal * 0.0f, s.site.normal);
    fc.samples = 2000;
    ForceRoundTripResult r;
    for (auto _ : state)
        r = measureForceRoundTrip(parseAddress("127.0.0.1:" + std::to_string(s.server->port())),
                                  fc);
    state.counters["round_trip_p50_us"] = r.p50Us;
    state.counters["round_trip_p99_us"] = r.p99Us;
    state.counters["target_p50_us"] = 300;
    state.counters["paper_us"] = 820;
    state.counters["server_p50_us"] = r.serverP50Us;
    state.counters["contacts"] = r.contacts;
    state.counters["lost"] = r.lost;
}

// A device held still at one pose.
class HoldDevice : public Device {
public:
    explicit HoldDevice(ToolPose p) : m_pose(p) {}
    std::string name() const override { return "hold"; }
    DeviceState read(double) override { return {m_pose, 0, true}; }
    void setForce(glm::vec3) override {}

private:
    ToolPose m_pose;
};

// The haptic loop on its own thread (1 kHz, tool states at 100 Hz) with the burr in contact,
// while another thread cuts 20^3 boxes every 10 ms so the server streams DBI updates to the
// same client (500x500 paper view, lz4).
void hapticLoopWhileStreaming(benchmark::State& state) {
    Session s(Codec::Lz4, "paper", 500, paperSkull());
    HoldDevice device(ToolPose::fromAxis(s.site.position, s.site.normal));
    std::mutex sendMutex;
    std::deque<ToolState> toSend;
    HapticLoop loop(device, {}, [&](const DeviceState& d, double) {
        ToolState t;
        t.diameterMm = 2.0f;
        t.position = d.pose.position;
        t.orientation = d.pose.orientation;
        t.clientTimeUs = steadyNowUs();
        std::lock_guard lock(sendMutex);
        toSend.push_back(t);
    });
    uint64_t loopStart = 0;
    s.client->setHapticCallback([&](const HapticModel& m, uint64_t arrivalUs) {
        loop.setModel(net::toModelData(m), double(int64_t(arrivalUs) - int64_t(loopStart)) * 1e-6);
    });
    HapticLoopStats st;
    uint64_t updates = 0;
    for (auto _ : state) {
        uint64_t updates0 = s.client->updatesApplied();
        std::atomic<bool> stop{false};
        std::thread cutter([&] {
            int i = 0;
            while (!stop.load()) {
                s.server->submitBoxCut(surfaceBox(s.skull, 20, (i++ % 9) * 4 - 16));
                std::this_thread::sleep_for(std::chrono::milliseconds(10));
            }
        });
        loopStart = steadyNowUs();
        loop.start();
        uint64_t end = steadyNowUs() + 3000000;
        std::vector<ToolState> batch;
        while (steadyNowUs() < end) {
            {
                std::lock_guard lock(sendMutex);
                batch.assign(toSend.begin(), toSend.end());
                toSend.clear();
            }
            for (const ToolState& t : batch)
                s.client->sendToolState(t);
            // As the headless trainee: short waits so queued tool states leave within ~0.2 ms.
            if (s.client->poll(0) == 0 && batch.empty())
                std::this_thread::sleep_for(std::chrono::microseconds(200));
        }
        loop.stop();
        stop = true;
        cutter.join();
        st = loop.stats();
        updates = s.client->updatesApplied() - updates0;
    }
    s.client->setHapticCallback({});
    const NetStats& ns = s.client->stats();
    state.counters["achieved_hz"] = st.achievedRateHz;
    state.counters["target_hz"] = 1000;
    state.counters["lateness_p50_ms"] = st.latenessP50Ms;
    state.counters["lateness_p99_ms"] = st.latenessP99Ms;
    state.counters["models"] = double(st.models);
    state.counters["force_rtt_p50_us"] = ns.hapticRoundTripUs.percentile(50);
    state.counters["force_rtt_p99_us"] = ns.hapticRoundTripUs.percentile(99);
    state.counters["dbi_updates"] = double(updates);
    state.counters["update_latency_p50_us"] = ns.updateLatencyUs.percentile(50);
}

} // namespace

BENCHMARK_CAPTURE(boxSweep, raw, Codec::Raw)->DenseRange(10, 80, 10)->Iterations(1)->UseRealTime();
BENCHMARK_CAPTURE(boxSweep, lz4, Codec::Lz4)->DenseRange(10, 80, 10)->Iterations(1)->UseRealTime();
BENCHMARK_CAPTURE(boxSweep, zstd, Codec::Zstd)
    ->DenseRange(10, 80, 10)
    ->Iterations(1)
    ->UseRealTime();
BENCHMARK(forceRoundTrip)->Iterations(1)->UseRealTime()->Unit(benchmark::kMillisecond);
BENCHMARK(hapticLoopWhileStreaming)->Iterations(1)->UseRealTime()->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(burrStroke, raw_burr5mm, Codec::Raw, 5.0f)->Iterations(200)->UseRealTime();
BENCHMARK_CAPTURE(burrStroke, lz4_burr5mm, Codec::Lz4, 5.0f)->Iterations(200)->UseRealTime();
BENCHMARK_CAPTURE(burrStroke, zstd_burr5mm, Codec::Zstd, 5.0f)->Iterations(200)->UseRealTime();
BENCHMARK_CAPTURE(fullRefresh, lz4, Codec::Lz4)->Iterations(10)->UseRealTime();

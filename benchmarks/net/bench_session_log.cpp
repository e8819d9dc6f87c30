// What --record adds to a tool state's path: framing one Tool record and write(2)ing it (the
// recorder's fdatasync runs on its own thread every 100 ms, as in the server), and what a served
// replay's seek backwards costs (a rebuild from the log's start).
#include "net/replay_feed.h"
#include "net/session_log.h"
#include "net/session_replay.h"
#include "net/session_server.h"

#include "libsim/skull.h"
#include "net/server_config.h"

#include <benchmark/benchmark.h>

#include <chrono>
#include <filesystem>
#include <thread>
#include <unistd.h>

using namespace trephine;
using namespace trephine::net;

namespace {

std::string logPath(const char* name) {
    const std::string p = (std::filesystem::temp_directory_path() /
                           (std::string("trephine_bench_") + name + std::to_string(getpid())))
                              .string();
    std::filesystem::remove(p);
    return p;
}

LogRecord toolRecord(uint32_t i) {
    ToolEvent e{1, {}};
    e.tool.sequence = i + 1;
    e.tool.clientTimeUs = 1000 + i * 10000ull;
    e.tool.diameterMm = 5.0f;
    e.tool.position = {0.0f, 0.0f, 20.0f - 0.001f * float(i % 1000)};
    e.tool.speed = 1.0f;
    e.tool.drilling = true;
    return {e.tool.clientTimeUs, e};
}

void BM_RecordOneToolState(benchmark::State& state) {
    const std::string path = logPath("write");
    const Volume sphere = makeSphere(32);
    ServerConfig c;
    auto recorder = SessionRecorder::create(path, makeLogHeader(sphere, c, "sphere:32", false, 0));
    uint32_t i = 0;
    for (auto _ : state) {
        const LogRecord r = toolRecord(i++);
        benchmark::DoNotOptimize(recorder->write({&r, 1}));
        recorder->tick(steadyNowUs()); // as the server's network loop: the syncs run meanwhile
    }
    state.counters["bytes/record"] =
        benchmark::Counter(double(recorder->bytes()) / double(std::max<uint64_t>(1, i)));
    recorder.reset();
    std::filesystem::remove(path);
}
BENCHMARK(BM_RecordOneToolState);

} // namespace

namespace {

// A trainee's `seconds` of drilling on skull:128 at 100 tool states a second: a burr hole at the
// default site, circling out from 1 to 4 mm while sinking from 1 to 6 mm, as a log's records.
std::vector<LogRecord> drillingLog(const Volume& skull, int seconds) {
    const SurfaceSite site = defaultBurrSite(skull);
    const glm::vec3 n = glm::normalize(site.normal);
    const glm::vec3 u = glm::normalize(
        glm::cross(n, std::abs(n.x) < 0.9f ? glm::vec3(1, 0, 0) : glm::vec3(0, 1, 0)));
    const glm::vec3 v = glm::cross(n, u);
    std::vector<LogRecord> records{{0, HelloEvent{1, Role::Trainee, "Ada"}},
                                   {0, JoinEvent{.client = 1}}};
    const int states = seconds * 100;
    for (int i = 0; i < states; ++i) {
        LogRecord r = toolRecord(uint32_t(i));
        const float a = float(i) * 0.01f, f = float(i) / float(states);
        r.as<ToolEvent>()->tool.position = site.position +
                                           (1.0f + 3.0f * f) * (std::cos(a) * u + std::sin(a) * v) -
                                           n * (1.0f + 5.0f * f);
        records.push_back(r);
    }
    return records;
}

// A window's seek backwards in a served log (`replay --serve`): from the end to the middle, the
// server rebuilds from the log's start volume and plays half the records again. Timed from the
// control to the server being idle with the state answering it.
void BM_ReplaySeekBack(benchmark::State& state) {
    const Volume skull = makeSkull(128);
    const std::vector<LogRecord> records = drillingLog(skull, int(state.range(0)));
    ServerConfig base;
    base.port = 0;
    base.renderThreads = 1;
    LogHeader header = makeLogHeader(skull, base, "skull:128", false, 0);
    SessionServer server(skull, replayServerConfig(header, base));
    server.serveLog(records, 1.0, false);
    server.start();
    const uint64_t end = sessionTimesUs(records).back();
    uint32_t seeks = 0;
    auto seek = [&](uint64_t to) {
        server.controlReplay({ReplayControl::Op::Seek, to});
        ++seeks;
        for (;;) {
            const std::optional<ReplayState> s = server.replayState();
            if (s && s->seeks == seeks && server.idle())
                return;
            std::this_thread::sleep_for(std::chrono::microseconds(200));
        }
    };
    for (auto _ : state) {
        state.PauseTiming();
        seek(end);
        state.ResumeTiming();
        seek(end / 2);
    }
    state.counters["session_s"] = double(end) * 1e-6;
    // The session drills: voxels changed by the middle.
    const Volume now = server.volumeSnapshot();
    size_t changed = 0;
    for (size_t i = 0; i < now.voxelCount(); ++i)
        changed += now.densityData()[i] != skull.densityData()[i];
    state.counters["voxels_changed"] = double(changed);
    server.stop();
}
BENCHMARK(BM_ReplaySeekBack)->Arg(60)->Arg(600)->Unit(benchmark::kMillisecond)->Iterations(3);

} // namespace

// What --record adds to a tool state's path: framing one Tool record and write(2)ing it (the
// recorder's fdatasync runs on its own thread every 100 ms, as in the server), and what a replay
// costs per record of drilling.
#include "net/session_log.h"
#include "net/session_replay.h"

#include "libsim/skull.h"
#include "net/server_config.h"

#include <benchmark/benchmark.h>

#include <filesystem>
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
    LogRecord r;
    r.kind = LogRecord::Kind::Tool;
    r.timeUs = 1000 + i * 10000ull;
    r.client = 1;
    r.tool.sequence = i + 1;
    r.tool.clientTimeUs = r.timeUs;
    r.tool.diameterMm = 5.0f;
    r.tool.position = {0.0f, 0.0f, 20.0f - 0.001f * float(i % 1000)};
    r.tool.speed = 1.0f;
    r.tool.drilling = true;
    return r;
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
    }
    state.counters["bytes/record"] =
        benchmark::Counter(double(recorder->bytes()) / double(std::max<uint64_t>(1, i)));
    recorder.reset();
    std::filesystem::remove(path);
}
BENCHMARK(BM_RecordOneToolState);

} // namespace

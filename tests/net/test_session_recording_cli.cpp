// `trephine server --record` killed with SIGKILL at random moments while a trainee drills: the
// log it leaves holds every change the trainee had seen. The check is exact: the trainee's DBI
// (raw codec, so its depth is the server's floats) equals, bit for bit, a render of the volume
// the log replays to after some prefix of its records. `--resume` then continues the log, and
// its --save-on-exit equals `trephine replay --save` of the whole log. `trephine replay --report`
// recomputes the participants' assessment metrics: they equal the server's own --report. A log
// with a byte flipped in a middle record replays and resumes from every other record, the damaged
// file kept whole beside it; a FIFO given as a log is refused at once.
#include "child_process.h"
#include "net/session_log.h"
#include "net/session_replay.h"

#include "net/session_client.h"
#include "net/view.h"

#include "libsim/skull.h"
#include "libsim/volume_io.h"

#include "loopback.h"
#include "test_support.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <random>
#include <string>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>
#include <vector>

using namespace trephine;
using namespace trephine::net;

using trephine::testing::burrState;
using trephine::testing::Child;
using trephine::testing::loopback;
using trephine::testing::namedClientConfig;
using trephine::testing::pumpUntil;

namespace {

constexpr int kN = 48;

std::string tempPath(const std::string& name) {
    const std::string p = (std::filesystem::temp_directory_path() /
                           ("trephine_kill_" + std::to_string(getpid()) + "_" + name))
                              .string();
    std::filesystem::remove(p);
    return p;
}

// Where each record of the log in `bytes` starts (the header's frame skipped), by its lengths.
std::vector<size_t> recordStarts(const std::string& bytes) {
    std::vector<size_t> starts;
    auto u32 = [&](size_t at) {
        uint32_t v = 0;
        for (int i = 0; i < 4; ++i)
            v |= uint32_t(uint8_t(bytes[at + i])) << (8 * i);
        return v;
    };
    for (size_t at = kLogPreambleBytes; at + kLogFrameBytes <= bytes.size();
         at += kLogFrameBytes + u32(at))
        if (at != kLogPreambleBytes)
            starts.push_back(at);
    return starts;
}

void writeBytes(const std::string& path, const std::string& bytes) {
    std::ofstream(path, std::ios::binary | std::ios::trunc) << bytes;
}

} // namespace

TEST(SessionRecordingCli, ASigkilledServersLogHoldsEveryChangeItsClientHadSeen) {
    const Volume sphere = makeSphere(kN);
    std::mt19937 rng(2511);
    constexpr int kTrials = 20;
    int torn = 0, matchedBeforeEnd = 0, drilledSeen = 0;
    for (int trial = 0; trial < kTrials; ++trial) {
        SCOPED_TRACE("trial " + std::to_string(trial));
        const std::string log = tempPath(std::to_string(trial) + ".log");
        Child server({"server", "--open", "--port", "0", "--volume", "sphere:48",
                      "--render-threads", "1", "--record", log});
        const int port = server.port();
        ASSERT_GT(port, 0);
        ClientConfig config = namedClientConfig(sphere, "Ada", Role::Trainee, 48);
        config.codec = Codec::Raw; // the DBI's depth is then the server's floats, bit for bit
        SessionClient ada(config);
        ada.connect(loopback(uint16_t(port)));
        ASSERT_TRUE(pumpUntil({&ada}, [&] { return ada.hasFullImage(); }));

        // Drill a stroke (at a random site) and kill the server after a random number of states,
        // some while updates are in flight; then take whatever it had sent.
        const float a = glm::radians(std::uniform_real_distribution<float>(-60, 60)(rng));
        const glm::vec3 normal(std::sin(a), 0.0f, std::cos(a));
        const SurfaceSite site{normal * sphereRadiusMm(kN), normal};
        const int killAfter = std::uniform_int_distribution<int>(0, 60)(rng);
        for (int i = 0; i < killAfter; ++i) {
            ada.sendToolState(burrState(site, i, 60, 1000000));
            ada.poll(1);
            if (i % 7 == 3)
                ada.poll(2);
        }
        EXPECT_EQ(server.end(SIGKILL), -1);
        for (int i = 0; i < 50; ++i)
            ada.poll(1);
        const Dbi seen = ada.dbi();

        const LogContents contents = readSessionLog(log);
        torn += !contents.stopped.empty();
        SessionReplay replay(contents.header, logStartVolume(contents.header, loadVolume));
        const Camera camera = toCamera(config.view);
        const Dbi start = replay.render(camera);
        drilledSeen += !(seen == start);
        // The newest prefix of the log whose volume renders exactly the trainee's picture.
        bool matched = seen == start;
        size_t matchedAt = 0;
        for (size_t i = 0; i < contents.records.size(); ++i) {
            replay.apply(contents.records[i]);
            if (contents.records[i].is<ToolEvent>() && replay.render(camera) == seen) {
                matched = true;
                matchedAt = i + 1;
            }
        }
        EXPECT_TRUE(matched) << "the trainee saw a change the log does not hold (" << killAfter
                             << " states sent, " << contents.records.size() << " records kept; "
                             << contents.stopped << ")";
        matchedBeforeEnd += matched && matchedAt < contents.records.size();

        // Every fifth trial: --resume continues the log, and the trainee's exported path runs
        // again against it as a headless script; the resumed server's save equals `replay
        // --save` of the whole log, and holds every voxel the killed server's log had cut.
        if (trial % 5 == 0) {
            const trephine::testing::TempDir dir;
            const std::string saved = dir / "resumed.nrrd", again = dir / "replayed.nrrd";
            const std::string paths = dir / "paths";
            auto trephine = [&](const std::string& args) {
                const trephine::testing::CommandResult r =
                    trephine::testing::runTrephine(dir, args);
                EXPECT_EQ(r.exitCode, 0) << args << ": " << r.err;
                return r.out;
            };
            trephine("replay " + trephine::testing::shellQuote(log) + " --trajectories " +
                     trephine::testing::shellQuote(paths));
            const std::string killed = trephine::testing::slurp(log);
            Child resumed({"server", "--open", "--port", "0", "--resume", log, "--render-threads",
                           "1", "--save-on-exit", saved});
            const int again_port = resumed.port();
            // A torn tail is not cut off the only copy: the killed server's log is kept whole.
            if (contents.stopped.empty())
                EXPECT_FALSE(std::filesystem::exists(log + ".damaged-1"));
            else
                EXPECT_TRUE(trephine::testing::slurp(log + ".damaged-1") == killed);
            ASSERT_GT(again_port, 0);
            const std::string script = paths + "/01-Ada-trainee.csv";
            if (killAfter > 1) {
                ASSERT_TRUE(std::filesystem::exists(script));
                trephine("trainee --headless --connect 127.0.0.1:" + std::to_string(again_port) +
                         " --script " + trephine::testing::shellQuote(script) + " --duration 2");
            }
            EXPECT_EQ(resumed.end(SIGTERM), 0);
            const std::string out = trephine("replay " + trephine::testing::shellQuote(log) +
                                             " --save " + trephine::testing::shellQuote(again));
            EXPECT_NE(out.find("x real time"), std::string::npos) << out;
            EXPECT_EQ(trephine::testing::slurp(saved), trephine::testing::slurp(again));
            const Volume recovered = loadVolume(again);
            const Volume& before = replay.volume();
            bool kept = true;
            for (size_t v = 0; v < before.voxelCount(); ++v)
                kept = kept && recovered.densityData()[v] <= before.densityData()[v];
            EXPECT_TRUE(kept) << "the resumed session lost a cut the killed server's log held";
        }
        std::filesystem::remove(log);
        std::filesystem::remove(log + ".damaged-1");
    }
    // Said, not asserted: how many kills tore a record, and how often the log held changes the
    // trainee had not seen yet (the log runs ahead of what is sent, never behind).
    std::printf("[ recording ] %d trials: %d saw drilling, %d left a torn tail, %d logged more "
                "than the trainee saw\n",
                kTrials, drilledSeen, torn, matchedBeforeEnd);
    EXPECT_GT(drilledSeen, kTrials / 2) << "most trials saw drilling before the kill";
}

TEST(SessionRecordingCli, BadLogsAndClashingFlagsAreRefusedInOneLine) {
    const trephine::testing::TempDir dir;
    auto run = [&](const std::string& args) { return trephine::testing::runTrephine(dir, args); };
    const std::string notLog = dir / "not.log";
    std::ofstream(notLog) << "hello\n";
    trephine::testing::CommandResult r = run("replay " + trephine::testing::shellQuote(notLog));
    EXPECT_EQ(r.exitCode, 1);
    EXPECT_NE(r.err.find("not a Trephine session log"), std::string::npos) << r.err;
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
    // An existing file is never overwritten by a new log.
    r = run("server --port 0 --volume sphere:16 --record " + trephine::testing::shellQuote(notLog));
    EXPECT_EQ(r.exitCode, 1);
    EXPECT_NE(r.err.find("--resume continues a log"), std::string::npos) << r.err;
    r = run("server --port 0 --volume sphere:16 --resume " + trephine::testing::shellQuote(notLog));
    EXPECT_NE(r.exitCode, 0) << "--resume takes its volume from the log";
    const std::string log = dir / "s.log";
    r = run("server --port 0 --record " + trephine::testing::shellQuote(log) + " --report " +
            trephine::testing::shellQuote(log));
    EXPECT_EQ(r.exitCode, 1);
    EXPECT_NE(r.err.find("is the session log"), std::string::npos) << r.err;
    EXPECT_FALSE(std::filesystem::exists(log));
}

TEST(SessionRecordingCli, ReplayReportRecomputesTheServersParticipantMetrics) {
    const trephine::testing::TempDir dir;
    const Volume sphere = makeSphere(kN);
    const std::string log = dir / "s.log", live = dir / "live.json", again = dir / "again.json";
    {
        Child server({"server", "--open", "--port", "0", "--volume", "sphere:48",
                      "--render-threads", "1", "--record", log, "--report", live, "--caution-mm",
                      "5", "--danger-mm", "2"});
        const int port = server.port();
        ASSERT_GT(port, 0);
        SessionClient ada(namedClientConfig(sphere, "Ada", Role::Trainee, 32));
        SessionClient ben(namedClientConfig(sphere, "Ben", Role::Trainee, 32));
        // Ada joins first: the report lists participants in the order they joined.
        ada.connect(loopback(uint16_t(port)));
        ASSERT_TRUE(pumpUntil({&ada}, [&] { return ada.welcomed(); }));
        ben.connect(loopback(uint16_t(port)));
        ASSERT_TRUE(pumpUntil({&ada, &ben}, [&] {
            return ada.hasFullImage() && ben.hasFullImage() && ada.participants().size() == 2;
        }));
        const SurfaceSite top = trephine::testing::sphereTop(kN);
        const SurfaceSite side{{sphereRadiusMm(kN), 0.0f, 0.0f}, {1.0f, 0.0f, 0.0f}};
        for (int i = 0; i < 30; ++i) {
            ada.sendToolState(burrState(top, i, 30, 1000000));
            if (i < 20)
                ben.sendToolState(burrState(side, i, 20, 5000000));
            ada.poll(1);
            ben.poll(1);
        }
        // Whatever the server has received when it stops is both logged and applied (its
        // simulation drains the queue), so the report and the log hold the same states.
        for (int i = 0; i < 100; ++i) {
            ada.poll(1);
            ben.poll(1);
        }
        EXPECT_EQ(server.end(SIGTERM), 0);
    }
    auto run = [&](const std::string& args) { return trephine::testing::runTrephine(dir, args); };
    using trephine::testing::shellQuote;
    trephine::testing::CommandResult r =
        run("replay " + shellQuote(log) + " --report " + shellQuote(again));
    ASSERT_EQ(r.exitCode, 0) << r.err;
    EXPECT_NE(r.out.find("wrote " + again), std::string::npos) << r.out;
    const nlohmann::json j = nlohmann::json::parse(trephine::testing::slurp(again));
    const nlohmann::json server = nlohmann::json::parse(trephine::testing::slurp(live));
    EXPECT_EQ(j.at("log"), log);
    EXPECT_EQ(j.at("stopped"), "");
    EXPECT_EQ(j.at("assessment").at("caution_mm"), 5.0) << "the zones come from the log";
    EXPECT_EQ(j.at("assessment").at("danger_mm"), 2.0);
    ASSERT_EQ(j.at("participants").size(), 2u);
    EXPECT_EQ(j.at("participants")[0].at("name"), "Ada");
    EXPECT_EQ(j.at("participants")[1].at("name"), "Ben");
    for (const nlohmann::json& p : j.at("participants")) {
        EXPECT_GT(p.at("metrics").at("bone_removed_voxels").at("cortical").get<int64_t>(), 0);
        EXPECT_GT(p.at("metrics").at("max_force_n").get<double>(), 0.0);
    }
    EXPECT_EQ(j.at("participants"), server.at("participants"))
        << "replayed:\n"
        << j.at("participants").dump(1) << "\nlive:\n"
        << server.at("participants").dump(1);

    // Bad paths: one line each, and the log is never overwritten.
    const std::string logBytes = trephine::testing::slurp(log);
    r = run("replay " + shellQuote(log) + " --report " + shellQuote(dir / "no/such/r.json"));
    EXPECT_EQ(r.exitCode, 1);
    EXPECT_NE(r.err.find("--report"), std::string::npos) << r.err;
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
    r = run("replay " + shellQuote(log) + " --report " + shellQuote(log));
    EXPECT_EQ(r.exitCode, 1);
    EXPECT_NE(r.err.find("is the session log"), std::string::npos) << r.err;
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
    EXPECT_EQ(trephine::testing::slurp(log), logBytes);
    r = run("replay " + shellQuote(log) + " --report " + shellQuote(dir.path.string()));
    EXPECT_NE(r.exitCode, 0);
    EXPECT_NE(r.err.find("is a folder"), std::string::npos) << r.err;
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
    r = run("replay " + shellQuote(dir / "missing.log") + " --report " + shellQuote(again));
    EXPECT_NE(r.exitCode, 0);
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
}

TEST(SessionRecordingCli, ALogDamagedMidwayReplaysAndResumesFromEveryIntactRecord) {
    const trephine::testing::TempDir dir;
    using trephine::testing::shellQuote;
    using trephine::testing::slurp;
    const Volume sphere = makeSphere(kN);
    const std::string log = dir / "s.log";
    {
        // Ada drills, Ben joins midway (a Hello that changes no voxel), Ada drills elsewhere.
        Child server({"server", "--open", "--port", "0", "--volume", "sphere:48",
                      "--render-threads", "1", "--record", log});
        const int port = server.port();
        ASSERT_GT(port, 0);
        SessionClient ada(namedClientConfig(sphere, "Ada", Role::Trainee, 32));
        SessionClient ben(namedClientConfig(sphere, "Ben", Role::Trainee, 32));
        ada.connect(loopback(uint16_t(port)));
        ASSERT_TRUE(pumpUntil({&ada}, [&] { return ada.hasFullImage(); }));
        const SurfaceSite top = trephine::testing::sphereTop(kN);
        const SurfaceSite side{{sphereRadiusMm(kN), 0.0f, 0.0f}, {1.0f, 0.0f, 0.0f}};
        for (int i = 0; i < 30; ++i) {
            ada.sendToolState(burrState(top, i, 30, 1000000));
            ada.poll(1);
        }
        ben.connect(loopback(uint16_t(port)));
        ASSERT_TRUE(pumpUntil({&ada, &ben}, [&] { return ben.hasFullImage(); }));
        for (int i = 0; i < 30; ++i) {
            ToolState t = burrState(side, i, 30, 5000000);
            t.sequence += 30;
            ada.sendToolState(t);
            ada.poll(1);
        }
        for (int i = 0; i < 100; ++i) {
            ada.poll(1);
            ben.poll(1);
        }
        EXPECT_EQ(server.end(SIGTERM), 0);
    }
    const LogContents clean = readSessionLog(log);
    ASSERT_TRUE(clean.stopped.empty()) << clean.stopped;
    const std::string bytes = slurp(log);
    const std::vector<size_t> starts = recordStarts(bytes);
    ASSERT_EQ(starts.size(), clean.records.size());
    size_t hello = 0, tool = 0, tools = 0;
    for (size_t i = 0; i < clean.records.size(); ++i) {
        const LogRecord& r = clean.records[i];
        if (const HelloEvent* h = r.as<HelloEvent>(); h && h->name == "Ben")
            hello = i;
        if (r.is<ToolEvent>() && ++tools == 10)
            tool = i;
    }
    ASSERT_GT(hello, tool) << "Ben's hello comes after Ada's 10th tool state";
    ASSERT_GE(tools, 40u) << "states of both strokes were logged";
    const std::string copy = dir / "clean.log", helloLog = dir / "hello.log",
                      toolLog = dir / "tool.log";
    writeBytes(copy, bytes);
    // A byte of each record's time flipped: its fields read, its CRC does not match.
    std::string damaged = bytes;
    damaged[starts[hello] + 10] ^= 0x04;
    writeBytes(helloLog, damaged);
    damaged = bytes;
    damaged[starts[tool] + 10] ^= 0x04;
    writeBytes(toolLog, damaged);
    auto trephine = [&](const std::string& args) {
        const trephine::testing::CommandResult r = trephine::testing::runTrephine(dir, args);
        EXPECT_EQ(r.exitCode, 0) << args << ": " << r.err;
        return r.out;
    };
    auto said = [&](size_t i) {
        return "skipped " + std::to_string(starts[i + 1] - starts[i]) + " damaged bytes at byte " +
               std::to_string(starts[i]) + " (1 record, corrupt: its checksum does not match); " +
               "kept " + std::to_string(clean.records.size() - i - 1) + " records after it\n";
    };

    // Ben's hello lost: the volume is the undamaged log's, byte for byte.
    trephine("replay " + shellQuote(copy) + " --save " + shellQuote(dir / "clean.nrrd"));
    std::string out =
        trephine("replay " + shellQuote(helloLog) + " --save " + shellQuote(dir / "hello.nrrd"));
    EXPECT_NE(out.find("trephine replay: " + helloLog + ": " + said(hello)), std::string::npos)
        << out;
    EXPECT_NE(out.find(std::to_string(clean.records.size() - 1) + " records"), std::string::npos)
        << out;
    EXPECT_EQ(slurp(dir / "hello.nrrd"), slurp(dir / "clean.nrrd"));

    // A tool state lost: the volume of every other record, which holds the later ones' cuts.
    out = trephine("replay " + shellQuote(toolLog) + " --save " + shellQuote(dir / "tool.nrrd"));
    EXPECT_NE(out.find("trephine replay: " + toolLog + ": " + said(tool)), std::string::npos)
        << out;
    std::printf("[ damaged ] of %zu records: %s", clean.records.size(), said(tool).c_str());
    std::vector<LogRecord> intact = clean.records;
    intact.erase(intact.begin() + ptrdiff_t(tool));
    SessionReplay expected(clean.header, logStartVolume(clean.header, loadVolume));
    expected.applyAll(intact);
    saveVolume(expected.volume(), dir / "expected.nrrd");
    EXPECT_EQ(slurp(dir / "tool.nrrd"), slurp(dir / "expected.nrrd"));
    SessionReplay before(clean.header, logStartVolume(clean.header, loadVolume));
    before.applyAll(std::span(clean.records).first(tool));
    EXPECT_FALSE(std::equal(before.volume().densityData(),
                            before.volume().densityData() + before.volume().voxelCount(),
                            expected.volume().densityData()))
        << "the records after the damaged one cut, and were kept";

    // --resume keeps the damaged file whole beside the log, which then reads whole.
    {
        Child resumed({"server", "--open", "--port", "0", "--resume", toolLog, "--render-threads",
                       "1", "--save-on-exit", dir / "resumed.nrrd"});
        const std::string line = resumed.waitFor("kept the damaged log whole as");
        EXPECT_NE(line.find(toolLog + ".damaged-1; " + toolLog + " now holds its " +
                            std::to_string(intact.size()) + " intact records"),
                  std::string::npos)
            << line;
        ASSERT_GT(resumed.port(), 0);
        EXPECT_EQ(resumed.end(SIGTERM), 0);
    }
    EXPECT_TRUE(slurp(toolLog + ".damaged-1") == damaged) << "the damaged log, byte for byte";
    const LogContents after = readSessionLog(toolLog);
    EXPECT_TRUE(after.stopped.empty()) << after.stopped;
    ASSERT_EQ(after.records.size(), intact.size() + 1);
    for (size_t i = 0; i < intact.size(); ++i) {
        EXPECT_EQ(after.records[i].kind(), intact[i].kind()) << i;
        EXPECT_EQ(after.records[i].timeUs, intact[i].timeUs) << i;
    }
    EXPECT_TRUE(after.records.back().is<ResumeEvent>());
    out = trephine("replay " + shellQuote(toolLog) + " --save " + shellQuote(dir / "again.nrrd"));
    EXPECT_EQ(out.find("skipped"), std::string::npos) << out;
    EXPECT_EQ(slurp(dir / "again.nrrd"), slurp(dir / "resumed.nrrd"));
    EXPECT_EQ(slurp(dir / "again.nrrd"), slurp(dir / "expected.nrrd"));
}

TEST(SessionRecordingCli, AFifoGivenAsALogIsRefusedInOneLineAtOnce) {
    // A FIFO blocked `replay` and `server --resume` on opening it, with no message.
    const trephine::testing::TempDir dir;
    using trephine::testing::shellQuote;
    const std::string fifo = dir / "fifo.log";
    ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
    for (const std::string& args :
         {"replay " + shellQuote(fifo), "server --port 0 --resume " + shellQuote(fifo),
          "server --port 0 --volume sphere:16 --record " + shellQuote(fifo)}) {
        SCOPED_TRACE(args);
        const auto t0 = std::chrono::steady_clock::now();
        // Run under `timeout`: a regression fails (124) instead of hanging the suite.
        const int status =
            std::system(("timeout 10 " + shellQuote(TREPHINE_BIN) + " " + args + " >" +
                         shellQuote(dir / "out") + " 2>" + shellQuote(dir / "err"))
                            .c_str());
        const double seconds =
            std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
        const std::string err = trephine::testing::slurp(dir / "err");
        EXPECT_EQ(WIFEXITED(status) ? WEXITSTATUS(status) : -1, 1) << err;
        EXPECT_NE(err.find(fifo + ": is not a regular file (a device, pipe or socket)"),
                  std::string::npos)
            << err;
        EXPECT_EQ(std::count(err.begin(), err.end(), '\n'), 1) << err;
        EXPECT_LT(seconds, 1.0);
        std::printf("[ fifo ] %s: refused in %.3f s\n", args.c_str(), seconds);
    }
}

// `trephine replay FILE`: plays a session log (`trephine server --record`) through the server's
// own simulation step, and writes what is asked: the final volume (--save, bit for bit what the
// server held), each participant's tool path as a trainee script (--trajectories). A damaged
// stretch is said in one line and skipped, the records after it kept. With --serve it then plays
// the session into a live server at the recorded pace (times --speed), for any number of windows
// to watch, and serves its final state until stopped. docs/recording.md.
#include "modes.h"

#include "libsim/error.h"
#include "libsim/volume_io.h"
#include "libsim_image/volume_slices.h"
#include "net/replay_feed.h"
#include "net/session_log.h"
#include "net/session_replay.h"
#include "net/session_server.h"

#include <atomic>
#include <thread>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <sstream>

namespace trephine::app {

namespace {

struct ReplayOptions {
    std::string log;
    std::string save;
    std::string trajectories;
    std::string report;
    bool serve = false;
    uint16_t port = 7777;
    double speed = 1.0;
    bool wait = false;
    int renderThreads = 0;
};

std::atomic<bool> g_replayStop{false};

extern "C" void onReplayStop(int) {
    g_replayStop = true;
}

// --serve: a live server on the log's starting volume and scene, open to anyone (a replay has
// nothing to protect), playing the log on a timeline the windows drive (play, pause, seek,
// speed); the server runs until a stop signal.
int serveReplay(const ReplayOptions& o, net::LogContents log, Volume start) {
    net::ServerConfig base;
    base.port = o.port;
    base.renderThreads = o.renderThreads;
    net::ServerConfig config = net::replayServerConfig(log.header, base);
    const glm::ivec3 d = start.dims();
    net::SessionServer server(std::move(start), config);
    const size_t records = log.records.size();
    server.serveLog(std::move(log.records), o.speed, !o.wait);
    handleStopSignals(onReplayStop);
    std::signal(SIGPIPE, SIG_IGN);
    server.start();
    std::printf("trephine replay: serving %s (%s, %d x %d x %d) on port %u at %gx: a replay, "
                "open to anyone who connects (trephine instructor --connect 127.0.0.1:%u); "
                "Ctrl-C stops\n",
                o.log.c_str(), config.volumeName.c_str(), d.x, d.y, d.z, unsigned(server.port()),
                o.speed, unsigned(server.port()));
    auto state = [&] {
        std::optional<net::ReplayState> s;
        while (!(s = server.replayState()) && !g_replayStop.load())
            std::this_thread::sleep_for(std::chrono::milliseconds(2));
        return s.value_or(net::ReplayState{});
    };
    std::printf("trephine replay: %zu records over %.1f s of session; the windows' timeline "
                "plays, pauses, seeks and changes the speed\n",
                records, double(state().durationUs) * 1e-6);
    if (o.wait) {
        std::printf("trephine replay: waiting for a window to connect before playing\n");
        std::fflush(stdout);
        while (!g_replayStop.load() && server.clientCount() == 0)
            std::this_thread::sleep_for(std::chrono::milliseconds(10));
        server.controlReplay({net::ReplayControl::Op::Play});
    }
    std::fflush(stdout);
    bool atEnd = false;
    while (!g_replayStop.load()) {
        const net::ReplayState s = state();
        const bool end = !s.playing && s.positionUs == s.durationUs;
        if (end && !atEnd) {
            std::printf("trephine replay: at the end of the session (%.1f s); serving its final "
                        "state until Ctrl-C or a window plays it again\n",
                        double(s.durationUs) * 1e-6);
            std::fflush(stdout);
        }
        atEnd = end;
        std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    std::printf("trephine replay: stopping (%llu tool states applied)\n",
                (unsigned long long)server.toolStatesApplied());
    server.stop();
    return 0;
}

// Seconds of session the records span: each server's stretch (a Resume starts a new clock).
double sessionSeconds(const std::vector<net::LogRecord>& records) {
    return records.empty() ? 0.0 : double(net::sessionTimesUs(records).back()) * 1e-6;
}

// --trajectories: one CSV per tool of the session.
void writeTrajectories(const ReplayOptions& o, const net::LogContents& log) {
    const std::vector<net::Trajectory> paths = net::trajectoriesOf(log.records);
    for (const net::Trajectory& t : paths) {
        const std::string file =
            (std::filesystem::path(o.trajectories) / net::trajectoryFileName(t)).string();
        if (!writeReplacing(file, net::trajectoryCsv(t)))
            throw Error("--trajectories: cannot write " + file);
    }
    std::printf("trephine replay: wrote %zu trajector%s into %s\n", paths.size(),
                paths.size() == 1 ? "y" : "ies", o.trajectories.c_str());
}

// The outputs, checked before the log is read: their folders, and none on another or on the log.
void checkReplayOutputs(const ReplayOptions& o) {
    if (!o.save.empty()) {
        checkSaveTarget(o.save);
        if (!savesMaterials(o.save))
            throw Error("--save " + o.save +
                        ": NIfTI keeps no materials (dura and brain would reload as bone); save "
                        "as .nrrd or .nhdr");
    }
    if (!o.trajectories.empty()) {
        std::error_code ec;
        std::filesystem::create_directories(o.trajectories, ec);
        if (!std::filesystem::is_directory(o.trajectories, ec))
            throw Error("--trajectories " + o.trajectories + ": cannot make that folder");
    }
    if (!o.report.empty()) {
        checkOutputFolder("--report", o.report);
        if (samePath(o.report, o.log))
            throw Error("--report " + o.report + " is the session log: write the report elsewhere");
        if (!o.save.empty() && samePath(o.report, o.save))
            throw Error("--report and --save name one file " + o.report + ": give each its own");
    }
}

int runReplay(const ReplayOptions& o) {
    checkReplayOutputs(o);
    const auto t0 = std::chrono::steady_clock::now();
    net::LogContents log = net::readSessionLog(o.log);
    std::istringstream damage(log.stopped);
    for (std::string line; std::getline(damage, line);)
        std::printf("trephine replay: %s\n", line.c_str());
    Volume start = net::logStartVolume(log.header, openVolume);
    if (o.serve && o.save.empty() && o.trajectories.empty() && o.report.empty())
        return serveReplay(o, std::move(log), std::move(start));
    net::SessionReplay replay(log.header, start);
    const auto t1 = std::chrono::steady_clock::now();
    replay.applyAll(log.records);
    const auto t2 = std::chrono::steady_clock::now();
    const double loadS = std::chrono::duration<double>(t1 - t0).count();
    const double replayS = std::chrono::duration<double>(t2 - t1).count();
    const double sessionS = sessionSeconds(log.records);
    // The target is the whole run's (reading, regenerating the volume, replaying): a short
    // session is dominated by the start.
    const double wholeS = loadS + replayS;
    std::printf("trephine replay: %s: %zu records, %llu tool states applied; %.2f s of session "
                "replayed in %.1f ms (%.0fx real time), %.0fx with the start's %.3f s (target "
                ">= 20x)\n",
                o.log.c_str(), log.records.size(), (unsigned long long)replay.toolStatesApplied(),
                sessionS, replayS * 1e3, replayS > 0 ? sessionS / replayS : 0.0,
                wholeS > 0 ? sessionS / wholeS : 0.0, loadS);
    if (!o.save.empty()) {
        saveVolume(replay.volume(), o.save);
        std::printf("trephine replay: wrote %s\n", o.save.c_str());
    }
    if (!o.trajectories.empty())
        writeTrajectories(o, log);
    if (!o.report.empty()) {
        if (!writeReplacing(o.report, net::replayReportText(replay, log, o.log)))
            throw Error("--report " + o.report + ": cannot write it");
        std::printf("trephine replay: wrote %s\n", o.report.c_str());
    }
    if (o.serve)
        return serveReplay(o, std::move(log), std::move(start));
    return 0;
}

} // namespace

void addReplayMode(CLI::App& root, int& exitCode) {
    auto o = std::make_shared<ReplayOptions>();
    CLI::App* sub = root.add_subcommand(
        "replay",
        "Play a session log (server --record): write its volume or tool paths, or serve it");
    sub->add_option("FILE", o->log, "The session log")->required()->check(CLI::ExistingFile);
    sub->add_option("--save", o->save,
                    "Write the final volume here (.nrrd or .nhdr): bit for bit the server's")
        ->check(outputFile());
    sub->add_option("--trajectories", o->trajectories,
                    "Write each participant's tool path here as a trainee script CSV "
                    "(docs/scripts.md), one file each");
    sub->add_option("--report", o->report,
                    "Write each participant's assessment metrics, recomputed from the log, here "
                    "(JSON, as the server's --report has them; docs/assessment.md)")
        ->check(outputFile());
    CLI::Option* serve = sub->add_flag(
        "--serve", o->serve,
        "Then play the session into a live server at its recorded pace, for windows to watch "
        "(trephine instructor --connect HOST:PORT), and serve its final state until Ctrl-C");
    sub->add_option("--port", o->port, "--serve: UDP port (0: any free port)")
        ->needs(serve)
        ->capture_default_str();
    sub->add_option("--speed", o->speed, "--serve: times the recorded pace (2: twice as fast)")
        ->needs(serve)
        ->check(finiteRange(net::kMinReplaySpeed, net::kMaxReplaySpeed))
        ->capture_default_str();
    sub->add_flag("--wait", o->wait,
                  "--serve: start playing once the first window has connected, so it sees the "
                  "whole session")
        ->needs(serve);
    sub->add_option("--render-threads", o->renderThreads, "--serve: render workers (0: all cores)")
        ->needs(serve)
        ->check(CLI::Range(0, 256));
    sub->callback([o, &exitCode] { exitCode = runReplay(*o); });
}

} // namespace trephine::app

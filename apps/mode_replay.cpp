// `trephine replay FILE`: plays a session log (`trephine server --record`) through the server's
// own simulation step, and writes what is asked: the final volume (--save, bit for bit what the
// server held), each participant's tool path as a trainee script (--trajectories). A torn or
// corrupt tail is said in one line and dropped. docs/recording.md.
#include "modes.h"

#include "libsim/error.h"
#include "libsim/volume_io.h"
#include "libsim_image/volume_slices.h"
#include "net/session_log.h"
#include "net/session_replay.h"

#include <chrono>
#include <cstdio>
#include <filesystem>

namespace trephine::app {

namespace {

struct ReplayOptions {
    std::string log;
    std::string save;
    std::string trajectories;
};

// Seconds of session the records span: each server's stretch (a Resume starts a new clock).
double sessionSeconds(const std::vector<net::LogRecord>& records) {
    double total = 0.0;
    uint64_t first = 0, last = 0;
    bool open = false;
    for (const net::LogRecord& r : records) {
        if (r.kind == net::LogRecord::Kind::Resume || !open) {
            total += open ? double(last - first) * 1e-6 : 0.0;
            first = last = r.timeUs;
            open = true;
            continue;
        }
        last = std::max(last, r.timeUs);
    }
    return total + (open ? double(last - first) * 1e-6 : 0.0);
}

int runReplay(const ReplayOptions& o) {
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
    const auto t0 = std::chrono::steady_clock::now();
    net::LogContents log = net::readSessionLog(o.log);
    if (!log.stopped.empty())
        std::printf("trephine replay: %s\n", log.stopped.c_str());
    net::SessionReplay replay(log.header, net::logStartVolume(log.header, openVolume));
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
    if (!o.trajectories.empty()) {
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
    return 0;
}

} // namespace

void addReplayMode(CLI::App& root, int& exitCode) {
    auto o = std::make_shared<ReplayOptions>();
    CLI::App* sub = root.add_subcommand(
        "replay", "Play a session log (server --record) and write its volume or tool paths");
    sub->add_option("FILE", o->log, "The session log")->required()->check(CLI::ExistingFile);
    sub->add_option("--save", o->save,
                    "Write the final volume here (.nrrd or .nhdr): bit for bit the server's")
        ->check(outputFile());
    sub->add_option("--trajectories", o->trajectories,
                    "Write each participant's tool path here as a trainee script CSV "
                    "(docs/scripts.md), one file each");
    sub->callback([o, &exitCode] { exitCode = runReplay(*o); });
}

} // namespace trephine::app

// `trephine server`: hold the skull and serve trainees and instructors over ENet until SIGINT,
// SIGTERM, SIGHUP or SIGQUIT, then apply every queued tool state and write --save-on-exit (the
// volume, and the instructors' marks and the scene beside it, which a later `--volume` of that
// file reads back).
#include "modes.h"

#include "libsim/error.h"
#include "libsim_image/volume_slices.h"
#include "net/marks_file.h"
#include "net/scene.h"
#include "net/session_server.h"

#include <atomic>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <thread>

namespace trephine::app {

namespace {

std::atomic<bool> g_stopRequested{false};

extern "C" void onStopSignal(int) {
    g_stopRequested = true;
}

struct ServerOptions {
    uint16_t port = 7777;
    std::string volume = "skull:128";
    std::string saveOnExit;
    int renderThreads = 0;
    size_t maxClients = 16;
    std::string report;
    float cautionMm = 3.0f, dangerMm = 1.0f;
    std::string debrief;
};

int runServer(const ServerOptions& o) {
    // Written when the session ends: a folder that is not there would lose its statistics.
    if (!o.report.empty()) {
        checkOutputFolder("--report", o.report);
        // The report is written after the save: over it, the drilled skull would become JSON.
        if (!o.saveOnExit.empty()) {
            for (const std::string& saved :
                 {o.saveOnExit, net::marksPathFor(o.saveOnExit), net::scenePathFor(o.saveOnExit)})
                if (samePath(o.report, saved))
                    throw Error("--report " + o.report +
                                " is where --save-on-exit writes the session: give it another "
                                "name");
        }
    }
    if (!(o.dangerMm > 0.0f && o.dangerMm < o.cautionMm && o.cautionMm < 20.0f))
        throw Error("--danger-mm and --caution-mm: need 0 < danger < caution < 20 mm");
    if (!o.debrief.empty()) {
        std::error_code made;
        std::filesystem::create_directories(o.debrief, made);
        if (!std::filesystem::is_directory(o.debrief))
            throw Error("--debrief " + o.debrief + ": not a folder that can be made");
    }
    Volume volume = openVolume(o.volume);
    net::ServerConfig config;
    config.cautionMm = o.cautionMm;
    config.dangerMm = o.dangerMm;
    config.debriefDir = o.debrief;
    // A session saved by --save-on-exit left its marks beside the volume: they come back too.
    const std::string volumeFile = volumeFileOf(o.volume);
    const std::string marks = net::marksPathFor(volumeFile);
    std::error_code ec;
    if (!volumeFile.empty() && std::filesystem::is_regular_file(marks, ec)) {
        config.marks = net::readMarksFile(marks);
        std::printf("trephine server: %zu mark%s from %s\n", config.marks.size(),
                    config.marks.size() == 1 ? "" : "s", marks.c_str());
    }
    // And its scene (presets, sites, the surgical field), so every preset names the view it named
    // before the save, however the skull was drilled since; otherwise built from the volume.
    config.scene = std::make_shared<const net::Scene>(net::sceneForVolume(volume, volumeFile));
    if (!volumeFile.empty() && std::filesystem::is_regular_file(net::scenePathFor(volumeFile), ec))
        std::printf("trephine server: the scene from %s\n", net::scenePathFor(volumeFile).c_str());
    config.port = o.port;
    config.volumeName = o.volume;
    config.saveOnExit = o.saveOnExit;
    config.renderThreads = o.renderThreads;
    config.maxClients = o.maxClients;
    glm::ivec3 d = volume.dims();
    net::SessionServer server(std::move(volume), config);
    // Every way a session is ended from outside saves it. Output gone (a `| tee` ended first) must
    // not kill it either: SIGPIPE is ignored and the lines are lost, not the session.
    handleStopSignals(onStopSignal);
    std::signal(SIGPIPE, SIG_IGN);
    server.start();
    std::printf("trephine server: %s (%d x %d x %d) on port %u; Ctrl-C stops\n", o.volume.c_str(),
                d.x, d.y, d.z, unsigned(server.port()));
    std::fflush(stdout);
    while (!g_stopRequested.load())
        std::this_thread::sleep_for(std::chrono::milliseconds(50));
    std::printf("trephine server: stopping (%llu tool states applied, %llu malformed dropped)\n",
                (unsigned long long)server.toolStatesApplied(),
                (unsigned long long)server.malformedTotal());
    server.stop();
    // A failed --save-on-exit was said by stop(), with the emergency copy it made instead.
    if (!o.saveOnExit.empty() && server.saveError().empty())
        std::printf("trephine server: wrote %s, %s and %s\n", o.saveOnExit.c_str(),
                    net::marksPathFor(o.saveOnExit).c_str(),
                    net::scenePathFor(o.saveOnExit).c_str());
    for (const std::string& d : server.debriefs())
        std::printf("trephine server: wrote %s\n", d.c_str());
    if (!o.report.empty()) {
        if (!writeReplacing(o.report, server.reportJson()))
            throw Error("--report " + o.report + ": cannot write it");
        std::printf("trephine server: wrote %s\n", o.report.c_str());
    }
    return server.saveError().empty() ? 0 : 1;
}

} // namespace

void addServerMode(CLI::App& root, int& exitCode) {
    auto o = std::make_shared<ServerOptions>();
    CLI::App* sub =
        root.add_subcommand("server", "Hold the skull and serve trainees and instructors");
    sub->add_option("--port", o->port, "UDP port (0: any free port)")->capture_default_str();
    sub->add_option("--volume", o->volume, "Volume spec (see `trephine volume --help`)")
        ->capture_default_str();
    sub->add_option(
           "--save-on-exit", o->saveOnExit,
           "Write the final volume here when the server stops (.nrrd or .nhdr, which keep the "
           "materials), and "
           "the instructors' marks and the scene beside it (FILE.marks, FILE.scene, read back by "
           "--volume FILE)")
        ->check(outputFile());
    sub->add_option("--render-threads", o->renderThreads, "Render workers (0: all cores)")
        ->check(CLI::Range(0, 256));
    sub->add_option("--max-clients", o->maxClients,
                    "Participants at once; one more is refused (server full)")
        ->check(CLI::Range(1, 1024))
        ->capture_default_str();
    sub->add_option("--report", o->report,
                    "Write server statistics as JSON here when it stops (per channel and peer)")
        ->check(outputFile());
    sub->add_option("--caution-mm", o->cautionMm,
                    "A cutter this near a critical structure (dura, sinus, artery) is in caution")
        ->capture_default_str();
    sub->add_option("--danger-mm", o->dangerMm,
                    "... and this near, in danger; touching it is a violation")
        ->capture_default_str();
    sub->add_option("--debrief", o->debrief,
                    "Write a Markdown debrief with SVG plots per participant in this folder when "
                    "the server stops");
    sub->callback([o, &exitCode] { exitCode = runServer(*o); });
}

} // namespace trephine::app

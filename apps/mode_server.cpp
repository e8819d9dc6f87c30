// `trephine server`: hold the skull and serve trainees and instructors over ENet until SIGINT,
// SIGTERM, SIGHUP or SIGQUIT, then apply every queued tool state and write --save-on-exit (the
// volume, and the instructors' marks and the scene beside it, which a later `--volume` of that
// file reads back). --record FILE logs the session as it goes (net/session_log.h); --resume FILE
// replays such a log to where its server stopped and goes on appending to it (a damaged one kept
// aside whole first).
#include "link_option.h"
#include "modes.h"

#include "libsim/error.h"
#include "libsim_gpu/gpu_renderer.h"
#include "libsim_image/volume_slices.h"
#include "net/marks_file.h"
#include "net/replay_feed.h"
#include "net/scene.h"
#include "net/secure_channel.h"
#include "net/server_banner.h"
#include "net/session_log.h"
#include "net/session_replay.h"
#include "net/session_server.h"

#include <fmt/format.h>

#include <atomic>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
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
    size_t maxClients = net::ServerConfig{}.maxClients;
    std::string report;
    std::string traineeCode, instructorCode; // generated when not given (docs/security.md)
    bool open = false;                       // no codes: anyone who reaches the port joins
    std::string record;
    std::string resume;
    float cautionMm = 3.0f, dangerMm = 1.0f;
    std::string debrief;
    std::string renderer = "cpu"; // --renderer: cpu, gpu or auto (libsim_gpu/gpu_renderer.h)
    std::string link; // --link: the emulator on --port, the server on a private port behind it
};

// The codes the server runs with: given, or made now; none with --open.
void chooseCodes(const ServerOptions& o, net::ServerConfig& config) {
    if (o.open) {
        if (!o.traineeCode.empty() || !o.instructorCode.empty())
            throw Error(
                "--open runs without codes: leave out --trainee-code and --instructor-code");
        return;
    }
    config.traineeCode = o.traineeCode.empty() ? net::generateCode() : o.traineeCode;
    config.instructorCode = o.instructorCode.empty() ? net::generateCode() : o.instructorCode;
    if (net::normaliseCode(config.traineeCode) == net::normaliseCode(config.instructorCode))
        throw Error("--trainee-code and --instructor-code are the same: give two codes");
}

// Said once the port is known (the lines after "on port N"): the codes to read out or, open,
// that anyone can join (on stderr too, where it is hard to miss).
void printCodes(const ServerOptions& o, const net::ServerConfig& config, uint16_t port) {
    if (o.open) {
        const std::string warning = fmt::format(
            "trephine server: WARNING: --open: NO CODES. Anyone who can reach UDP port {} joins, "
            "may claim the instructor's role, and sees everything in the clear (images, volumes, "
            "marks, forces)\n",
            port);
        std::fputs(warning.c_str(), stdout);
        std::fputs(warning.c_str(), stderr);
        return;
    }
    std::printf("trephine server: trainee code    %s%s\n", config.traineeCode.c_str(),
                o.traineeCode.empty() ? " (generated)" : "");
    std::printf("trephine server: instructor code %s%s\n", config.instructorCode.c_str(),
                o.instructorCode.empty() ? " (generated)" : "");
}

// Whether a spec regenerates its volume (skull:N, sphere:N, box:N): a log then carries only its
// hash. Files and folders may change or vanish, so their voxels go into the log.
bool regenerates(const std::string& spec) {
    if (!volumeFileOf(spec).empty())
        return false;
    const std::string kind = spec.substr(0, spec.find_first_of(":?"));
    return kind == "skull" || kind == "sphere" || kind == "box";
}

uint64_t unixNowUs() {
    return uint64_t(std::chrono::duration_cast<std::chrono::microseconds>(
                        std::chrono::system_clock::now().time_since_epoch())
                        .count());
}

// The lines once the port is known: where to join from, the codes, the recording.
void printStarted(const ServerOptions& o, const net::ServerConfig& config,
                  const net::SessionServer& server, glm::ivec3 d, const net::LinkEmulator* link) {
    const uint16_t port = link ? link->port() : server.port();
    std::printf("trephine server: %s (%d x %d x %d) on port %u; Ctrl-C stops\n",
                config.volumeName.c_str(), d.x, d.y, d.z, unsigned(port));
    if (link)
        std::printf("trephine server: --link %s: clients reach port %u through the emulated link "
                    "(%s), the server behind it on port %u\n",
                    o.link.c_str(), unsigned(port), link->conditions().describe().c_str(),
                    unsigned(server.port()));
    printCodes(o, config, port);
    // Where to join from, and whether the session outlives the server (saved, or recorded).
    const bool keeps = !o.saveOnExit.empty() || config.recorder;
    for (const std::string& line :
         net::serverStartLines(port, net::localAddresses(), keeps, config.traineeCode))
        std::printf("trephine server: %s\n", line.c_str());
    if (config.recorder)
        std::printf("trephine server: recording to %s (written back every %d ms, synced every %d "
                    "ms)\n",
                    config.recorder->path().c_str(), net::SessionRecorder::kWritebackIntervalMs,
                    net::SessionRecorder::kDefaultSyncIntervalMs);
}

// What the stopped server wrote: the saved session, the debriefs, the report.
void printWritten(const ServerOptions& o, const net::SessionServer& server) {
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
}

// --resume: the log played to where its server stopped; what it found said on stdout.
Volume resumedVolume(const ServerOptions& o, net::ServerConfig& config) {
    net::Resumed resumed = net::resumeSession(o.resume, config, openVolume, unixNowUs());
    std::istringstream damage(resumed.stopped);
    for (std::string line; std::getline(damage, line);)
        std::printf("trephine server: %s\n", line.c_str());
    if (!resumed.keptAside.empty())
        std::printf("trephine server: kept the damaged log whole as %s; %s now holds its %zu "
                    "intact records, and goes on from them\n",
                    resumed.keptAside.c_str(), o.resume.c_str(), resumed.records);
    std::printf("trephine server: resumed %s: %zu records, %llu tool states applied, %zu "
                "mark%s\n",
                o.resume.c_str(), resumed.records, (unsigned long long)resumed.toolStates,
                config.marks.size(), config.marks.size() == 1 ? "" : "s");
    return std::move(resumed.volume);
}

// The volume, with the marks and the scene a --save-on-exit left beside it, and the recorder.
Volume startingVolume(const ServerOptions& o, net::ServerConfig& config) {
    Volume volume = openVolume(o.volume);
    // A session saved by --save-on-exit left its marks beside the volume: they come back too.
    const std::string volumeFile = volumeFileOf(o.volume);
    const std::string marks = net::marksPathFor(volumeFile);
    std::error_code ec;
    if (!volumeFile.empty() && std::filesystem::is_regular_file(marks, ec)) {
        config.marks = net::readMarksFile(marks);
        std::printf("trephine server: %zu mark%s from %s\n", config.marks.size(),
                    config.marks.size() == 1 ? "" : "s", marks.c_str());
    }
    // And its scene (presets, sites, the surgical field), so every preset names the view it
    // named before the save, however the skull was drilled since; otherwise built from the
    // volume.
    config.scene = std::make_shared<const net::Scene>(net::sceneForVolume(volume, volumeFile));
    if (!volumeFile.empty() && std::filesystem::is_regular_file(net::scenePathFor(volumeFile), ec))
        std::printf("trephine server: the scene from %s\n", net::scenePathFor(volumeFile).c_str());
    config.volumeName = o.volume;
    if (!o.record.empty())
        config.recorder = net::SessionRecorder::create(
            o.record,
            net::makeLogHeader(volume, config, o.volume, !regenerates(o.volume), unixNowUs()));
    return volume;
}

// The outputs written when the session ends, checked before it starts: none may land on another
// or on the log, and their folders must be there.
void checkServerOutputs(const ServerOptions& o) {
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
    // The log is the one record of the session: nothing else this run writes may land on it.
    const std::string& log = o.record.empty() ? o.resume : o.record;
    if (!log.empty()) {
        std::vector<std::string> outputs{o.report};
        if (!o.saveOnExit.empty())
            outputs.insert(outputs.end(), {o.saveOnExit, net::marksPathFor(o.saveOnExit),
                                           net::scenePathFor(o.saveOnExit)});
        for (const std::string& other : outputs)
            if (!other.empty() && samePath(log, other))
                throw Error(log + " is the session log: write the volume and the report elsewhere");
    }
    if (!(o.dangerMm > 0.0f && o.dangerMm < o.cautionMm && o.cautionMm < 20.0f))
        throw Error("--danger-mm and --caution-mm: need 0 < danger < caution < 20 mm");
    if (!o.debrief.empty()) {
        std::error_code made;
        std::filesystem::create_directories(o.debrief, made);
        if (!std::filesystem::is_directory(o.debrief))
            throw Error("--debrief " + o.debrief + ": not a folder that can be made");
    }
}

int runServer(const ServerOptions& o) {
    checkServerOutputs(o);
    net::ServerConfig config;
    config.cautionMm = o.cautionMm;
    config.dangerMm = o.dangerMm;
    config.debriefDir = o.debrief;
    config.port = o.link.empty() ? o.port : 0;
    config.saveOnExit = o.saveOnExit;
    config.renderThreads = o.renderThreads;
    config.maxClients = o.maxClients;
    chooseCodes(o, config);
    std::string rendering;
    if (auto gpu = gpu::chooseRenderer(gpu::parseRendererChoice(o.renderer), &rendering))
        config.renderer = *gpu;
    Volume volume = o.resume.empty() ? startingVolume(o, config) : resumedVolume(o, config);
    glm::ivec3 d = volume.dims();
    net::SessionServer server(std::move(volume), config);
    // Every way a session is ended from outside saves it. Output gone (a `| tee` ended first) must
    // not kill it either: SIGPIPE is ignored and the lines are lost, not the session.
    handleStopSignals(onStopSignal);
    std::signal(SIGPIPE, SIG_IGN);
    const auto link =
        net::startLinkEnd(o.link, net::LinkEnd::Server,
                          net::parseAddress("127.0.0.1:" + std::to_string(server.port())), o.port);
    server.start();
    printStarted(o, config, server, d, link.get());
    // The choice, and why; or, when the chosen renderer failed at start, what renders instead.
    std::printf("trephine server: rendering on %s\n",
                server.rendererFallbacks() ? server.rendererName().c_str() : rendering.c_str());
    std::fflush(stdout);
    while (!g_stopRequested.load())
        std::this_thread::sleep_for(std::chrono::milliseconds(50));
    std::printf("trephine server: stopping (%llu tool states applied, %llu malformed dropped)\n",
                (unsigned long long)server.toolStatesApplied(),
                (unsigned long long)server.malformedTotal());
    server.stop();
    printWritten(o, server);
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
    sub->add_option(
           "--renderer", o->renderer,
           "Render views on the cpu, the gpu (OpenGL 4.3, or 3.3, through EGL, no display needed; "
           "llvmpipe will do) or auto (the GPU when EGL finds a hardware one)")
        ->check(CLI::IsMember({"cpu", "gpu", "auto"}))
        ->capture_default_str();
    sub->add_option("--render-threads", o->renderThreads, "Render workers (0: all cores)")
        ->check(CLI::Range(0, 256));
    sub->add_option("--max-clients", o->maxClients,
                    "Participants at once; one more is refused (server full)")
        ->check(CLI::Range(1, 1024))
        ->capture_default_str();
    sub->add_option("--trainee-code", o->traineeCode,
                    "The code trainees join with (default: a fresh one, printed at start)")
        ->check(roleCode());
    sub->add_option("--instructor-code", o->instructorCode,
                    "The code instructors join with (default: a fresh one, printed at start)")
        ->check(roleCode());
    sub->add_flag("--open", o->open,
                  "No codes: anyone who reaches the port joins, in any role, unencrypted");
    sub->add_option("--report", o->report,
                    "Write server statistics as JSON here when it stops (per channel and peer)")
        ->check(outputFile());
    CLI::Option* record =
        sub->add_option("--record", o->record,
                        "Log every change to the session here as it happens (a new file; "
                        "docs/recording.md): `trephine replay` plays it, --resume continues it")
            ->check(outputFile());
    sub->add_option("--resume", o->resume,
                    "Start from a session log (--record's): replay it to where its server "
                    "stopped, then go on appending to it (--volume is the log's)")
        ->check(CLI::ExistingFile)
        ->excludes(record)
        ->excludes("--volume");
    sub->add_option("--caution-mm", o->cautionMm,
                    "A cutter this near a critical structure (dura, sinus, artery) is in caution")
        ->capture_default_str();
    sub->add_option("--danger-mm", o->dangerMm,
                    "... and this near, in danger; touching it is a violation")
        ->capture_default_str();
    addLinkOption(sub, o->link, "clients join on --port through it");
    sub->add_option("--debrief", o->debrief,
                    "Write a Markdown debrief with SVG plots per participant in this folder when "
                    "the server stops");
    sub->callback([o, &exitCode] { exitCode = runServer(*o); });
}

} // namespace trephine::app

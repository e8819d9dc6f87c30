// `trephine trainee`: join a session. By default a trainee window (apps/mode_window.cpp);
// `--headless` runs a real client with no window, driven by a script (the built-in `burrhole` or a
// CSV trajectory, see docs/scripts.md), and writes statistics as a JSON report. `--sync volume`
// runs the replicated-volume baseline: the client holds the volume and renders its view itself.
#include "link_option.h"
#include "mode_window.h"
#include "modes.h"
#include "scripted_device.h"

#include "libsim/camera.h"
#include "libsim/error.h"
#include "libsim/haptics.h"
#include "libsim/skull.h"
#include "libsim/tool_catalogue.h"
#include "libsim_devices/anchored_device.h"
#include "libsim_devices/device_select.h"
#include "libsim_devices/devices.h"
#include "libsim_devices/spacemouse.h"
#include "libsim_image/dbi_io.h"
#include "net/client_model.h"
#include "net/codec.h"
#include "net/scene.h"
#include "net/scripts.h"
#include "net/trainee_core.h"
#include "net/trainee_session.h"
#include "net/view.h"

#include <glm/gtx/quaternion.hpp>

#include <algorithm>
#include <atomic>
#include <charconv>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <thread>

namespace trephine::app {

namespace {

std::atomic<bool> g_traineeStop{false};

extern "C" void onTraineeStopSignal(int) {
    g_traineeStop = true;
}

struct TraineeOptions {
    std::string connect;
    bool headless = false;
    std::string script = "burrhole";
    std::string camera = "working";
    std::string codec = "lz4";
    std::string sync = "dbi";        // dbi | volume
    std::string volumeCodec = "raw"; // volume box encoding: raw (1 byte/voxel), lz4, zstd
    int size = 500;
    double durationS = 0; // 0: the script's own length
    std::string report;
    std::string saveDbi;
    std::string name = "trainee";
    std::string code;          // the trainee code (docs/security.md); empty: an open session
    double toolRateHz = 100.0; // tool states per second from the haptic loop
    std::string screenshot;    // window: as `trephine instructor --screenshot`
    int frames = 0;            // window: as `trephine instructor --frames` (0: run until closed)
    double timeoutS = 90.0;
    std::string link;     // --link: the emulator between this trainee and --connect
    std::string device;   // --device: "" (the shell's default), spacemouse[...], plugin:PATH.so
    std::string pedalMap; // --pedal-map: the window's
    // The first option given that only a --headless trainee uses ("": none); the window refuses it
    // rather than run without it.
    std::string headlessOnly;
};

using Sample = net::ScriptSample;

// The figures of the session so far, on stdout (the report has them all).
void printFigures(const net::ClientModel& model, const net::TraineeCore& core, bool volume) {
    const net::ClientSnapshot none;
    const net::ClientSnapshot& s = model.session() ? *model.session() : none;
    std::printf("trainee: %llu updates (%llu full), latency p50 %.0f us p99 %.0f us, "
                "%.0f bytes/update (raw %.0f), rtt p50 %.0f us, %llu malformed dropped\n",
                (unsigned long long)s.updatesApplied, (unsigned long long)s.fullUpdates,
                s.latencyP50Us, s.latencyP99Us, s.meanBytes, s.meanRawBytes, s.rttP50Us,
                (unsigned long long)s.malformed);
    for (net::Sync mode : {net::Sync::Dbi, net::Sync::Volume}) {
        const net::ModeFigures& m = s.modes[size_t(mode)];
        if (m.updatesApplied == 0)
            continue;
        std::printf("trainee: %s updates %llu, stage p50 us: erode %.0f, server render %.0f, "
                    "encode %.0f, transmit %.0f, client apply %.0f, client render %.0f\n",
                    mode == net::Sync::Dbi ? "dbi" : "volume", (unsigned long long)m.updatesApplied,
                    m.erodeP50Us, m.serverRenderP50Us, m.encodeP50Us, m.transmitP50Us, m.applyP50Us,
                    m.clientRenderP50Us);
    }
    const HapticLoopStats h = core.hapticStats();
    std::printf("trainee: haptic loop %.0f Hz achieved (lateness p50 %.3f ms p99 %.3f ms), "
                "%llu tool states at %.0f Hz, %llu force models, force round trip p50 %.0f us "
                "p99 %.0f us\n",
                h.achievedRateHz, h.latenessP50Ms, h.latenessP99Ms,
                (unsigned long long)s.toolStatesSent, core.hapticConfig().sendRateHz,
                (unsigned long long)s.hapticModels, s.hapticRoundTripP50Us, s.hapticRoundTripP99Us);
    if (volume)
        std::printf("trainee: forces computed locally on the replicated volume in %llu of %llu "
                    "haptic ticks (the rest: before the volume arrived), with %zu tool%s\n",
                    (unsigned long long)core.localForceTicks(), (unsigned long long)h.ticks,
                    core.localForceTools(), core.localForceTools() == 1 ? "" : "s");
}

net::TraineeSessionConfig sessionConfigFor(const TraineeOptions& o) {
    net::TraineeSessionConfig c;
    c.address = o.connect;
    c.client.name = o.name;
    c.client.code = o.code;
    c.client.codec = net::parseCodec(o.codec);
    c.client.sync = o.sync == "volume" ? net::Sync::Volume : net::Sync::Dbi;
    c.client.volumeCodec = net::parseCodec(o.volumeCodec);
    // A 1x1 placeholder view: the preset comes in the server's scene, after the welcome.
    c.client.view.width = c.client.view.height = 1;
    c.size = o.size;
    c.toolRateHz = o.toolRateHz;
    return c;
}

// --report: the figures of the session as JSON, with what it was asked to do.
void writeReport(const TraineeOptions& o, const net::TraineeSession& session, const Camera& camera,
                 double elapsedS) {
    net::ClientReportExtras x = session.core().reportExtras();
    x.durationS = elapsedS;
    const net::ClientModel& model = session.model();
    const bool volumeAtEnd = model.session() && model.session()->sync == net::Sync::Volume;
    x.session = {{"server", o.connect}, {"name", o.name},
                 {"codec", o.codec},    {"sync", volumeAtEnd ? "volume" : "dbi"},
                 {"view", o.camera},    {"camera", describe(camera)},
                 {"script", o.script}};
    if (!writeReplacing(
            o.report,
            model.report(x).dump(2, ' ', false, nlohmann::json::error_handler_t::replace) + "\n"))
        throw Error("--report " + o.report + ": cannot write it");
}

// [Headless] A trainee session with a script as its tool: join, open the view, drill, lift and
// drain, then the figures, the report and the picture.
int runHeadlessTrainee(const TraineeOptions& o, std::vector<Sample> script,
                       std::unique_ptr<Device> opened) {
    const auto link = net::startLinkEnd(o.link, net::LinkEnd::Client, net::parseAddress(o.connect));
    net::TraineeSessionConfig config = sessionConfigFor(o);
    if (link)
        config.address = net::relayAddress(*link);
    net::TraineeSession session(config);
    const net::Welcome welcome = session.join();
    session.awaitScene();
    const Camera camera = session.openPreset(o.camera);
    if (o.script == "burrhole")
        script = session.burrhole(o.durationS > 0 ? o.durationS : net::kBurrholeSeconds);
    std::printf("trainee: %s as client %u, view %s (%s), sync %s, codec %s, %zu script samples\n",
                o.connect.c_str(), unsigned(welcome.clientId), o.camera.c_str(),
                describe(camera).c_str(), o.sync.c_str(), o.codec.c_str(), script.size());
    std::fflush(stdout); // shown now, not when the script ends, where stdout is a pipe or file
    const double scriptEnd =
        o.durationS > 0 ? std::min(script.back().t, o.durationS) : script.back().t;
    // Ctrl-C (or kill, or a closed terminal) ends the script early; the figures so far are still
    // printed and --report / --save-dbi still written.
    g_traineeStop = false;
    handleStopSignals(onTraineeStopSignal);
    // The core's haptic loop (1 kHz) plays the script, feels the server's force models (or, in
    // the volume design, the local volume) and sends tool states at --tool-rate.
    std::unique_ptr<Device> device = headlessDevice(std::move(opened), script);
    session.play(std::move(script), scriptEnd, std::move(device));
    session.drill([](double) { return !g_traineeStop; });
    session.liftAndDrain();
    if (g_traineeStop)
        session.noteStopped();
    const net::SessionEnd end = session.finish();

    printFigures(session.model(), session.core(), o.sync == "volume");
    if (!o.report.empty())
        writeReport(o, session, camera, end.elapsedS);
    if (!o.saveDbi.empty())
        writeDbiExr(o.saveDbi, session.view().dbi());
    if (end.how == net::SessionEnd::How::ScriptDone)
        return 0;
    std::fprintf(stderr, "%s\n", session.endText(end).c_str());
    return 1;
}

int runTrainee(const TraineeOptions& o) {
    if (!o.headless && !o.headlessOnly.empty())
        throw Error(o.headlessOnly + ": only a --headless trainee uses it; the trainee window has "
                                     "no such option (add --headless, or leave it out)");
    if (!o.headless) { // the window starts in --sync's design; its Comparison toggle switches
        WindowedOptions w;
        w.connect = o.connect;
        w.name = o.name;
        w.code = o.code;
        w.codec = o.codec;
        w.size = o.size;
        w.sizeOption = "--size";
        w.sync = o.sync;
        w.volumeCodec = o.volumeCodec;
        w.screenshot = o.screenshot;
        w.frames = o.frames;
        w.timeoutS = o.timeoutS;
        w.link = o.link;
        w.device = o.device;
        w.pedalMap = o.pedalMap;
        return runWindowedClient(w);
    }
    if (!o.pedalMap.empty())
        throw Error("--pedal-map: the window's; a --headless trainee reads no joystick (GLFW's "
                    "joystick API needs a display)");
    if (!o.screenshot.empty())
        throw Error("--screenshot: the window's; a --headless trainee has none (--save-dbi writes "
                    "its picture)");
    net::parseAddress(o.connect); // a bad address is refused before anything else
    // The outputs are checked first too: a typo found after the session would waste it.
    if (!o.report.empty())
        checkOutputFolder("--report", o.report);
    if (!o.saveDbi.empty()) {
        checkDbiExrPath(o.saveDbi);
        checkOutputFolder("--save-dbi", o.saveDbi);
        // Both are written at the end, the picture last: the report would be lost under it.
        if (!o.report.empty() && samePath(o.report, o.saveDbi))
            throw Error("--report " + o.report +
                        " is where --save-dbi writes the picture: give "
                        "it another name");
    }
    // A CSV script is read first, so a bad file fails before anything connects.
    std::vector<Sample> script;
    if (o.script != "burrhole")
        script = net::csvScript(o.script);
    return runHeadlessTrainee(o, std::move(script), openHeadlessDevice(o.device, "trainee"));
}

// Options only a --headless trainee uses: listed under their own heading, and refused by the
// window (runTrainee) rather than ignored.
const std::string kHeadlessOnly = "Headless only (with --headless)";

void addHeadlessOnlyOptions(CLI::App* sub, TraineeOptions& o) {
    sub->add_option("--script", o.script, "burrhole, or a CSV trajectory (docs/scripts.md)")
        ->capture_default_str()
        ->group(kHeadlessOnly);
    // Checked as the command line is read: an unknown preset was refused only once connected.
    sub->add_option("--camera", o.camera, "View preset, as in `trephine render`")
        ->check(CLI::IsMember(cameraPresetNames()))
        ->capture_default_str()
        ->group(kHeadlessOnly);
    sub->add_option("--duration", o.durationS, "Seconds of script to run (burrhole: its length)")
        ->check(finiteRange(0.0, 3600.0))
        ->group(kHeadlessOnly);
    sub->add_option("--report", o.report, "Write statistics as JSON here")
        ->check(outputFile())
        ->group(kHeadlessOnly);
    sub->add_option("--save-dbi", o.saveDbi, "Write the final DBI as OpenEXR here")
        ->check(outputFile())
        ->group(kHeadlessOnly);
    sub->add_option("--tool-rate", o.toolRateHz,
                    "Tool states per second sent by the haptic loop (20-1000)")
        ->check(finiteRange(20.0, 1000.0))
        ->capture_default_str()
        ->group(kHeadlessOnly);
}

} // namespace

void addTraineeMode(CLI::App& root, int& exitCode) {
    auto o = std::make_shared<TraineeOptions>();
    CLI::App* sub =
        root.add_subcommand("trainee", "Join a session as a trainee (window or headless)");
    sub->add_option("--connect", o->connect, "Server address HOST:PORT")
        ->check(serverAddress())
        ->required();
    sub->add_flag("--headless", o->headless, "No window: run a script and report statistics");
    sub->add_option("--codec", o->codec, "Image codec: raw, lz4 or zstd")
        ->check(CLI::IsMember({"raw", "lz4", "zstd"}))
        ->capture_default_str();
    sub->add_option("--sync", o->sync,
                    "How the picture is kept: dbi (the server renders and sends image "
                    "rectangles) or volume (the baseline: the server sends voxels, the client "
                    "holds the volume and renders locally; a window ray casts it on the GPU and "
                    "switches live with its Comparison toggle)")
        ->check(CLI::IsMember({"dbi", "volume"}))
        ->capture_default_str();
    sub->add_option("--volume-codec", o->volumeCodec,
                    "With --sync volume: voxel boxes raw (1 byte each, as the paper), lz4 or zstd")
        ->check(CLI::IsMember({"raw", "lz4", "zstd"}))
        ->capture_default_str();
    sub->add_option("--size", o->size, "Window size in pixels (square)")
        ->check(CLI::Range(16, 4096))
        ->capture_default_str();
    sub->add_option("--name", o->name, "Name shown to others")
        ->check(participantName())
        ->capture_default_str();
    addCodeOption(sub, o->code, "trainee");
    addLinkOption(sub, o->link, "between this trainee and --connect");
    addDeviceOptions(sub, o->device, o->pedalMap);
    sub->add_option("--screenshot", o->screenshot,
                    "Window: write it to this PNG once the view has settled, then exit")
        ->check(outputFile());
    sub->add_option("--frames", o->frames,
                    "Window: settled frames before the screenshot (without one: frames to run, 0 "
                    "until closed)")
        ->check(CLI::Range(0, 1000000))
        ->capture_default_str();
    sub->add_option("--timeout", o->timeoutS, "Window, with --screenshot: give up after this long")
        ->check(finiteRange(1.0, 3600.0))
        ->capture_default_str();
    addHeadlessOnlyOptions(sub, *o);
    sub->callback([o, sub, &exitCode] {
        for (const CLI::Option* opt : sub->get_options())
            if (o->headlessOnly.empty() && opt->get_group() == kHeadlessOnly && opt->count())
                o->headlessOnly = opt->get_name();
        exitCode = runTrainee(*o);
    });
}

} // namespace trephine::app

// `trephine trainee`: join a session. By default a trainee window (apps/mode_window.cpp);
// `--headless` runs a real client with no window, driven by a script (the built-in `burrhole` or a
// CSV trajectory, see docs/scripts.md), and writes statistics as a JSON report. `--sync volume`
// runs the replicated-volume baseline: the client holds the volume and renders its view itself.
#include "mode_window.h"
#include "modes.h"

#include "libsim/camera.h"
#include "libsim/error.h"
#include "libsim/haptics.h"
#include "libsim/skull.h"
#include "libsim/tool_catalogue.h"
#include "libsim_devices/devices.h"
#include "libsim_image/dbi_io.h"
#include "net/client_model.h"
#include "net/codec.h"
#include "net/scene.h"
#include "net/scripts.h"
#include "net/trainee_core.h"
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

// [Headless] Silence after which the server counts as lost (it answers pings within ms).
constexpr uint64_t kServerSilenceUs = 3000000;

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

// [Headless] The trainee core with a script as its tool: join, open the view, drill, drain, then
// the figures, the report and the picture.
int runHeadlessTrainee(const TraineeOptions& o, std::vector<Sample> script) {
    net::TraineeCoreConfig coreConfig;
    net::ClientConfig& config = coreConfig.client.client;
    config.name = o.name;
    config.code = o.code;
    config.codec = net::parseCodec(o.codec);
    config.sync = o.sync == "volume" ? net::Sync::Volume : net::Sync::Dbi;
    config.volumeCodec = net::parseCodec(o.volumeCodec);
    // A 1x1 placeholder view: the preset comes in the server's scene, after the welcome.
    config.view.width = config.view.height = 1;
    coreConfig.client.address = o.connect;
    coreConfig.client.connectTimeoutS = 10.0;
    coreConfig.client.retryS = 3600.0; // a headless run does not reconnect: a lost link ends it
    coreConfig.haptics.sendRateHz = o.toolRateHz;
    // The script's device and tool source outlive the core, whose haptic loop reads them.
    std::unique_ptr<ScriptedDevice> device;
    std::unique_ptr<net::ScriptToolSource> tools;
    net::TraineeCore core(coreConfig);
    net::ClientThread& client = core.client();
    net::HeadlessView view(o.size);
    core.connect();
    // The client ended the session over a malformed message of the server's: its reason names
    // the server and the message ("HOST sent a malformed scene (...)").
    auto faulted = [&] { return view.snap()->fault.has_value(); };
    if (!view.waitFor(client, 15.0, [&] { return view.connected(); })) {
        const std::string& reason = view.snap()->closeReason;
        if (reason.empty())
            throw Error("trainee: no answer from " + o.connect +
                        " (is `trephine server` running?)");
        if (faulted() || reason.rfind("no answer", 0) == 0)
            throw Error("trainee: " + reason);
        throw Error("trainee: " + o.connect + " refused us: " + reason);
    }
    const net::Welcome welcome = *view.snap()->welcome;
    // The scene follows the welcome on the same reliable channel: presets and the burr site come
    // from the server, so the trainee needs its address only (it never opens a volume).
    if (!view.waitFor(client, 10.0, [&] { return view.snap()->scene != nullptr; })) {
        if (faulted())
            throw Error("trainee: " + view.snap()->closeReason);
        throw Error(
            "trainee: " + o.connect + " sent no scene after its welcome" +
            (view.snap()->closeReason.empty() ? std::string() : ": " + view.snap()->closeReason));
    }
    const std::shared_ptr<const net::ReceivedScene> scene = view.snap()->scene;
    const std::optional<Camera> preset =
        net::presetCamera(scene->scene, o.camera, {o.size, o.size});
    if (!preset)
        throw Error("trainee: the server's scene has no camera preset '" + o.camera + "'");
    const Camera camera = *preset;
    // Refused (larger than the server serves): it would run on and report the 1x1 placeholder as
    // its picture.
    if (int64_t(o.size) * o.size > welcome.maxViewPixels)
        throw Error("trainee: the server serves views of at most " +
                    std::to_string(welcome.maxViewPixels) + " pixels; --size " +
                    std::to_string(o.size) + " asks for " +
                    std::to_string(int64_t(o.size) * o.size) + ": give a smaller --size");
    client.requestView(net::toViewSpec(camera));
    if (!view.waitFor(client, 30.0, [&] { return view.hasPicture(); })) {
        const net::ClientSnapshot& s = *view.snap();
        if (faulted())
            throw Error("trainee: " + s.closeReason);
        if (!s.closeReason.empty())
            throw Error("trainee: no image from " + o.connect + ": " + s.closeReason);
        if (s.malformedImages > 0)
            throw Error("trainee: no image from " + o.connect +
                        ": the server's images were malformed (" +
                        std::to_string(s.malformedImages) + " dropped)");
        throw Error("trainee: no image from " + o.connect + " in 30 s");
    }

    if (o.script == "burrhole") {
        const net::SceneSite* site = net::findSite(scene->scene, net::kDefaultSiteName);
        if (!site)
            throw Error("trainee: the server's scene has no burr site for the burrhole script");
        script = net::burrholeScript({site->position, site->normal},
                                     o.durationS > 0 ? o.durationS : net::kBurrholeSeconds);
    }
    std::printf("trainee: %s as client %u, view %s (%s), sync %s, codec %s, %zu script samples\n",
                o.connect.c_str(), unsigned(welcome.clientId), o.camera.c_str(),
                describe(camera).c_str(), o.sync.c_str(), o.codec.c_str(), script.size());
    std::fflush(stdout); // shown now, not when the script ends, where stdout is a pipe or file
    // The core's haptic loop (its own thread, 1 kHz) reads a device that follows the script's
    // poses, feels the server's force models (or, in the volume design, the local volume) and
    // sends tool states at --tool-rate through the client thread.
    std::vector<Waypoint> waypoints;
    for (const Sample& s : script)
        waypoints.push_back({s.t, ToolPose{s.tool.position, s.tool.orientation}, 0});
    device = std::make_unique<ScriptedDevice>(std::move(waypoints));
    double scriptEnd = script.back().t;
    if (o.durationS > 0)
        scriptEnd = std::min(scriptEnd, o.durationS);
    tools = std::make_unique<net::ScriptToolSource>(*device, script, scriptEnd);
    // Ctrl-C (or kill, or a closed terminal) ends the script early; the figures so far are still
    // printed and --report / --save-dbi still written.
    g_traineeStop = false;
    handleStopSignals(onTraineeStopSignal);
    core.startHaptics(*tools);
    const uint64_t start = net::steadyNowUs();
    const uint64_t end = start + uint64_t(scriptEnd * 1e6);
    // A server killed, crashed or cut off sends no goodbye, and ENet gives up on it only after 5
    // to 30 s: past a short script. The client thread's pings are answered within milliseconds,
    // so seconds of silence mean it is gone. Counted from the script's start at the earliest.
    auto serverLost = [&] {
        return view.connected() &&
               net::steadyNowUs() - std::max(view.snap()->lastHeardUs, start) > kServerSilenceUs;
    };
    auto closed = [&] { return !view.connected(); };
    while (net::steadyNowUs() < end && !closed() && !serverLost() && !g_traineeStop) {
        view.take(client, core.hapticStats().ticks);
        std::this_thread::sleep_for(std::chrono::milliseconds(2));
    }
    core.stopHaptics();
    if (!closed() && !serverLost()) {
        net::ToolState last = script.back().tool; // lift: drilling off
        last.speed = 0.0f;
        last.drilling = false;
        client.sendToolState(last);
    }
    // Let the last updates arrive: stop after 0.5 s without one, and 2 s after the script at the
    // latest (others drilling on kept it waiting for as long as they drilled).
    const uint64_t drainUntil = net::steadyNowUs() + 2000000;
    uint64_t lastCount = view.snap()->updatesApplied, quietSince = net::steadyNowUs();
    while (!closed() && !serverLost() && net::steadyNowUs() - quietSince < 500000 &&
           net::steadyNowUs() < drainUntil) {
        std::this_thread::sleep_for(std::chrono::milliseconds(5));
        view.take(client, core.hapticStats().ticks);
        if (view.snap()->updatesApplied != lastCount) {
            lastCount = view.snap()->updatesApplied;
            quietSince = net::steadyNowUs();
        }
    }
    const double elapsed = double(net::steadyNowUs() - start) * 1e-6;
    const bool refused = closed();
    const bool lost = serverLost();
    const bool interrupted = g_traineeStop;
    const std::string reason = view.snap()->closeReason;
    core.stop();

    printFigures(view.model, core, config.sync == net::Sync::Volume);
    if (!o.report.empty()) {
        net::ClientReportExtras x = core.reportExtras();
        x.durationS = elapsed;
        const bool volumeAtEnd =
            view.model.session() && view.model.session()->sync == net::Sync::Volume;
        x.session = {{"server", o.connect}, {"name", o.name},
                     {"codec", o.codec},    {"sync", volumeAtEnd ? "volume" : "dbi"},
                     {"view", o.camera},    {"camera", describe(camera)},
                     {"script", o.script}};
        if (!writeReplacing(o.report, view.model.report(x).dump(
                                          2, ' ', false, nlohmann::json::error_handler_t::replace) +
                                          "\n"))
            throw Error("--report " + o.report + ": cannot write it");
    }
    if (!o.saveDbi.empty())
        writeDbiExr(o.saveDbi, view.dbi());
    if (refused) {
        std::fprintf(stderr, "trainee: the server closed the session: %s\n", reason.c_str());
        return 1;
    }
    if (lost) {
        std::fprintf(stderr,
                     "trainee: lost the server %s: nothing heard for %.0f s (killed, "
                     "crashed or cut off), %.1f s into the script\n",
                     o.connect.c_str(), double(kServerSilenceUs) * 1e-6, elapsed);
        return 1;
    }
    if (interrupted) {
        std::fprintf(stderr, "trainee: stopped by a signal %.1f s into the script\n", elapsed);
        return 1;
    }
    return 0;
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
        return runWindowedClient(w);
    }
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
    return runHeadlessTrainee(o, std::move(script));
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
    // Options only a --headless trainee uses: listed under their own heading, and refused by the
    // window (runTrainee) rather than ignored.
    static const std::string kHeadlessOnly = "Headless only (with --headless)";
    sub->add_option("--script", o->script, "burrhole, or a CSV trajectory (docs/scripts.md)")
        ->capture_default_str()
        ->group(kHeadlessOnly);
    // Checked as the command line is read: an unknown preset was refused only once connected.
    sub->add_option("--camera", o->camera, "View preset, as in `trephine render`")
        ->check(CLI::IsMember(cameraPresetNames()))
        ->capture_default_str()
        ->group(kHeadlessOnly);
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
    sub->add_option("--duration", o->durationS, "Seconds of script to run (burrhole: its length)")
        ->check(finiteRange(0.0, 3600.0))
        ->group(kHeadlessOnly);
    sub->add_option("--report", o->report, "Write statistics as JSON here")
        ->check(outputFile())
        ->group(kHeadlessOnly);
    sub->add_option("--save-dbi", o->saveDbi, "Write the final DBI as OpenEXR here")
        ->check(outputFile())
        ->group(kHeadlessOnly);
    sub->add_option("--name", o->name, "Name shown to others")
        ->check(participantName())
        ->capture_default_str();
    addCodeOption(sub, o->code, "trainee");
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
    sub->add_option("--tool-rate", o->toolRateHz,
                    "Tool states per second sent by the haptic loop (20-1000)")
        ->check(finiteRange(20.0, 1000.0))
        ->capture_default_str()
        ->group(kHeadlessOnly);
    sub->callback([o, sub, &exitCode] {
        for (const CLI::Option* opt : sub->get_options())
            if (o->headlessOnly.empty() && opt->get_group() == kHeadlessOnly && opt->count())
                o->headlessOnly = opt->get_name();
        exitCode = runTrainee(*o);
    });
}

} // namespace trephine::app

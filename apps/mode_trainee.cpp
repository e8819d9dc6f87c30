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

// The built-in burr hole: a 5 mm burr starts 1 mm above the server's burr site (its scene's) and
// feeds in along the normal at 1 mm/s, tool states at 100 Hz, then lifts (drilling off).
std::vector<Sample> burrholeScript(const net::SceneSite& site, double durationS) {
    std::vector<Sample> out;
    int n = int(durationS * 100.0);
    for (int i = 0; i <= n; ++i) {
        Sample s;
        s.t = i / 100.0;
        s.tool.toolKind = uint8_t(ToolKind::Burr);
        s.tool.diameterMm = 5.0f;
        float depth = -1.0f + float(s.t);
        s.tool.position = site.position - site.normal * depth;
        s.tool.orientation = glm::rotation(glm::vec3(0, 0, 1), site.normal);
        s.tool.speed = i < n ? 1.0f : 0.0f;
        s.tool.drilling = i < n;
        out.push_back(s);
    }
    return out;
}

// A whole cell as a decimal number (spaces around it allowed): stod read "0x10" as hex 16 and
// "5mm" or "1.5.2" as their leading number, so a mistyped cell drilled somewhere else.
bool parseNumberCell(const std::string& cell, double& v) {
    const char* p = cell.data();
    const char* end = p + cell.size();
    while (p < end && std::isspace(uint8_t(*p)))
        ++p;
    while (end > p && std::isspace(uint8_t(end[-1])))
        --end;
    if (p < end && *p == '+')
        ++p;
    auto [ptr, ec] = std::from_chars(p, end, v);
    return p < end && ec == std::errc() && ptr == end;
}

// time_s,x,y,z,qw,qx,qy,qz,speed,tool with tool `burr:D` or `perforator[:D]`; '#' comments and
// a header line are skipped.
std::vector<Sample> csvScript(const std::string& path) {
    std::error_code ec;
    if (std::filesystem::is_directory(path, ec))
        throw Error("script " + path + ": a folder, not a CSV file (use `burrhole` or a CSV file)");
    std::ifstream in(path);
    if (!in)
        throw Error("script " + path + ": cannot open it (use `burrhole` or a CSV file)");
    std::vector<Sample> out;
    std::string line;
    int lineNo = 0;
    auto fail = [&](const std::string& what) {
        return Error("script " + path + " line " + std::to_string(lineNo) + ": " + what);
    };
    // Lines of at most kMaxLine characters: std::getline on a file with no newline (/dev/zero, a
    // binary file) grew one line until memory ran out.
    constexpr size_t kMaxLine = 4096;
    auto readLine = [&] {
        ++lineNo;
        line.clear();
        for (int c; (c = in.get()) != std::char_traits<char>::eof();) {
            if (c == '\n')
                return true;
            if (line.size() == kMaxLine)
                throw fail("longer than " + std::to_string(kMaxLine) +
                           " characters: not a CSV trajectory");
            line += char(c);
        }
        return !line.empty();
    };
    while (readLine()) {
        if (!line.empty() && line.back() == '\r')
            line.pop_back();
        // A UTF-8 byte order mark (spreadsheets write one) is no part of the first cell: kept, it
        // made a first sample unreadable, skipped as a header and lost.
        if (lineNo == 1 && line.rfind("\xEF\xBB\xBF", 0) == 0)
            line.erase(0, 3);
        // Line 1 is a header when its first cell is not a number (" 5.0" and "+5.0" are numbers:
        // judged by the first character, they were skipped as a header and the sample lost).
        double firstCell = 0.0;
        if (line.empty() || line[0] == '#' ||
            (lineNo == 1 && !parseNumberCell(line.substr(0, line.find(',')), firstCell)))
            continue;
        // Every cell, an empty last one too: "...,burr:5," has 11 columns, not 10.
        std::vector<std::string> cells;
        for (size_t at = 0;;) {
            const size_t comma = line.find(',', at);
            cells.push_back(line.substr(at, comma - at));
            if (comma == std::string::npos)
                break;
            at = comma + 1;
        }
        if (cells.size() != 10)
            throw fail("expected 10 columns time_s,x,y,z,qw,qx,qy,qz,speed,tool, found " +
                       std::to_string(cells.size()));
        double v[9];
        for (int i = 0; i < 9; ++i)
            if (!parseNumberCell(cells[size_t(i)], v[i]))
                throw fail("column " + std::to_string(i + 1) + " is not a number");
        // A number takes nan and inf, and a double beyond a float's range becomes inf as one: a NaN
        // time never ended the run, a huge one overflowed the end time.
        for (int i = 0; i < 9; ++i)
            if (!std::isfinite(float(v[i])))
                throw fail("column " + std::to_string(i + 1) + " is not a finite number");
        if (!(v[0] >= 0.0 && v[0] <= 86400.0))
            throw fail("time must be from 0 to 86400 s");
        if (!(std::abs(v[1]) <= net::kMaxToolDistanceMm &&
              std::abs(v[2]) <= net::kMaxToolDistanceMm &&
              std::abs(v[3]) <= net::kMaxToolDistanceMm))
            throw fail("position beyond 100 m of the volume's centre");
        const glm::quat q = glm::quat(float(v[4]), float(v[5]), float(v[6]), float(v[7]));
        if (!(glm::dot(q, q) > 1e-6f))
            throw fail("the orientation quaternion is zero");
        Sample s;
        s.t = v[0];
        s.tool.position = {float(v[1]), float(v[2]), float(v[3])};
        s.tool.orientation = glm::normalize(q);
        if (!(v[8] >= 0.0 && v[8] <= 1.0))
            throw fail("speed must be in [0, 1]");
        s.tool.speed = float(v[8]);
        s.tool.drilling = v[8] > 0.0;
        std::string tool = cells[9];
        while (!tool.empty() && std::isspace(uint8_t(tool.back())))
            tool.pop_back();
        ToolShape shape;
        auto diameter = [&](size_t from) {
            double d = 0.0;
            if (!parseNumberCell(tool.substr(from), d))
                throw fail("tool diameter in '" + tool + "' is not a number");
            return float(d);
        };
        try {
            // NAME:D, or NAME alone for the tool's usual size (ToolType::name).
            const size_t colon = tool.find(':');
            const std::optional<ToolKind> kind = toolKindNamed(tool.substr(0, colon));
            if (!kind)
                throw fail("tool must be NAME:D or NAME (burr, perforator, diamond), not '" + tool +
                           "'");
            shape =
                ToolShape::of(*kind, colon == std::string::npos ? toolType(*kind).defaultDiameterMm
                                                                : diameter(colon + 1));
        } catch (const Error& e) {
            if (std::string(e.what()).rfind("script ", 0) == 0)
                throw;
            throw fail(e.what()); // the tool's own complaint, with the file and line
        }
        s.tool.toolKind = uint8_t(shape.kind);
        s.tool.diameterMm = shape.diameterMm;
        if (!out.empty() && s.t < out.back().t)
            throw fail("times must not decrease");
        out.push_back(s);
    }
    if (out.empty())
        throw Error("script " + path + ": no samples");
    return out;
}

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
        script = burrholeScript(*site, o.durationS > 0 ? o.durationS : 4.0);
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
        script = csvScript(o.script);
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

// `trephine demo`: the README's main job. With a display: an embedded session server on the
// procedural skull plus a trainee window connected over loopback, drilled with the mouse or a
// script. Without one (or with --headless): the same embedded server and the headless trainee
// core over loopback drill a burr hole with the cranial perforator at the default site; it prints
// the session's figures and writes the trainee's final picture as a PNG.
#include "modes.h"

#include "mode_window.h"
#include "net/scripts.h"
#include "net/secure_channel.h"
#include "net/session_server.h"

#include "libsim/camera.h"
#include "libsim/drill.h"
#include "libsim/error.h"
#include "libsim/haptics.h"
#include "libsim/skull.h"
#include "libsim/tool_catalogue.h"
#include "libsim_devices/devices.h"
#include "libsim_image/dbi_io.h"
#include "libsim_image/volume_slices.h"
#include "net/trainee_core.h"
#include "net/view.h"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <glm/gtx/quaternion.hpp>
#include <memory>
#include <thread>

namespace trephine::app {

namespace {

struct DemoOptions {
    std::string volume = "skull:128";
    float feedMmPerS = 1.0f;
    float maxSeconds = 30.0f;
    bool headless = false;
    // Headless: the final picture (by default in the temporary folder, not wherever the demo
    // was started: scripts/demo runs in the repository).
    std::string picture = (std::filesystem::temp_directory_path() / "trephine-demo.png").string();
    int pictureSize = 400;
    WindowedOptions window;
};

// Voxel counts per material of voxels that were bone before and are air now.
std::vector<int64_t> removedByMaterial(const Volume& before, const Volume& after) {
    std::vector<int64_t> removed(kMaterialCount, 0);
    const uint8_t* mb = before.materialData();
    const uint8_t* ma = after.materialData();
    for (size_t i = 0; i < before.voxelCount(); ++i)
        if (mb[i] != ma[i] && ma[i] == uint8_t(Material::Air) && mb[i] < kMaterialCount)
            removed[mb[i]]++;
    return removed;
}

// What the trainee saw while drilling: the clutch (cutting stopped while the feed went on) and
// the forces it felt.
struct DemoRun {
    double clutchDepth = -1; // mm below the surface where cutting stopped (-1: it never did)
    double lastDepth = -1;
    float peakForceN = 0, peakModelN = 0;
};

// The perforator at `pose` is through the inner table when its clutch rule finds dura or brain
// within its margin on the server's volume now (a copy: the check cuts nothing of the session's).
bool throughInnerTable(net::SessionServer& server, const ToolPose& pose) {
    Volume v = server.volumeSnapshot();
    Driller probe(ToolShape::perforator());
    return probe.drill(v, pose, 1.0f, 1e-3f).clutchDisengaged;
}

DemoRun drillOverLoopback(net::TraineeCore& core, net::HeadlessView& view,
                          net::SessionServer& server, const SurfaceSite& site,
                          const DemoOptions& o) {
    using Clock = std::chrono::steady_clock;
    DemoRun run;
    const auto start = Clock::now();
    double nextReport = 0, lastCutAt = -1, nextForces = 0, nextProbe = 0;
    uint64_t cuts = 0;
    for (;;) {
        const double t = std::chrono::duration<double>(Clock::now() - start).count();
        const HapticLoopStats h = core.hapticStats();
        view.take(core.client(), h.ticks);
        const net::ClientSnapshot& s = *view.snap();
        run.lastDepth = -1.0 + o.feedMmPerS * t;
        if (s.hapticModel)
            run.peakModelN = std::max(run.peakModelN, glm::length(s.hapticModel->force));
        if (t >= nextForces) { // the recorder holds the last 4 s of ticks
            for (const HapticSample& x : core.hapticSamples())
                run.peakForceN = std::max(run.peakForceN, x.forceN);
            nextForces = t + 1.0;
        }
        const uint64_t incremental = s.updatesApplied - s.fullUpdates;
        if (incremental != cuts) {
            cuts = incremental;
            lastCutAt = t;
        }
        if (t >= nextReport) {
            std::printf("  t %5.1f s  tip %5.1f mm below the surface  %llu updates  |F| %.2f N\n",
                        t, run.lastDepth, (unsigned long long)cuts,
                        s.hapticModel ? glm::length(s.hapticModel->force) : 0.0f);
            std::fflush(stdout);
            nextReport += 2.0;
        }
        // The server's drill stops cutting when the perforator's clutch disengages: after half a
        // second without an update while fed into the bone, the clutch rule is asked on the
        // server's volume (a pause without breakthrough drills on).
        if (lastCutAt >= 0 && run.lastDepth > 0 && t - lastCutAt > 0.5 && t >= nextProbe) {
            const ToolPose pose{site.position - site.normal * float(run.lastDepth),
                                glm::rotation(glm::vec3(0, 0, 1), site.normal)};
            if (throughInnerTable(server, pose)) {
                run.clutchDepth = -1.0 + o.feedMmPerS * lastCutAt;
                break;
            }
            nextProbe = t + 0.5;
        }
        if (t >= o.maxSeconds || !view.connected())
            break;
        std::this_thread::sleep_for(std::chrono::milliseconds(2));
    }
    return run;
}

void printSession(const net::HeadlessView& view, const net::TraineeCore& core) {
    const net::ClientSnapshot none;
    const net::ClientSnapshot& s = view.model.session() ? *view.model.session() : none;
    const HapticLoopStats h = core.hapticStats();
    const net::ClientModel& m = view.model;
    std::printf(
        "updates  %llu image updates (%llu full), latency p50 %.0f us p99 %.0f us, "
        "%.0f bytes each (raw %.0f, %.1fx), round trip p50 %.0f us\n",
        (unsigned long long)s.updatesApplied, (unsigned long long)s.fullUpdates, s.latencyP50Us,
        s.latencyP99Us, s.meanBytes, s.meanRawBytes,
        m.updateBytes.totalSum() > 0 ? m.updateRawBytes.totalSum() / m.updateBytes.totalSum() : 1.0,
        s.rttP50Us);
    const auto& image = s.rateHistory;
    double inBytes = 0;
    for (const auto& second : image)
        inBytes += second[size_t(net::Channel::Image)].bytesInPerS;
    std::printf(
        "bytes    %.1f KB/s of image updates on average over %zu s; %llu tool states sent\n",
        image.empty() ? 0.0 : inBytes / double(image.size()) * 1e-3, image.size(),
        (unsigned long long)s.toolStatesSent);
    std::printf("haptics  %.0f Hz achieved (lateness p99 %.2f ms), %llu force models, force round "
                "trip p50 %.0f us p99 %.0f us\n",
                h.achievedRateHz, h.latenessP99Ms, (unsigned long long)s.hapticModels,
                s.hapticRoundTripP50Us, s.hapticRoundTripP99Us);
}

// The embedded server: on a free port, with codes of its own that it hands its trainee, so the
// demo's session is sealed like any other.
net::ServerConfig demoServerConfig(const std::string& volume) {
    net::ServerConfig config;
    config.port = 0;
    config.volumeName = volume;
    config.traineeCode = net::generateCode();
    do
        config.instructorCode = net::generateCode();
    while (config.instructorCode == config.traineeCode);
    return config;
}

int runHeadlessDemo(const DemoOptions& o) {
    std::printf("Trephine demo: an embedded server and a headless trainee over loopback: a burr "
                "hole with the cranial perforator\n");
    Volume skull = openVolume(o.volume);
    const Volume original = skull;
    const glm::vec3 spacing = skull.spacing();
    std::printf("volume   %s: %d x %d x %d voxels, %.3g mm spacing\n", o.volume.c_str(),
                skull.dims().x, skull.dims().y, skull.dims().z, spacing.x);
    const SurfaceSite site = defaultBurrSite(skull);
    std::printf("site     (%.1f, %.1f, %.1f) mm, normal (%.2f, %.2f, %.2f)\n", site.position.x,
                site.position.y, site.position.z, site.normal.x, site.normal.y, site.normal.z);
    const int size = o.pictureSize;
    const Camera camera =
        cameraLookingAt(site.position, site.normal, 120.0f, 45.0f, {size, size}, original);

    // The server owns the only volume; the trainee holds the DBI of its view and feels the
    // server's force models, as a remote one would.
    net::ServerConfig config = demoServerConfig(o.volume);
    net::SessionServer server(std::move(skull), config);
    server.start();
    net::TraineeCoreConfig cc;
    cc.client.address = "127.0.0.1:" + std::to_string(server.port());
    cc.client.client.name = "demo";
    cc.client.client.code = config.traineeCode;
    cc.client.client.view = net::toViewSpec(camera);
    cc.client.retryS = 3600.0; // one connection: a lost link ends the demo
    // The script's device and tool source outlive the core, whose haptic loop reads them.
    std::unique_ptr<ScriptedDevice> device;
    std::unique_ptr<net::ScriptToolSource> tools;
    net::TraineeCore core(cc);
    net::HeadlessView view(size);
    core.connect();
    if (!view.waitFor(core.client(), 30.0, [&] { return view.hasPicture(); }))
        throw Error("demo: no picture from the embedded server: " + view.snap()->closeReason);
    double firstBytes = 0; // the full image of the view, as it came over the wire
    for (const net::NetworkHistory::Update& u : view.model.network.updates)
        firstBytes += u.full ? u.bytes : 0;
    std::printf("session  server on %s; trainee joined as client %u, its %dx%d DBI in %.0f KB\n",
                cc.client.address.c_str(), unsigned(view.snap()->welcome->clientId), size, size,
                firstBytes * 1e-3);

    std::vector<Waypoint> waypoints;
    const std::vector<net::ScriptSample> script = net::feedScript(site, o.feedMmPerS, o.maxSeconds);
    for (const net::ScriptSample& s : script)
        waypoints.push_back({s.t, ToolPose{s.tool.position, s.tool.orientation}, 0});
    device = std::make_unique<ScriptedDevice>(std::move(waypoints));
    tools = std::make_unique<net::ScriptToolSource>(*device, script, o.maxSeconds);
    core.startHaptics(*tools);
    const DemoRun run = drillOverLoopback(core, view, server, site, o);
    core.stopHaptics();
    net::ToolState lift = script.back().tool;
    lift.speed = 0.0f;
    lift.drilling = false;
    core.client().sendToolState(lift);
    // The last updates: until 0.3 s pass without one (2 s at most).
    for (auto until = std::chrono::steady_clock::now() + std::chrono::seconds(2),
              quiet = std::chrono::steady_clock::now() + std::chrono::milliseconds(300);
         std::chrono::steady_clock::now() < std::min(until, quiet);) {
        const uint64_t before = view.snap()->updatesApplied;
        std::this_thread::sleep_for(std::chrono::milliseconds(5));
        view.take(core.client(), core.hapticStats().ticks);
        if (view.snap()->updatesApplied != before)
            quiet = std::chrono::steady_clock::now() + std::chrono::milliseconds(300);
    }
    core.stop();
    server.stop();

    std::printf("result   ");
    if (run.clutchDepth >= 0)
        std::printf("the drill stopped cutting at %.1f mm while still fed: the perforator's clutch "
                    "disengaged, the inner table breached, dura intact\n",
                    run.clutchDepth);
    else
        std::printf("stopped after %.1f s at %.1f mm without breaking through\n", o.maxSeconds,
                    run.lastDepth);
    const auto removed = removedByMaterial(original, server.volumeSnapshot());
    const double voxelMm3 = double(spacing.x) * spacing.y * spacing.z;
    std::printf("removed  ");
    for (int m = 1; m < kMaterialCount; ++m)
        if (removed[size_t(m)] > 0)
            std::printf("%s %lld voxels (%.0f mm3)  ",
                        std::string(materialName(Material(m))).c_str(),
                        (long long)removed[size_t(m)], double(removed[size_t(m)]) * voxelMm3);
    std::printf("\n");
    printSession(view, core);
    std::printf("forces   peak |F| felt %.2f N, peak server model %.2f N\n", run.peakForceN,
                run.peakModelN);
    if (!o.picture.empty()) {
        writeColorPng(o.picture, view.dbi());
        std::printf("picture  %s (%dx%d, the trainee's DBI at the end)\n", o.picture.c_str(),
                    view.dbi().width(), view.dbi().height());
    }
    // A failure is said on stderr too, where scripts look (stdout has the whole summary).
    if (run.clutchDepth < 0)
        std::fprintf(stderr, "trephine: demo: the perforator did not break through in %.1f s\n",
                     o.maxSeconds);
    return run.clutchDepth >= 0 ? 0 : 1;
}

int runDemo(DemoOptions& o) {
    std::string why;
    // A screenshot needs the window: the headless demo would exit 0 without writing it.
    if (!o.window.screenshot.empty() && o.headless)
        throw Error("--screenshot: the window's; the --headless demo has none (leave one out)");
    if (!o.window.screenshot.empty() && !windowAvailable(&why))
        throw Error("--screenshot: no window to take it from: " + why + " (run under xvfb-run -a)");
    if (!o.headless && !windowAvailable(&why)) {
        std::printf("demo: no window (%s); running the headless demo\n", why.c_str());
        o.headless = true;
    }
    if (o.headless) {
        if (!o.picture.empty()) { // checked before the session: a typo found after would waste it
            checkColorPngPath(o.picture);
            checkOutputFolder("--picture", o.picture);
        }
        return runHeadlessDemo(o);
    }
    // The embedded server on a free loopback port, then the trainee window.
    net::ServerConfig config = demoServerConfig(o.volume);
    net::SessionServer server(openVolume(o.volume), config);
    server.start();
    o.window.connect = "127.0.0.1:" + std::to_string(server.port());
    o.window.code = config.traineeCode;
    std::printf("demo: server on %s (%s), trainee window connected; an instructor joins with "
                "--code %s\n",
                o.window.connect.c_str(), o.volume.c_str(), config.instructorCode.c_str());
    std::fflush(stdout); // read while the window runs, where stdout is a pipe or file
    int rc = runWindowedClient(o.window);
    server.stop();
    return rc;
}

} // namespace

void addDemoMode(CLI::App& root, int& exitCode) {
    auto o = std::make_shared<DemoOptions>();
    CLI::App* sub = root.add_subcommand(
        "demo", "An embedded server on the procedural skull and a trainee window (without a "
                "display: a headless trainee drills a burr hole over loopback and prints the "
                "session's figures)");
    sub->add_flag("--headless", o->headless,
                  "No window: a headless trainee drills; print the figures, write --picture");
    sub->add_option("--picture", o->picture,
                    "Headless: the trainee's final picture as PNG here (\"\": none)")
        ->capture_default_str();
    sub->add_option("--script", o->window.script,
                    "Windowed: `burrhole` drills a scripted hole (default: the mouse drills)")
        ->check(CLI::IsMember({"", "burrhole"}));
    addWindowOptions(sub, o->window);
    sub->add_option("--volume", o->volume, "Volume spec (see `trephine volume --help`)")
        ->capture_default_str();
    sub->add_option("--feed", o->feedMmPerS, "Perforator feed rate, mm/s")
        ->check(finiteRange(0.05, 20.0))
        ->capture_default_str();
    sub->add_option("--max-seconds", o->maxSeconds, "Headless: drilling time limit, s")
        ->check(finiteRange(0.1, 600.0))
        ->capture_default_str();
    sub->callback([o, &exitCode] { exitCode = runDemo(*o); });
}

} // namespace trephine::app

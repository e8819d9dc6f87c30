// `trephine demo`: the README's main job. With a display: an embedded session server on the
// procedural skull plus a trainee window connected over loopback, drilled with the mouse or a
// script. Without one (or with --headless): the same embedded server and the headless trainee
// core over loopback drill a burr hole with the cranial perforator at the default site; it prints
// the session's figures and writes the trainee's final picture as a PNG.
#include "modes.h"

#include "mode_window.h"
#include "net/link_emulator.h"
#include "net/scripts.h"
#include "net/secure_channel.h"
#include "net/session_server.h"
#include "scripted_device.h"

#include "libsim/camera.h"
#include "libsim/drill.h"
#include "libsim/error.h"
#include "libsim/haptics.h"
#include "libsim/hole.h"
#include "libsim/skull.h"
#include "libsim/tool_catalogue.h"
#include "libsim_devices/devices.h"
#include "libsim_image/dbi_io.h"
#include "libsim_image/volume_slices.h"
#include "net/trainee_session.h"
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

// The session's drill with the demo's watch on it: a line every 2 s, the peak forces, and the
// clutch asked about when the cutting stops.
DemoRun drillOverLoopback(net::TraineeSession& session, net::SessionServer& server,
                          const SurfaceSite& site, const DemoOptions& o) {
    DemoRun run;
    double nextReport = 0, lastCutAt = -1, nextForces = 0, nextProbe = 0;
    uint64_t cuts = 0;
    session.drill([&](double t) {
        const net::ClientSnapshot& s = session.snap();
        run.lastDepth = -1.0 + o.feedMmPerS * t;
        if (s.hapticModel)
            run.peakModelN = std::max(run.peakModelN, glm::length(s.hapticModel->force));
        if (t >= nextForces) { // the recorder holds the last 4 s of ticks
            for (const HapticSample& x : session.core().hapticSamples())
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
                return false;
            }
            nextProbe = t + 0.5;
        }
        return true;
    });
    return run;
}

void printSession(const net::TraineeSession& session) {
    const net::ClientModel& m = session.model();
    const net::ClientSnapshot none;
    const net::ClientSnapshot& s = m.session() ? *m.session() : none;
    const HapticLoopStats h = session.core().hapticStats();
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
        inBytes += net::imageBytesInPerS(second);
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

// The demo's trainee: the embedded server's address and trainee code, and the view of `camera`
// in its hello (the demo knows the volume, so it needs no preset from the scene).
net::TraineeSessionConfig demoSessionConfig(uint16_t port, const net::ServerConfig& server,
                                            const Camera& camera) {
    net::TraineeSessionConfig c;
    c.address = "127.0.0.1:" + std::to_string(port);
    c.client.name = "demo";
    c.client.code = server.traineeCode;
    c.client.view = net::toViewSpec(camera);
    c.size = camera.width;
    c.who = "demo";
    return c;
}

// Joins and waits for the whole picture of the hello's view; says so, with its size on the wire.
void joinDemo(net::TraineeSession& session) {
    session.connect();
    if (!session.waitFor(30.0, [&] { return session.view().hasPicture(); }))
        throw Error("demo: no picture from the embedded server: " + session.snap().closeReason);
    double firstBytes = 0; // the full image of the view, as it came over the wire
    for (const net::NetworkHistory::Update& u : session.model().network.updates)
        firstBytes += u.full ? u.bytes : 0;
    const int size = session.config().size;
    std::printf("session  server on %s; trainee joined as client %u, its %dx%d DBI in %.0f KB\n",
                session.config().address.c_str(), unsigned(session.snap().welcome->clientId), size,
                size, firstBytes * 1e-3);
}

// Whether the clutch stopped the drill, and the voxels of each material it removed.
void printResult(const DemoRun& run, const DemoOptions& o, const Volume& before,
                 const Volume& after) {
    std::printf("result   ");
    if (run.clutchDepth >= 0)
        std::printf("the drill stopped cutting at %.1f mm while still fed: the perforator's clutch "
                    "disengaged, the inner table breached, dura intact\n",
                    run.clutchDepth);
    else
        std::printf("stopped after %.1f s at %.1f mm without breaking through\n", o.maxSeconds,
                    run.lastDepth);
    const auto removed = removedByMaterial(before, after);
    const glm::vec3 spacing = before.spacing();
    const double voxelMm3 = double(spacing.x) * spacing.y * spacing.z;
    std::printf("removed  ");
    for (int m = 1; m < kMaterialCount; ++m)
        if (removed[size_t(m)] > 0)
            std::printf("%s %lld voxels (%.0f mm3)  ",
                        std::string(materialName(Material(m))).c_str(),
                        (long long)removed[size_t(m)], double(removed[size_t(m)]) * voxelMm3);
    std::printf("\n");
}

int runHeadlessDemo(const DemoOptions& o) {
    std::printf("Trephine demo: an embedded server and a headless trainee over loopback: a burr "
                "hole with the cranial perforator\n");
    std::unique_ptr<Device> opened = openHeadlessDevice(o.window.device, "demo");
    Volume skull = openVolume(o.volume);
    const Volume original = skull;
    std::printf("volume   %s: %d x %d x %d voxels, %.3g mm spacing\n", o.volume.c_str(),
                skull.dims().x, skull.dims().y, skull.dims().z, skull.spacing().x);
    const SurfaceSite site = defaultBurrSite(skull);
    std::printf("site     (%.1f, %.1f, %.1f) mm, normal (%.2f, %.2f, %.2f)\n", site.position.x,
                site.position.y, site.position.z, site.normal.x, site.normal.y, site.normal.z);
    const Camera camera = cameraLookingAt(site.position, site.normal, 120.0f, 45.0f,
                                          {o.pictureSize, o.pictureSize}, original);
    // The server owns the only volume; the trainee holds the DBI of its view and feels the
    // server's force models, as a remote one would.
    const net::ServerConfig config = demoServerConfig(o.volume);
    net::SessionServer server(std::move(skull), config);
    server.start();
    // --link: the trainee reaches the embedded server through the emulator, as across a network.
    const auto link =
        net::startLinkEnd(o.window.link, net::LinkEnd::Client,
                          net::parseAddress("127.0.0.1:" + std::to_string(server.port())));
    net::TraineeSessionConfig sessionConfig = demoSessionConfig(server.port(), config, camera);
    if (link)
        sessionConfig.address = net::relayAddress(*link);
    net::TraineeSession session(sessionConfig);
    joinDemo(session);
    std::vector<net::ScriptSample> script = net::feedScript(site, o.feedMmPerS, o.maxSeconds);
    std::unique_ptr<Device> device = headlessDevice(std::move(opened), script);
    session.play(std::move(script), o.maxSeconds, std::move(device));
    const DemoRun run = drillOverLoopback(session, server, site, o);
    session.liftAndDrain(0.3);
    session.finish();
    server.stop();

    printResult(run, o, original, server.volumeSnapshot());
    printSession(session);
    std::printf("forces   peak |F| felt %.2f N, peak server model %.2f N\n", run.peakForceN,
                run.peakModelN);
    if (!o.picture.empty()) {
        const Dbi& picture = session.view().dbi();
        writeColorPng(o.picture, picture);
        std::printf("picture  %s (%dx%d, the trainee's DBI at the end)\n", o.picture.c_str(),
                    picture.width(), picture.height());
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

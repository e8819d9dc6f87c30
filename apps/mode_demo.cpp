// `trephine demo`: the README's main job. With a display: an embedded session server on the
// procedural skull plus a trainee window connected over loopback, drilled with the mouse or a
// script. Without one (or with --headless): drills a burr hole with the cranial perforator at the
// default site and prints what happened.
#include "modes.h"

#include "mode_window.h"
#include "net/session_server.h"

#include "libsim/drill.h"
#include "libsim/error.h"
#include "libsim/skull.h"
#include "libsim/stats.h"
#include "libsim_image/volume_slices.h"

#include <chrono>
#include <cstdio>
#include <glm/gtx/quaternion.hpp>

namespace trephine::app {

namespace {

struct DemoOptions {
    std::string volume = "skull:128";
    float feedMmPerS = 1.0f;
    float dtMs = 1.0f;
    float maxSeconds = 30.0f;
    bool headless = false;
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

int runHeadlessDemo(const DemoOptions& o) {
    using Clock = std::chrono::steady_clock;
    std::printf("Trephine demo: a burr hole with the cranial perforator (headless)\n");
    Volume skull = openVolume(o.volume);
    const Volume original = skull;
    glm::vec3 spacing = skull.spacing();
    std::printf("volume   %s: %d x %d x %d voxels, %.3g mm spacing\n", o.volume.c_str(),
                skull.dims().x, skull.dims().y, skull.dims().z, spacing.x);

    SurfaceSite site = defaultBurrSite(skull);
    std::printf("site     (%.1f, %.1f, %.1f) mm, normal (%.2f, %.2f, %.2f)\n", site.position.x,
                site.position.y, site.position.z, site.normal.x, site.normal.y, site.normal.z);

    Driller driller(ToolShape::perforator());
    ToolPose pose;
    // The shaft (+z of the tool) points out along the surface normal; the tip starts 1 mm above.
    pose.orientation = glm::rotation(glm::vec3(0, 0, 1), site.normal);
    const float dt = o.dtMs / 1000.0f;
    const int steps = int(o.maxSeconds / dt);
    Box3i touched;
    SampleWindow stepUs(1 << 16);
    int64_t duraContacts = 0;
    float depth = -1.0f, clutchDepth = -1.0f, nextReport = 0.0f;
    int step = 0;
    for (; step < steps; ++step) {
        float t = float(step) * dt;
        depth = -1.0f + o.feedMmPerS * t;
        pose.position = site.position - site.normal * depth;
        auto start = Clock::now();
        DrillResult r = driller.drill(skull, pose, 1.0f, dt);
        stepUs.add(std::chrono::duration<double, std::micro>(Clock::now() - start).count());
        touched.merge(r.changed);
        duraContacts += r.duraContact;
        if (t >= nextReport) {
            std::printf("  t %5.1f s  tip %5.1f mm below the surface  %lld voxels touched\n", t,
                        depth, (long long)r.voxelsTouched);
            nextReport += 2.0f;
        }
        if (r.clutchDisengaged) {
            clutchDepth = depth;
            break;
        }
    }

    auto removed = removedByMaterial(original, skull);
    double voxelMm3 = double(spacing.x) * spacing.y * spacing.z;
    std::printf("result   ");
    if (clutchDepth >= 0)
        std::printf("clutch disengaged at %.1f mm: the inner table is breached, dura intact\n",
                    clutchDepth);
    else
        std::printf("stopped after %.1f s at %.1f mm without breaking through\n", o.maxSeconds,
                    depth);
    std::printf("removed  ");
    for (int m = 1; m < kMaterialCount; ++m)
        if (removed[size_t(m)] > 0)
            std::printf("%s %lld voxels (%.0f mm3)  ",
                        std::string(materialName(Material(m))).c_str(),
                        (long long)removed[size_t(m)], double(removed[size_t(m)]) * voxelMm3);
    std::printf("\nBB_volume lo (%d, %d, %d) size %d x %d x %d voxels\n", touched.lo.x,
                touched.lo.y, touched.lo.z, touched.size().x, touched.size().y, touched.size().z);
    std::printf("dura     %lld steps in contact (violations)\n", (long long)duraContacts);
    std::printf("timing   %d drilling steps of %.1f ms simulated; wall time per step p50 %.1f us, "
                "p99 %.1f us\n",
                step + 1, o.dtMs, stepUs.percentile(50), stepUs.percentile(99));
    // A failure is said on stderr too, where scripts look (stdout has the whole summary).
    if (clutchDepth < 0)
        std::fprintf(stderr, "trephine: demo: the perforator did not break through in %.1f s\n",
                     o.maxSeconds);
    if (duraContacts > 0)
        std::fprintf(stderr, "trephine: demo: the perforator touched the dura in %lld steps\n",
                     (long long)duraContacts);
    return clutchDepth >= 0 && duraContacts == 0 ? 0 : 1;
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
    if (o.headless)
        return runHeadlessDemo(o);
    // The embedded server on a free loopback port, then the trainee window.
    net::ServerConfig config;
    config.port = 0;
    config.volumeName = o.volume;
    net::SessionServer server(openVolume(o.volume), config);
    server.start();
    o.window.connect = "127.0.0.1:" + std::to_string(server.port());
    std::printf("demo: server on %s (%s), trainee window connected\n", o.window.connect.c_str(),
                o.volume.c_str());
    int rc = runWindowedClient(o.window);
    server.stop();
    return rc;
}

} // namespace

void addDemoMode(CLI::App& root, int& exitCode) {
    auto o = std::make_shared<DemoOptions>();
    CLI::App* sub = root.add_subcommand(
        "demo", "An embedded server on the procedural skull and a trainee window (headless "
                "without a display: drill a burr hole and print a summary)");
    sub->add_flag("--headless", o->headless, "No window: drill and print a summary");
    sub->add_option("--script", o->window.script,
                    "Windowed: `burrhole` drills a scripted hole (default: the mouse drills)")
        ->check(CLI::IsMember({"", "burrhole"}));
    addWindowOptions(sub, o->window);
    sub->add_option("--volume", o->volume, "Volume spec (see `trephine volume --help`)")
        ->capture_default_str();
    sub->add_option("--feed", o->feedMmPerS, "Perforator feed rate, mm/s")
        ->check(finiteRange(0.05, 20.0))
        ->capture_default_str();
    sub->add_option("--dt", o->dtMs, "Simulation step, ms")
        ->check(finiteRange(0.1, 50.0))
        ->capture_default_str();
    sub->add_option("--max-seconds", o->maxSeconds, "Simulated time limit, s")
        ->check(finiteRange(0.1, 600.0))
        ->capture_default_str();
    sub->callback([o, &exitCode] { exitCode = runDemo(*o); });
}

} // namespace trephine::app

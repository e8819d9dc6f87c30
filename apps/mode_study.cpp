// `trephine study SUBCOMMAND`: the reproducible studies. `haptics` runs the multi-rate haptics
// study (issue 5); `updates`, `display` and `all` arrive with the baseline (issue 7).
#include "modes.h"

#include "libsim/error.h"
#include "libsim/haptics_study.h"
#include "libsim/stats.h"
#include "libsim_devices/devices.h"
#include "libsim_image/volume_slices.h"
#include "net/force_round_trip.h"
#include "net/session_server.h"

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <string>
#include <thread>
#include <vector>

namespace trephine::app {

namespace {

struct HapticsOptions {
    std::vector<double> updateRates{20, 50, 100, 1000};
    std::vector<double> latencies{0, 25, 50};
    std::string out = ".";
    std::string volume = "skull:128";
    float burrMm = 2.0f;
    bool quick = false;
};

struct Timing {
    const char* name;
    double p50Ms, p99Ms;
    double paperMs;
    double targetMs;
};

// Wall time of one force + gradient at a contact pose (median of many): the figure the paper
// gives per haptic update.
Timing timeForceModel(const char* name, const Volume& v, const SurfaceSite& site,
                      const ToolShape& shape, float depthMm, double paperMs, double targetMs,
                      int reps) {
    using Clock = std::chrono::steady_clock;
    ForceModel model(shape);
    // The cutter's lowest point depthMm into the bone.
    const float lift = (shape.kind == ToolKind::Burr ? 0.5f * shape.diameterMm : 0.0f) - depthMm;
    ToolPose pose = ToolPose::fromAxis(site.position + site.normal * lift, site.normal);
    SampleWindow ms{size_t(reps)};
    volatile float sink = 0.0f; // keeps the calls
    for (int i = 0; i < reps; ++i) {
        pose.position += site.normal * (i % 2 ? 1e-3f : -1e-3f);
        auto t0 = Clock::now();
        ForceResult r = model.compute(v, pose);
        ms.add(std::chrono::duration<double, std::milli>(Clock::now() - t0).count());
        sink = sink + r.force.x;
    }
    return {name, ms.percentile(50), ms.percentile(99), paperMs, targetMs};
}

int runHapticsStudy(const HapticsOptions& o) {
    Volume volume;
    SurfaceSite site;
    if (o.volume == "box") {
        volume = makeBox(48);
        site = boxTopSite(volume);
    } else {
        volume = openVolume(o.volume);
        site = defaultBurrSite(volume);
    }
    HapticsStudyConfig config;
    config.shape = ToolShape::burr(o.burrMm);
    std::vector<double> rates = o.updateRates, latencies = o.latencies;
    if (o.quick) {
        config.durationS = 1.0;
        rates = {20, 100};
        latencies = {0, 50};
    }
    for (double r : rates)
        if (!(r > 0.0 && r <= config.hapticRateHz))
            throw Error("--update-rates: " + std::to_string(r) + " Hz is not in (0, 1000]");
    for (double l : latencies)
        if (!(l >= 0.0 && l <= 10000.0))
            throw Error("--latencies: " + std::to_string(l) + " ms is not in [0, 10000]");

    std::error_code ec;
    std::filesystem::create_directories(o.out, ec);
    const std::string csvPath = (std::filesystem::path(o.out) / "haptics.csv").string();
    std::ofstream csv(csvPath);
    if (!csv)
        throw Error("cannot write " + csvPath + ": check that --out is a writable folder");
    csv << hapticsCsvHeader() << "\n";

    std::printf("Haptics study: %s pressed on %s at (%.1f, %.1f, %.1f) mm, %.1f s per case, "
                "1 kHz haptic loop\n",
                config.shape.describe().c_str(), o.volume.c_str(), site.position.x, site.position.y,
                site.position.z, config.durationS);
    std::printf("%-10s %7s %8s %10s %10s %12s %7s %9s\n", "method", "upd Hz", "lat ms", "rms err N",
                "peak err N", "injected mJ", "stable", "max pen");
    for (double rate : rates)
        for (double lat : latencies)
            for (HapticMethod m : {HapticMethod::Multirate, HapticMethod::ZeroOrderHold}) {
                HapticsCaseResult r = runHapticsCase(volume, site, config, {m, rate, lat});
                csv << hapticsCsvRow(r) << "\n";
                std::printf("%-10s %7g %8g %10.4f %10.4f %12.4f %7s %8.2fmm\n", hapticMethodName(m),
                            rate, lat, r.forceRmsErrorN, r.forcePeakErrorN, r.energyInjectedJ * 1e3,
                            r.stable ? "yes" : "NO", r.maxPenetrationMm);
            }
    csv.close();

    const int reps = o.quick ? 500 : 3000;
    std::printf("\nForce model time per update (force + gradient, one core):\n");
    std::printf("%-16s %9s %9s %10s %10s\n", "tool", "p50 ms", "p99 ms", "target ms", "paper ms");
    for (Timing t :
         {timeForceModel("burr 2 mm", volume, site, ToolShape::burr(2.0f), 1.0f, 0.56, 0.1, reps),
          timeForceModel("burr 6 mm", volume, site, ToolShape::burr(6.0f), 1.0f, 0.56, 0.1, reps),
          timeForceModel("perforator 14mm", volume, site, ToolShape::perforator(), 3.0f, 2.98, 0.5,
                         reps)})
        std::printf("%-16s %9.4f %9.4f %10.2f %10.2f\n", t.name, t.p50Ms, t.p99Ms, t.targetMs,
                    t.paperMs);
    // The 1 kHz loop on this machine (a scripted hand resting on the model; no server yet).
    {
        ToolPose rest = ToolPose::fromAxis(site.position, site.normal);
        ScriptedDevice device({{0.0, rest, 0}});
        HapticLoop loop(device, {}, nullptr);
        LocalForceSource local(volume, config.shape);
        loop.setForceSource(&local);
        loop.start();
        std::this_thread::sleep_for(std::chrono::milliseconds(o.quick ? 300 : 1000));
        loop.stop();
        HapticLoopStats st = loop.stats();
        std::printf("\nHaptic loop (local force model, %s): %.0f Hz achieved, lateness p50 "
                    "%.3f ms, p99 %.3f ms over %llu ticks\n",
                    config.shape.describe().c_str(), st.achievedRateHz, st.latenessP50Ms,
                    st.latenessP99Ms, (unsigned long long)st.ticks);
    }
    // The force round trip through a real in-process server over loopback: tool state out, its
    // HapticModel back (the server answers on its network thread, before drilling).
    {
        net::ServerConfig sc;
        sc.port = 0;
        sc.volumeName = o.volume;
        sc.renderThreads = 1;
        net::SessionServer server(volume, sc);
        server.start();
        net::ForceRoundTripConfig fc;
        fc.shape = config.shape;
        const float lift = 0.5f * config.shape.diameterMm - 1.0f; // 1 mm into the bone
        fc.pose = ToolPose::fromAxis(site.position + site.normal * lift, site.normal);
        fc.samples = o.quick ? 300 : 2000;
        fc.rateHz = 1000.0;
        net::ForceRoundTripResult rt = net::measureForceRoundTrip(
            net::parseAddress("127.0.0.1:" + std::to_string(server.port())), fc);
        server.stop();
        std::printf("\nForce round trip over loopback through a session server (%s in contact, "
                    "%d round trips at %.0f Hz):\n",
                    config.shape.describe().c_str(), rt.samples, fc.rateHz);
        std::printf("%-16s %9s %9s %10s %10s\n", "", "p50 ms", "p99 ms", "target ms", "paper ms");
        std::printf("%-16s %9.4f %9.4f %10.2f %10.2f\n", "round trip", rt.p50Us * 1e-3,
                    rt.p99Us * 1e-3, 0.3, 0.82);
        std::printf("%-16s %9.4f %9s %10s %10s\n", "  server share", rt.serverP50Us * 1e-3, "", "",
                    "");
        if (rt.lost > 0)
            std::printf("(%d tool states got no answer within 100 ms)\n", rt.lost);
    }
    std::printf("(paper: its drill and perforator on its faster machine; its round trip over its "
                "LAN)\nwrote %s\n",
                csvPath.c_str());
    return 0;
}

} // namespace

void addStudyMode(CLI::App& root, int& exitCode) {
    CLI::App* study = root.add_subcommand("study", "Run the reproducible studies");
    study->require_subcommand(1);

    auto o = std::make_shared<HapticsOptions>();
    CLI::App* haptics = study->add_subcommand(
        "haptics", "Multi-rate haptics vs zero-order hold across update rates and latencies");
    haptics->add_option("--update-rates", o->updateRates, "Force update rates, Hz")
        ->delimiter(',')
        ->capture_default_str();
    haptics->add_option("--latencies", o->latencies, "Round-trip latencies, ms")
        ->delimiter(',')
        ->capture_default_str();
    haptics->add_option("--out", o->out, "Folder for haptics.csv")->capture_default_str();
    haptics->add_option("--volume", o->volume, "Volume spec, or `box` for a flat bone block")
        ->capture_default_str();
    haptics->add_option("--burr", o->burrMm, "Burr diameter, mm (1-6)")->capture_default_str();
    haptics->add_flag("--quick", o->quick, "A reduced grid in well under a minute");
    haptics->callback([o, &exitCode] { exitCode = runHapticsStudy(*o); });
}

} // namespace trephine::app

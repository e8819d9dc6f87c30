// `study haptics`: the grid of simulated cases (haptics.csv), then three timings on this machine:
// the force model per update, the 1 kHz loop, and the force round trip through a real server.
#include "study/commands.h"

#include "output.h"

#include "libsim/error.h"
#include "libsim/replacing_file.h"
#include "libsim/stats.h"
#include "libsim_devices/devices.h"
#include "libsim_image/volume_slices.h"
#include "net/force_round_trip.h"
#include "net/session_server.h"

#include <fmt/format.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <thread>

namespace trephine::study {

namespace {

// Wall time of one force + gradient at a contact pose (median of many): the figure the paper
// gives per haptic update.
ForceTiming timeForceModel(const char* name, const Volume& v, const SurfaceSite& site,
                           const ToolShape& shape, float depthMm, double paperServerMs,
                           double paperClientMs, double targetMs, int reps) {
    using Clock = std::chrono::steady_clock;
    ForceModel model(shape);
    // The cutter's lowest point depthMm into the bone.
    const float lift = (shape.sphere() ? 0.5f * shape.diameterMm : 0.0f) - depthMm;
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
    return {name, ms.percentile(50), ms.percentile(99), paperServerMs, paperClientMs, targetMs};
}

// Every (rate, latency, method) case, printed and written to `csvPath`.
std::vector<HapticsCaseResult> runCases(const Volume& volume, const SurfaceSite& site,
                                        const HapticsStudyConfig& config,
                                        const std::vector<double>& rates,
                                        const std::vector<double>& latencies,
                                        const std::string& csvPath) {
    // The rows go to a file beside haptics.csv, put in its place once complete: a run that fails
    // or is interrupted leaves an earlier haptics.csv whole.
    ReplacingFile csvFile(csvPath);
    std::ofstream& csv = csvFile.stream();
    if (!csvFile.good())
        throw Error("cannot write " + csvPath + ": check that --out is a writable folder");
    csv << hapticsCsvHeader() << "\n";
    fmt::print("{:<10} {:>7} {:>8} {:>10} {:>10} {:>12} {:>9} {:>9} {:>7}\n", "method", "upd Hz",
               "lat ms", "rms err N", "peak err N", "injected mJ", "max pen", "osc+ mm", "stable");
    std::vector<HapticsCaseResult> cases;
    for (double rate : rates)
        for (double lat : latencies)
            for (HapticMethod m : {HapticMethod::Multirate, HapticMethod::ZeroOrderHold}) {
                HapticsCaseResult r = runHapticsCase(volume, site, config, {m, rate, lat});
                csv << hapticsCsvRow(r) << "\n";
                cases.push_back(r);
                fmt::print("{:<10} {:>7g} {:>8g} {:>10.4f} {:>10.4f} {:>12.4f} {:>7.2f}mm {:>9.4f} "
                           "{:>7}\n",
                           hapticMethodName(m), rate, lat, r.forceRmsErrorN, r.forcePeakErrorN,
                           r.energyInjectedJ * 1e3, r.maxPenetrationMm, r.excessOscillationMm,
                           r.stable ? "yes" : "NO");
            }
    fmt::print("(stable: against a run of the same hand on the exact force at 1 kHz with no delay; "
               "osc+ is the oscillation the display adds, docs/haptics.md)\n");
    // Buffered rows reach the file only here: a full disk shows at the close.
    if (!csvFile.commit())
        throw Error("cannot write " + csvPath + ": check that --out is a writable folder");
    return cases;
}

std::vector<ForceTiming> timeForceModels(const Volume& volume, const SurfaceSite& site, int reps) {
    fmt::print("\nForce model time per update (force + gradient, one core):\n");
    // Both of the paper's times: its server's and its (slower) client's, each the time of one
    // force update there.
    fmt::print("{:<16} {:>9} {:>9} {:>10} {:>16}\n", "tool", "p50 ms", "p99 ms", "target ms",
               "paper srv/cli ms");
    // Paper: the drill 0.56 ms on its server, 1.75 ms on its client; the perforator 2.98 / 9.19.
    std::vector<ForceTiming> timings = {
        timeForceModel("burr 2 mm", volume, site, ToolShape::burr(2.0f), 1.0f, 0.56, 1.75, 0.1,
                       reps),
        timeForceModel("burr 6 mm", volume, site, ToolShape::burr(6.0f), 1.0f, 0.56, 1.75, 0.1,
                       reps),
        timeForceModel("perforator 14mm", volume, site, ToolShape::perforator(), 3.0f, 2.98, 9.19,
                       0.5, reps)};
    for (const ForceTiming& t : timings)
        fmt::print("{:<16} {:>9.4f} {:>9.4f} {:>10.2f} {:>8.2f} / {:>5.2f}\n", t.tool, t.p50Ms,
                   t.p99Ms, t.targetMs, t.paperServerMs, t.paperClientMs);
    return timings;
}

// The 1 kHz loop on this machine: a scripted hand resting on the local force model.
double measureLoopRate(const Volume& volume, const SurfaceSite& site, const ToolShape& shape,
                       double seconds) {
    ToolPose rest = ToolPose::fromAxis(site.position, site.normal);
    ScriptedDevice device({{0.0, rest, 0}});
    HapticLoop loop(device, {}, nullptr);
    LocalForceSource local(volume, shape);
    loop.setForceSource(&local);
    loop.start();
    std::this_thread::sleep_for(std::chrono::duration<double>(seconds));
    loop.stop();
    HapticLoopStats st = loop.stats();
    fmt::print("\nHaptic loop (local force model, {}): {:.0f} Hz achieved, lateness p50 "
               "{:.3f} ms, p99 {:.3f} ms over {} ticks\n",
               shape.describe(), st.achievedRateHz, st.latenessP50Ms, st.latenessP99Ms, st.ticks);
    return st.achievedRateHz;
}

// The force round trip through a real in-process server over loopback: tool state out, its
// HapticModel back (the server answers on its network thread, before drilling).
void measureRoundTrip(const Volume& volume, const HapticsOptions& o, const SurfaceSite& site,
                      const ToolShape& shape, HapticsFigures& figures) {
    net::ServerConfig sc;
    sc.port = 0;
    sc.volumeName = o.volume;
    sc.renderThreads = 1;
    net::SessionServer server(volume, sc);
    server.start();
    net::ForceRoundTripConfig fc;
    fc.shape = shape;
    const float lift = 0.5f * shape.diameterMm - 1.0f; // 1 mm into the bone
    fc.pose = ToolPose::fromAxis(site.position + site.normal * lift, site.normal);
    fc.samples = o.quick ? 300 : 2000;
    fc.rateHz = 1000.0;
    net::ForceRoundTripResult rt = net::measureForceRoundTrip(
        net::parseAddress("127.0.0.1:" + std::to_string(server.port())), fc);
    server.stop();
    figures.roundTripP50Ms = rt.p50Us * 1e-3;
    figures.roundTripP99Ms = rt.p99Us * 1e-3;
    figures.roundTripServerMs = rt.serverP50Us * 1e-3;
    fmt::print("\nForce round trip over loopback through a session server ({} in contact, "
               "{} round trips at {:.0f} Hz):\n",
               shape.describe(), rt.samples, fc.rateHz);
    fmt::print("{:<16} {:>9} {:>9} {:>10} {:>10}\n", "", "p50 ms", "p99 ms", "target ms",
               "paper ms");
    fmt::print("{:<16} {:>9.4f} {:>9.4f} {:>10.2f} {:>10.2f}\n", "round trip", rt.p50Us * 1e-3,
               rt.p99Us * 1e-3, 0.3, 0.82);
    fmt::print("{:<16} {:>9.4f} {:>9} {:>10} {:>10}\n", "  server share", rt.serverP50Us * 1e-3, "",
               "", "");
    if (rt.lost > 0)
        fmt::print("({} tool states got no answer within 100 ms)\n", rt.lost);
}

} // namespace

HapticsFigures runHapticsStudy(const HapticsOptions& o) {
    HapticsFigures figures;
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
    std::string handName = "spring-damper hand";
    if (o.hand != "spring") {
        std::string path = o.hand == "device"                ? builtSimDevicePath()
                           : o.hand.rfind("device:", 0) == 0 ? o.hand.substr(7)
                                                             : std::string();
        if (path.empty())
            throw Error(o.hand == "device"
                            ? "--hand device: no simulated device beside this program "
                              "(build the trephine_sim_device target, or give --hand spring)"
                            : "--hand " + o.hand + ": spring, device or device:PATH.so");
        PluginHand probe(path, config.hand, {}, glm::dvec3(0.0)); // a bad plugin fails here, once
        config.makeHand = [path, hand = config.hand](const HandFrame& f, glm::dvec3 start) {
            return std::make_unique<PluginHand>(path, hand, f, start);
        };
        handName = "simulated force device " + path;
    }
    std::vector<double> rates = o.updateRates, latencies = o.latencies;
    if (o.quick) {
        config.durationS = 1.0;
        if (!o.ratesGiven)
            rates = {20, 100};
        if (!o.latenciesGiven)
            latencies = {0, 50, 300};
    }
    for (double r : rates)
        if (!(r > 0.0 && r <= config.hapticRateHz))
            throw Error("--update-rates: " + std::to_string(r) + " Hz is not in (0, 1000]");
    for (double l : latencies)
        if (!(l >= 0.0 && l <= 10000.0))
            throw Error("--latencies: " + std::to_string(l) + " ms is not in [0, 10000]");

    makeOutDir(o.out);
    const std::string csvPath = (std::filesystem::path(o.out) / "haptics.csv").string();
    fmt::print("Haptics study: {} pressed on {} at ({:.1f}, {:.1f}, {:.1f}) mm, {:.1f} s per case, "
               "1 kHz haptic loop; the hand: {}\n",
               config.shape.describe(), o.volume, site.position.x, site.position.y, site.position.z,
               config.durationS, handName);
    figures.cases = runCases(volume, site, config, rates, latencies, csvPath);
    figures.timings = timeForceModels(volume, site, o.quick ? 500 : 3000);
    figures.loopRateHz = measureLoopRate(volume, site, config.shape, o.quick ? 0.3 : 1.0);
    measureRoundTrip(volume, o, site, config.shape, figures);
    fmt::print("(paper: its drill and perforator on its faster machine; its round trip over its "
               "LAN)\nwrote {}\n",
               csvPath);
    figures.measured = true;
    return figures;
}

} // namespace trephine::study

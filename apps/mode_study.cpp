// `trephine study SUBCOMMAND`: the reproducible studies. `haptics`: multi-rate haptics against a
// zero-order hold (issue 5). `updates`: DBI against replicated-volume update cycles (the paper's
// Table 1, Figures 7 and 8). `display`: the DBI composite's display rate against local volume
// rendering. `all`: every study and DIR/report.md. Each takes --quick (a run under a minute).
#include "modes.h"

#include "libsim/error.h"
#include "libsim/haptics_study.h"
#include "libsim/progress.h"
#include "libsim/stats.h"
#include "libsim/svg_plot.h"
#include "libsim_devices/devices.h"
#include "libsim_image/volume_slices.h"
#include "net/codec.h"
#include "net/force_round_trip.h"
#include "net/session_server.h"
#include "net/study_report.h"
#include "net/update_study.h"
#ifdef TREPHINE_HAVE_GUI
#include "ui/display_study.h"
#endif

#include <cerrno>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <fcntl.h>
#include <filesystem>
#include <fstream>
#include <memory>
#include <string>
#include <thread>
#include <unistd.h>
#include <vector>

namespace trephine::app {

namespace {

std::string makeOutDir(const std::string& out);

// --link's conditions for a study: the emulator passes nothing at a loss of 100 %, and the study
// then waited a minute per method for updates that never came.
net::LinkConditions studyLink(const std::string& text) {
    const net::LinkConditions c = net::LinkConditions::parse(text);
    if (!(c.lossPercent < 100.0))
        throw Error("--link " + text + ": a loss of 100 % lets no update through; give under 100");
    return c;
}

struct HapticsOptions {
    std::vector<double> updateRates{20, 50, 100, 1000};
    std::vector<double> latencies{0, 25, 50};
    std::string out = ".";
    std::string volume = "skull:128";
    float burrMm = 2.0f;
    bool quick = false;
    // Given on the command line: they win over --quick's reduced grid, as in `study updates`.
    bool ratesGiven = false, latenciesGiven = false;
};

// Wall time of one force + gradient at a contact pose (median of many): the figure the paper
// gives per haptic update.
net::ForceTiming timeForceModel(const char* name, const Volume& v, const SurfaceSite& site,
                                const ToolShape& shape, float depthMm, double paperServerMs,
                                double paperClientMs, double targetMs, int reps) {
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
    return {name, ms.percentile(50), ms.percentile(99), paperServerMs, paperClientMs, targetMs};
}

net::HapticsFigures runHapticsStudy(const HapticsOptions& o) {
    net::HapticsFigures figures;
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
        if (!o.ratesGiven)
            rates = {20, 100};
        if (!o.latenciesGiven)
            latencies = {0, 50};
    }
    for (double r : rates)
        if (!(r > 0.0 && r <= config.hapticRateHz))
            throw Error("--update-rates: " + std::to_string(r) + " Hz is not in (0, 1000]");
    for (double l : latencies)
        if (!(l >= 0.0 && l <= 10000.0))
            throw Error("--latencies: " + std::to_string(l) + " ms is not in [0, 10000]");

    makeOutDir(o.out);
    const std::string csvPath = (std::filesystem::path(o.out) / "haptics.csv").string();
    // The rows go to a file beside haptics.csv, put in its place once complete: a run that fails
    // or is interrupted leaves an earlier haptics.csv whole.
    ReplacingFile csvFile(csvPath);
    std::ofstream& csv = csvFile.stream();
    if (!csvFile.good())
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
                figures.cases.push_back(r);
                std::printf("%-10s %7g %8g %10.4f %10.4f %12.4f %7s %8.2fmm\n", hapticMethodName(m),
                            rate, lat, r.forceRmsErrorN, r.forcePeakErrorN, r.energyInjectedJ * 1e3,
                            r.stable ? "yes" : "NO", r.maxPenetrationMm);
            }
    // Buffered rows reach the file only here: a full disk shows at the close.
    if (!csvFile.commit())
        throw Error("cannot write " + csvPath + ": check that --out is a writable folder");

    const int reps = o.quick ? 500 : 3000;
    std::printf("\nForce model time per update (force + gradient, one core):\n");
    // Both of the paper's times: its server's and its (slower) client's, each the time of one
    // force update there (the column said "paper ms" beside the server's alone).
    std::printf("%-16s %9s %9s %10s %16s\n", "tool", "p50 ms", "p99 ms", "target ms",
                "paper srv/cli ms");
    // Paper: the drill 0.56 ms on its server, 1.75 ms on its client; the perforator 2.98 / 9.19.
    figures.timings = {timeForceModel("burr 2 mm", volume, site, ToolShape::burr(2.0f), 1.0f, 0.56,
                                      1.75, 0.1, reps),
                       timeForceModel("burr 6 mm", volume, site, ToolShape::burr(6.0f), 1.0f, 0.56,
                                      1.75, 0.1, reps),
                       timeForceModel("perforator 14mm", volume, site, ToolShape::perforator(),
                                      3.0f, 2.98, 9.19, 0.5, reps)};
    for (const net::ForceTiming& t : figures.timings)
        std::printf("%-16s %9.4f %9.4f %10.2f %8.2f / %5.2f\n", t.tool.c_str(), t.p50Ms, t.p99Ms,
                    t.targetMs, t.paperServerMs, t.paperClientMs);
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
        figures.loopRateHz = st.achievedRateHz;
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
        figures.roundTripP50Ms = rt.p50Us * 1e-3;
        figures.roundTripP99Ms = rt.p99Us * 1e-3;
        figures.roundTripServerMs = rt.serverP50Us * 1e-3;
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
    figures.measured = true;
    return figures;
}

// [SECTION] updates

struct UpdatesOptions {
    std::string out = ".";
    std::vector<int> sizes{10, 20, 30, 40, 50, 60, 70, 80};
    std::string volume = "skull:128";
    std::string camera = "paper";
    // zstd: with predicted updates it sends ~35 % fewer bytes than lz4 for ~0.1-0.4 ms more
    // encoding per update (docs/study.md); the bytes target at 10^3 needs it.
    std::string codec = "zstd";
    // A burst of other work on a shared machine weighs less in each median than with 30.
    int cycles = 100;
    // The sweep runs 4 times, each with a quarter of the cycles: a cell's medians draw on four
    // stretches of the run (docs/study.md).
    int rounds = 4;
    std::string link; // empty: plain loopback
    std::string csvName = "updates.csv";
    std::vector<std::string> methods; // empty: every method
    bool quick = false;
    bool sizesGiven = false;  // --sizes on the command line wins over --quick's sizes
    bool cyclesGiven = false; // likewise --cycles, and --rounds
    bool roundsGiven = false; // without --rounds, fewer cycles than rounds means fewer rounds
    // The volume, already opened from `volume` (study all checks it before its first study).
    std::shared_ptr<const Volume> opened;
};

// Made (with its parents) and checked writable before the study runs: an empty --out wrote into
// the working folder (haptics) or failed unclearly (updates), and a folder that takes no files
// was found only once the study had run.
std::string makeOutDir(const std::string& out) {
    if (out.empty())
        throw Error("--out: an empty path (give the folder to write into)");
    std::error_code ec;
    std::filesystem::create_directories(out, ec);
    if (ec || !std::filesystem::is_directory(out))
        throw Error("cannot create --out folder " + out + ": " +
                    (ec ? ec.message() : std::string("a file is there")));
    // A file made and removed: the folder's permissions do not tell for root, or for /sys.
    const std::string probe =
        (std::filesystem::path(out) / (".trephine-probe-" + std::to_string(::getpid()))).string();
    const int fd = ::open(probe.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0600);
    if (fd < 0)
        throw Error("--out " + out + ": cannot write into it (" + std::strerror(errno) + ")");
    ::close(fd);
    ::unlink(probe.c_str());
    return out;
}

// Staging folders of `study all` runs that ended without cleaning up (killed): their process is
// gone. A running study's folder (another process writing to DIR) is left alone.
void removeAbandonedStaging(const std::string& out) {
    std::error_code ec;
    for (const auto& entry : std::filesystem::directory_iterator(out, ec)) {
        const std::string name = entry.path().filename().string();
        const std::string prefix = ".study-all-";
        if (name.rfind(prefix, 0) != 0 || !entry.is_directory(ec))
            continue;
        const std::string pid = name.substr(prefix.size());
        if (pid.empty() || pid.find_first_not_of("0123456789") != std::string::npos ||
            std::filesystem::exists("/proc/" + pid, ec))
            continue;
        std::filesystem::remove_all(entry.path(), ec);
    }
}

// Through a temporary file renamed over `path` once complete: a failed write (a full disk) leaves
// an earlier run's file whole, where it used to leave it empty.
void writeText(const std::filesystem::path& path, const std::string& text) {
    if (!writeReplacing(path.string(), text))
        throw Error("cannot write " + path.string() + ": check that --out is a writable folder");
}

// The volume a study runs on; with the paper camera its spacing is set so the volume spans the
// paper's 300 pixels (section 4.1).
Volume studyVolume(Volume volume, const std::string& camera) {
    if (camera == "paper") {
        const glm::ivec3 d = volume.dims();
        volume.setSpacing(glm::vec3(paperSpacingMm(std::max({d.x, d.y, d.z}))));
    }
    return volume;
}

// The update study's config from the options, checked (the volume is checked by
// net::checkUpdateStudy).
void configureUpdatesStudy(const UpdatesOptions& o, net::UpdateStudyConfig& config) {
    config.sizes = o.sizes;
    config.volumeName = o.volume;
    config.camera = o.camera;
    config.codec = net::parseCodec(o.codec);
    config.cycles = o.cycles;
    config.rounds = o.roundsGiven ? o.rounds : std::min(o.rounds, std::max(o.cycles, 1));
    if (!o.link.empty())
        config.link = studyLink(o.link);
    config.methods = o.methods;
    if (o.quick) {
        if (!o.sizesGiven)
            config.sizes = {10, 40, 80};
        if (!o.cyclesGiven)
            config.cycles = 5;
        config.warmup = 1;
        if (!o.roundsGiven)
            config.rounds = 1;
    }
    if (config.cycles < 1 || config.cycles > 100000)
        throw Error("--cycles must be in [1, 100000]");
    if (config.rounds < 1 || config.rounds > config.cycles)
        throw Error("--rounds must be in [1, --cycles] (got " + std::to_string(config.rounds) +
                    " with " + std::to_string(config.cycles) + " cycles)");
    const std::vector<std::string> methods = net::updateStudyMethods(config.codec);
    for (const std::string& m : o.methods)
        if (std::find(methods.begin(), methods.end(), m) == methods.end()) {
            std::string names;
            for (const std::string& known : methods)
                names += (names.empty() ? "" : ", ") + known;
            throw Error("--methods: unknown method '" + m + "' (with --codec " + o.codec + ": " +
                        names + ")");
        }
    bool known = false;
    for (const std::string& n : cameraPresetNames())
        known = known || n == o.camera;
    if (!known)
        throw Error("--camera: unknown preset '" + o.camera + "'");
}

std::vector<net::UpdateStudyRow> runUpdatesStudy(const UpdatesOptions& o,
                                                 net::UpdateStudyConfig& config) {
    configureUpdatesStudy(o, config);
    Volume volume = studyVolume(o.opened ? Volume(*o.opened) : openVolume(o.volume), o.camera);
    makeOutDir(o.out);
    std::printf("Update study: %s, camera %s, %dx%d, codec %s, %d cycles per method and size in "
                "%d round%s, %s\n",
                o.volume.c_str(), o.camera.c_str(), config.window, config.window, o.codec.c_str(),
                config.cycles, config.rounds, config.rounds == 1 ? "" : "s",
                config.link ? ("emulated link: " + config.link->describe()).c_str() : "loopback");
    std::fflush(stdout);
    const size_t methodCount = config.methods.empty() ? net::updateStudyMethods(config.codec).size()
                                                      : config.methods.size();
    ProgressBar bar(int(config.sizes.size() * methodCount) * config.rounds);
    config.progress = [&](const std::string& label, int done, int) { bar.set(done, label); };
    std::vector<net::UpdateStudyRow> rows = net::runUpdateStudy(volume, config);
    bar.finish();
    config.progress = nullptr;

    std::string csv = net::updatesCsvHeader() + "\n";
    for (const net::UpdateStudyRow& r : rows)
        csv += net::updatesCsvRow(r) + "\n";
    const auto path = std::filesystem::path(o.out) / o.csvName;
    writeText(path, csv);

    std::printf("%-16s %6s %9s %11s %11s %9s %9s %9s\n", "method", "box", "BB_screen", "bytes/upd",
                "raw bytes", "upd/s", "p50 ms", "p99 ms");
    for (const net::UpdateStudyRow& r : rows)
        std::printf("%-16s %4d^3 %4dx%-4d %11.0f %11.0f %9.1f %9.3f %9.3f\n", r.method.c_str(),
                    r.box, r.bbScreenW, r.bbScreenH, r.bytesPerUpdate, r.rawBytesPerUpdate,
                    r.updatesPerS, r.latencyP50Ms, r.latencyP99Ms);
    for (const std::string& line : net::updateTargetLines(rows))
        std::printf("%s\n", line.c_str());
    for (const std::string& line : net::rateMissNotes(rows, config.link.has_value()))
        std::printf("%s\n", line.c_str());
    std::printf("wrote %s\n", path.string().c_str());
    return rows;
}

// [SECTION] display

struct DisplayOptions {
    std::string out = ".";
    bool quick = false;
};

net::DisplayFigures runDisplayStudy(const DisplayOptions& o) {
    net::DisplayFigures figures;
    makeOutDir(o.out);
#ifdef TREPHINE_HAVE_GUI
    try {
        ui::DisplayStudyConfig config;
        if (o.quick) {
            config.dbiFrames = 40;
            config.volumeFrames = 4;
            config.warmupFrames = 1;
        }
        std::printf("Display study: DBI composite against local volume ray casting, %s view "
                    "%dx%d\n",
                    config.camera.c_str(), config.windowPx, config.windowPx);
        std::fflush(stdout);
        ui::DisplayStudyResult r = ui::measureDisplayRates(config);
        figures.measured = true;
        figures.glRenderer = r.glRenderer + " (" + r.glVersion + ")";
        figures.entries.push_back({"dbi composite", r.dbi.fps, r.dbi.medianMs, r.dbi.p99Ms, 990.0});
        for (const ui::DisplayRate& v : r.volume)
            figures.entries.push_back({formatString("volume %d^3", v.volumeSize), v.fps, v.medianMs,
                                       v.p99Ms,
                                       v.volumeSize == 128   ? 57.0
                                       : v.volumeSize == 256 ? 26.0
                                                             : 0.0});
    } catch (const Error& e) {
        figures.why = e.what();
    }
#else
    figures.why = "this trephine was built without the GUI (TREPHINE_BUILD_GUI=OFF)";
#endif
    if (!figures.measured) {
        std::printf("display study not run: %s\n", figures.why.c_str());
        return figures;
    }
    std::string csv = "renderer,fps,frame_p50_ms,frame_p99_ms,paper_fps\n";
    std::printf("%-18s %10s %12s %12s %10s\n", "client draws", "FPS", "p50 ms", "p99 ms",
                "paper FPS");
    for (const auto& e : figures.entries) {
        csv += formatString("%s,%.2f,%.4f,%.4f,%.0f\n", e.name.c_str(), e.fps, e.frameP50Ms,
                            e.frameP99Ms, e.paperFps);
        std::printf("%-18s %10.1f %12.3f %12.3f %10.0f\n", e.name.c_str(), e.fps, e.frameP50Ms,
                    e.frameP99Ms, e.paperFps);
    }
    for (const std::string& line : net::displayTargetLines(figures))
        std::printf("%s\n", line.c_str());
    const auto path = std::filesystem::path(o.out) / "display.csv";
    writeText(path, csv);
    std::printf("(%s)\nwrote %s\n", figures.glRenderer.c_str(), path.string().c_str());
    return figures;
}

// [SECTION] all

// The link `study all` runs the update study over a second time: the paper's 100 Mbit/s LAN.
constexpr const char* kPaperLink = "rate=100";

struct AllOptions {
    std::string out = "study";
    std::string volume = "skull:128";
    std::string codec = "zstd";
    // The update study runs over loopback, then again over this emulated link; "off": only once.
    std::string link = kPaperLink;
    bool quick = false;
};

int runAllStudies(const AllOptions& o, const std::string& command) {
    // Options of the later studies are checked before the first one runs.
    net::parseCodec(o.codec);
    const bool linkRun = o.link != "off";
    // An empty --link parsed as no conditions: the second run was plain loopback again, written
    // up as the emulated link.
    if (linkRun && o.link.find_first_not_of(" ,") == std::string::npos)
        throw Error("--link: give the link's conditions (e.g. rate=100) or off, not '" + o.link +
                    "'");
    if (linkRun)
        studyLink(o.link);
    // A volume that does not open fails here, not after the haptics study has replaced the
    // folder's haptics.csv.
    auto volume = std::make_shared<const Volume>(openVolume(o.volume));
    UpdatesOptions u;
    u.out = o.out;
    u.volume = o.volume;
    u.opened = volume;
    u.codec = o.codec;
    u.quick = o.quick;
    {
        // Likewise a volume too small for the cuts, or without bone where they fall.
        net::UpdateStudyConfig config;
        configureUpdatesStudy(u, config);
        net::checkUpdateStudy(studyVolume(*volume, u.camera), config);
    }
    makeOutDir(o.out);
    // Each file moves over its name in DIR at the end: a folder (or anything but a file) there
    // failed that move after the whole run, with some files replaced and the new report lost.
    for (const char* name : {"haptics.csv", "updates.csv", "updates.svg", "bytes.svg",
                             "updates-link.csv", "updates-link.svg", "display.csv", "report.md"}) {
        const std::filesystem::path there = std::filesystem::path(o.out) / name;
        std::error_code ec;
        const auto st = std::filesystem::symlink_status(there, ec);
        if (!ec && std::filesystem::exists(st) && !std::filesystem::is_regular_file(st) &&
            !std::filesystem::is_symlink(st))
            throw Error("--out " + o.out + ": " + name + " there is not a file, and the study's " +
                        name + " cannot replace it (move it away)");
    }
    // Every file is written into a staging folder inside DIR and moved into DIR only once the
    // report is written: a run stopped or failing part way (a full disk, Ctrl-C during the
    // display study) left new CSVs beside an earlier run's report and plots.
    const std::filesystem::path staging =
        std::filesystem::path(o.out) / (".study-all-" + std::to_string(getpid()));
    removeAbandonedStaging(o.out);
    std::filesystem::remove_all(staging);
    makeOutDir(staging.string());
    struct RemoveStaging {
        std::filesystem::path path;
        ~RemoveStaging() {
            std::error_code ec;
            std::filesystem::remove_all(path, ec);
        }
    } removeStaging{staging};
    u.out = staging.string();
    net::StudyReportInput input;
    input.command = command;
    input.machine = net::describeMachine();
    input.quick = o.quick;

    const int studies = linkRun ? 4 : 3;
    std::printf("== 1/%d haptics ==\n", studies);
    HapticsOptions h;
    h.out = staging.string();
    h.quick = o.quick;
    input.haptics = runHapticsStudy(h);

    std::printf("\n== 2/%d updates over loopback ==\n", studies);
    input.updates = runUpdatesStudy(u, input.updateConfig);

    if (linkRun) {
        std::printf("\n== 3/%d updates over an emulated link ==\n", studies);
        u.link = o.link;
        u.csvName = "updates-link.csv";
        input.linkUpdates = runUpdatesStudy(u, input.linkUpdateConfig);
    }

    std::printf("\n== %d/%d display ==\n", studies, studies);
    DisplayOptions d;
    d.out = staging.string();
    d.quick = o.quick;
    input.display = runDisplayStudy(d);

    const std::string report = net::writeStudyReport(input, staging.string());
    writeText(staging / "report.md", report);
    // The whole set is there: into DIR, each file replacing the earlier run's.
    for (const auto& entry : std::filesystem::directory_iterator(staging)) {
        std::error_code ec;
        std::filesystem::rename(entry.path(),
                                std::filesystem::path(o.out) / entry.path().filename(), ec);
        if (ec) { // the new set stays whole where it is, and is said
            removeStaging.path.clear();
            throw Error("cannot move " + entry.path().filename().string() + " into " + o.out +
                        ": " + ec.message() + "; this run's files are in " + staging.string());
        }
    }
    const auto path = std::filesystem::path(o.out) / "report.md";
    std::printf("\nwrote %s (with updates.svg%s and bytes.svg; the studies' files moved there "
                "from %s)\n",
                path.string().c_str(), linkRun ? ", updates-link.svg" : "",
                staging.filename().string().c_str());
    // Files of ours an earlier run left in DIR that this run did not write (--link off, or no
    // display) would sit beside a report that does not mention them, as if they were its figures.
    // They go once the new report is in place (a run that fails before leaves the old set whole).
    std::vector<std::string> stale;
    if (!linkRun)
        stale.insert(stale.end(), {"updates-link.csv", "updates-link.svg"});
    if (!input.display.measured)
        stale.push_back("display.csv");
    std::string removed;
    for (const std::string& name : stale) {
        const auto file = std::filesystem::path(o.out) / name;
        std::error_code ec;
        if (std::filesystem::is_directory(file, ec))
            continue; // not one of ours
        if (std::filesystem::remove(file, ec))
            removed += (removed.empty() ? "" : ", ") + name;
        else if (ec)
            throw Error("cannot remove the earlier run's " + file.string() + ": " + ec.message());
    }
    if (!removed.empty())
        std::printf("removed %s from an earlier run: this run has no such results\n",
                    removed.c_str());
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
    haptics->add_flag("--quick", o->quick,
                      "A reduced grid in well under a minute (--update-rates and --latencies "
                      "given win)");
    haptics->callback([o, haptics, &exitCode] {
        o->ratesGiven = haptics->count("--update-rates") > 0;
        o->latenciesGiven = haptics->count("--latencies") > 0;
        runHapticsStudy(*o);
        exitCode = 0;
    });

    auto u = std::make_shared<UpdatesOptions>();
    CLI::App* updates = study->add_subcommand(
        "updates", "DBI vs replicated-volume update cycles per box size (Table 1, Figures 7, 8)");
    updates->add_option("--out", u->out, "Folder for updates.csv")->capture_default_str();
    updates->add_option("--sizes", u->sizes, "Box edges N (voxels) of the N^3 cuts")
        ->delimiter(',')
        ->check(CLI::Range(1, 512))
        ->capture_default_str();
    updates->add_option("--volume", u->volume, "Volume spec")->capture_default_str();
    updates->add_option("--camera", u->camera, "Camera preset (paper: the paper's setup)")
        ->capture_default_str();
    updates->add_option("--codec", u->codec, "Image codec: raw, lz4 or zstd")
        ->capture_default_str();
    updates->add_option("--cycles", u->cycles, "Measured cycles per method and size")
        ->capture_default_str();
    updates
        ->add_option("--rounds", u->rounds,
                     "Run the sweep this many times, each with its share of the cycles, and pool "
                     "them")
        ->capture_default_str();
    updates
        ->add_option("--link", u->link,
                     "Emulate a link between clients and server, e.g. rate=100,latency=0.1 (the "
                     "paper's 100 Mbit/s LAN); default: plain loopback")
        ->capture_default_str();
    updates
        ->add_option("--methods", u->methods,
                     "Only these methods (dbi, dbi-fullrender, volume, volume-CODEC)")
        ->delimiter(',');
    updates->add_flag(
        "--quick", u->quick,
        "Sizes 10, 40, 80 and 5 cycles in one round, under a minute (--sizes, --cycles and "
        "--rounds given win)");
    updates->callback([u, updates, &exitCode] {
        u->sizesGiven = updates->count("--sizes") > 0;
        u->cyclesGiven = updates->count("--cycles") > 0;
        u->roundsGiven = updates->count("--rounds") > 0;
        net::UpdateStudyConfig config;
        runUpdatesStudy(*u, config);
        exitCode = 0;
    });

    auto d = std::make_shared<DisplayOptions>();
    CLI::App* display = study->add_subcommand(
        "display", "Display rate: DBI composite vs local volume rendering at 128^3 and 256^3");
    display->add_option("--out", d->out, "Folder for display.csv")->capture_default_str();
    display->add_flag("--quick", d->quick, "Fewer frames: a few seconds");
    display->callback([d, &exitCode] {
        net::DisplayFigures f = runDisplayStudy(*d);
        if (!f.measured) // said where a script looks for a failure (stdout has it too)
            std::fprintf(stderr, "trephine: the display study did not run: %s\n", f.why.c_str());
        exitCode = f.measured ? 0 : 1;
    });

    auto a = std::make_shared<AllOptions>();
    CLI::App* all = study->add_subcommand(
        "all", "Every study, then DIR/report.md with the paper's figures beside ours");
    all->add_option("--out", a->out, "Folder for the CSVs, SVGs and report.md")
        ->capture_default_str();
    all->add_option("--volume", a->volume, "Volume spec for the update study")
        ->capture_default_str();
    all->add_option("--codec", a->codec, "Image codec: raw, lz4 or zstd")->capture_default_str();
    all->add_option("--link", a->link,
                    "Run the update study over loopback, then again over this emulated link "
                    "(default: the paper's 100 Mbit/s LAN); off: loopback only")
        ->capture_default_str();
    all->add_flag("--quick", a->quick, "A reduced run of every study, under a minute");
    all->callback([a, &exitCode] {
        std::string command = "trephine study all --out " + a->out + " --volume " + a->volume +
                              " --codec " + a->codec + " --link " + a->link +
                              (a->quick ? " --quick" : "");
        exitCode = runAllStudies(*a, command);
    });
}

} // namespace trephine::app

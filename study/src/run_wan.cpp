// `study wan`: the options checked into a WanStudyConfig, the study run with a progress bar, its
// CSVs written and its table and targets printed.
#include "study/wan_study.h"

#include "output.h"

#include "libsim/camera.h"
#include "libsim/error.h"
#include "libsim_image/volume_slices.h"
#include "net/codec.h"
#include "study/progress.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>

namespace trephine::study {

namespace {

// --quick: RTT {0, 100} x loss {0, 1} and the target link, box 40, soaks of 1.5 s (the target
// link's 3 s) and classrooms of 1 and 4: under a minute here.
void configureWan(const WanOptions& o, WanStudyConfig& config) {
    config.volumeName = o.volume;
    config.codec = net::parseCodec(o.codec);
    config.links = wanSweep(o.quick);
    config.boxes = o.boxesGiven || !o.quick ? o.boxes : std::vector<int>{40};
    config.classroom = o.clientsGiven || !o.quick ? o.clients : std::vector<int>{1, 4};
    if (std::find(config.boxes.begin(), config.boxes.end(), config.classroomBox) ==
        config.boxes.end())
        config.classroomBox = *std::max_element(config.boxes.begin(), config.boxes.end());
    if (o.quick) {
        config.soakS = 1.5;
        config.targetSoakS = 3;
        config.classroomSoakS = 1.5;
        config.joinTimeoutS = 20;
    }
    if (!o.rtts.empty() || !o.losses.empty()) {
        config.links.clear();
        for (double rtt : o.rtts.empty() ? std::vector<double>{0} : o.rtts)
            for (double loss : o.losses.empty() ? std::vector<double>{0} : o.losses)
                config.links.push_back({rtt, loss, 100});
        config.links.push_back(wanTargetLink());
    }
    if (o.soakS > 0)
        config.soakS = config.classroomSoakS = o.soakS;
    config.classroomRateMbit = o.classroomRateMbit;
}

// The paper camera's volume: its spacing makes it span the paper's 300 pixels.
Volume wanVolume(const WanOptions& o) {
    Volume volume = o.opened ? Volume(*o.opened) : openVolume(o.volume);
    const glm::ivec3 d = volume.dims();
    volume.setSpacing(glm::vec3(paperSpacingMm(std::max({d.x, d.y, d.z}))));
    return volume;
}

std::string ms(double v) {
    return std::isnan(v) ? "-" : v < 0 ? "never" : fmt::format("{:.1f}", v);
}

void printWan(const WanResults& r) {
    fmt::print("{:<7} {:>5} {:>5} {:>5} {:>4} {:>5} {:>7} {:>8} {:>8} {:>8} {:>8} {:>8} {:>9}\n",
               "design", "rtt", "loss", "Mbit", "cl", "box", "upd/s", "p50 ms", "p99 ms", "join ms",
               "view ms", "stall ms", "MB/s out");
    for (const WanRow& w : r.rows)
        fmt::print("{:<7} {:>5.0f} {:>5.1f} {:>5.0f} {:>4} {:>4}^ {:>7.1f} {:>8} {:>8} {:>8} "
                   "{:>8} {:>8} {:>9.2f}\n",
                   w.design, w.rttMs, w.lossPct, w.rateMbit, w.clients, w.box, w.updatesPerS,
                   ms(w.latencyP50Ms), ms(w.latencyP99Ms), ms(w.joinMs), ms(w.viewChangeMs),
                   ms(w.maxStallMs), w.egressBytesPerS * 1e-6);
    for (const std::string& line : wanTargetLines(r))
        fmt::print("{}\n", line);
}

} // namespace

void checkWanOptions(const WanOptions& o, const Volume& volume) {
    WanStudyConfig config;
    configureWan(o, config);
    checkWanStudy(volume, config);
}

WanResults runWanCommand(const WanOptions& o, WanStudyConfig& config) {
    configureWan(o, config);
    const Volume volume = wanVolume(o);
    checkWanStudy(volume, config);
    makeOutDir(o.out);
    fmt::print("WAN study: {}, paper camera, {}x{}, codec {}, {} links x {} boxes per design, "
               "soaks of {} s ({} s at the target link), {} cuts a second; classrooms of {} "
               "clients in this process on {}\n",
               o.volume, config.window, config.window, o.codec, config.links.size(),
               config.boxes.size(), config.soakS, config.targetSoakS, config.cutHz,
               fmt::join(config.classroom, ", "), classroomLink(config.classroomRateMbit));
    std::fflush(stdout);
    ProgressBar bar(int(2 * (config.links.size() * config.boxes.size() + config.classroom.size())));
    config.progress = [&](const std::string& label, int done, int) { bar.set(done, label); };
    WanResults r = runWanStudy(volume, config);
    bar.finish();
    config.progress = nullptr;

    std::string csv = wanCsvHeader() + "\n";
    for (const WanRow& w : r.rows)
        csv += wanCsvRow(w) + "\n";
    writeText(std::filesystem::path(o.out) / "wan.csv", csv);
    std::string clients = wanClientsCsvHeader() + "\n";
    for (const WanClientRow& c : r.clients)
        clients += wanClientsCsvRow(c) + "\n";
    writeText(std::filesystem::path(o.out) / "wan-classroom.csv", clients);
    printWan(r);
    fmt::print("wrote {} and wan-classroom.csv\n",
               (std::filesystem::path(o.out) / "wan.csv").string());
    return r;
}

} // namespace trephine::study

// `study updates`: the options checked into an UpdateStudyConfig, the study run with a progress
// bar, its CSV written and its table and targets printed.
#include "study/commands.h"

#include "output.h"

#include "libsim/camera.h"
#include "libsim/error.h"
#include "libsim_image/volume_slices.h"
#include "net/codec.h"
#include "study/progress.h"

#include <fmt/format.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>

namespace trephine::study {

namespace {

// The volume a study runs on; with the paper camera its spacing is set so the volume spans the
// paper's 300 pixels (section 4.1).
Volume studyVolume(Volume volume, const std::string& camera) {
    if (camera == "paper") {
        const glm::ivec3 d = volume.dims();
        volume.setSpacing(glm::vec3(paperSpacingMm(std::max({d.x, d.y, d.z}))));
    }
    return volume;
}

// The options' config, checked; checkUpdateStudy checks it against the volume.
void configureUpdatesStudy(const UpdatesOptions& o, UpdateStudyConfig& config) {
    config.sizes = o.sizes;
    config.volumeName = o.volume;
    config.camera = o.camera;
    config.codec = net::parseCodec(o.codec);
    config.cycles = o.cycles;
    config.rounds = o.roundsGiven ? o.rounds : std::min(o.rounds, std::max(o.cycles, 1));
    if (!o.link.empty())
        config.link = studyLink(o.link);
    config.methods = o.methods;
    config.record = o.record;
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
    const std::vector<std::string> methods = updateStudyMethods(config.codec);
    for (const std::string& m : o.methods)
        if (std::find(methods.begin(), methods.end(), m) == methods.end()) {
            std::string names;
            for (const std::string& known : methods)
                names += (names.empty() ? "" : ", ") + known;
            throw Error("--methods: unknown method '" + m + "' (with --codec " + o.codec + ": " +
                        names + ")");
        }
    const std::vector<std::string> presets = cameraPresetNames();
    if (std::find(presets.begin(), presets.end(), o.camera) == presets.end())
        throw Error("--camera: unknown preset '" + o.camera + "'");
}

void printRows(const std::vector<UpdateStudyRow>& rows, bool emulatedLink) {
    fmt::print("{:<16} {:>6} {:>9} {:>11} {:>11} {:>9} {:>9} {:>9}\n", "method", "box", "BB_screen",
               "bytes/upd", "raw bytes", "upd/s", "p50 ms", "p99 ms");
    for (const UpdateStudyRow& r : rows)
        fmt::print("{:<16} {:>4}^3 {:>4}x{:<4} {:>11.0f} {:>11.0f} {:>9.1f} {:>9.3f} {:>9.3f}\n",
                   r.method, r.box, r.bbScreenW, r.bbScreenH, r.bytesPerUpdate, r.rawBytesPerUpdate,
                   r.updatesPerS, r.latencyP50Ms, r.latencyP99Ms);
    for (const std::string& line : updateTargetLines(rows))
        fmt::print("{}\n", line);
    for (const std::string& line : rateMissNotes(rows, emulatedLink))
        fmt::print("{}\n", line);
}

} // namespace

void checkUpdatesOptions(const UpdatesOptions& o, const Volume& volume) {
    UpdateStudyConfig config;
    configureUpdatesStudy(o, config);
    checkUpdateStudy(studyVolume(volume, o.camera), config);
}

std::vector<UpdateStudyRow> runUpdatesStudy(const UpdatesOptions& o, UpdateStudyConfig& config) {
    configureUpdatesStudy(o, config);
    Volume volume = studyVolume(o.opened ? Volume(*o.opened) : openVolume(o.volume), o.camera);
    makeOutDir(o.out);
    fmt::print("Update study: {}, camera {}, {}x{}, codec {}, {} cycles per method and size in "
               "{} round{}, {}\n",
               o.volume, o.camera, config.window, config.window, o.codec, config.cycles,
               config.rounds, config.rounds == 1 ? "" : "s",
               config.link ? "emulated link: " + config.link->describe() : "loopback");
    std::fflush(stdout);
    const size_t methodCount =
        config.methods.empty() ? updateStudyMethods(config.codec).size() : config.methods.size();
    ProgressBar bar(int(config.sizes.size() * methodCount) * config.rounds);
    config.progress = [&](const std::string& label, int done, int) { bar.set(done, label); };
    std::vector<UpdateStudyRow> rows = runUpdateStudy(volume, config);
    bar.finish();
    config.progress = nullptr;

    std::string csv = updatesCsvHeader() + "\n";
    for (const UpdateStudyRow& r : rows)
        csv += updatesCsvRow(r) + "\n";
    const auto path = std::filesystem::path(o.out) / o.csvName;
    writeText(path, csv);
    printRows(rows, config.link.has_value());
    fmt::print("wrote {}\n", path.string());
    return rows;
}

} // namespace trephine::study

// `study display`: the display study's rates as figures, display.csv and a table. Without the GUI
// (TREPHINE_BUILD_GUI=OFF) the study is absent and the figures say so.
#include "study/commands.h"

#include "output.h"

#include "libsim/error.h"
#ifdef TREPHINE_HAVE_GUI
#include "study/display_study.h"
#endif

#include <fmt/format.h>

#include <cstdio>
#include <filesystem>

namespace trephine::study {

namespace {

#ifdef TREPHINE_HAVE_GUI
// The paper's frame rate for an entry of ours (990 FPS for its DBI client), 0 where it gave none.
double paperFps(int volumeSize) {
    return volumeSize == 128 ? 57.0 : volumeSize == 256 ? 26.0 : 0.0;
}

void measure(const DisplayOptions& o, DisplayFigures& figures) {
    DisplayStudyConfig config;
    if (o.quick) {
        config.dbiFrames = 40;
        config.volumeFrames = 4;
        config.warmupFrames = 1;
    }
    fmt::print("Display study: DBI composite against local volume ray casting, {} view {}x{}\n",
               config.camera, config.windowPx, config.windowPx);
    std::fflush(stdout);
    DisplayStudyResult r = measureDisplayRates(config);
    figures.measured = true;
    figures.glRenderer = r.glRenderer + " (" + r.glVersion + ")";
    figures.entries.push_back({"dbi composite", r.dbi.fps, r.dbi.medianMs, r.dbi.p99Ms, 990.0});
    for (const DisplayRate& v : r.volume)
        figures.entries.push_back({fmt::format("volume {}^3", v.volumeSize), v.fps, v.medianMs,
                                   v.p99Ms, paperFps(v.volumeSize)});
}
#endif

} // namespace

DisplayFigures runDisplayStudy(const DisplayOptions& o) {
    DisplayFigures figures;
    makeOutDir(o.out);
#ifdef TREPHINE_HAVE_GUI
    try {
        measure(o, figures);
    } catch (const Error& e) {
        figures.why = e.what();
    }
#else
    figures.why = "this trephine was built without the GUI (TREPHINE_BUILD_GUI=OFF)";
#endif
    if (!figures.measured) {
        fmt::print("display study not run: {}\n", figures.why);
        return figures;
    }
    std::string csv = "renderer,fps,frame_p50_ms,frame_p99_ms,paper_fps\n";
    fmt::print("{:<18} {:>10} {:>12} {:>12} {:>10}\n", "client draws", "FPS", "p50 ms", "p99 ms",
               "paper FPS");
    for (const auto& e : figures.entries) {
        csv += fmt::format("{},{:.2f},{:.4f},{:.4f},{:.0f}\n", e.name, e.fps, e.frameP50Ms,
                           e.frameP99Ms, e.paperFps);
        fmt::print("{:<18} {:>10.1f} {:>12.3f} {:>12.3f} {:>10.0f}\n", e.name, e.fps, e.frameP50Ms,
                   e.frameP99Ms, e.paperFps);
    }
    for (const std::string& line : displayTargetLines(figures))
        fmt::print("{}\n", line);
    const auto path = std::filesystem::path(o.out) / "display.csv";
    writeText(path, csv);
    fmt::print("({})\nwrote {}\n", figures.glRenderer, path.string());
    return figures;
}

} // namespace trephine::study

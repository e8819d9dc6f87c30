// `trephine study display` (issue 7): the client's display rate with the DBI design (two-pass
// composite of a server-rendered DBI plus a tool) against local volume rendering of the same view
// on the GPU (VolumeView) at several volume sizes, measured in one process and one run.
#pragma once

#include <string>
#include <vector>

namespace trephine::study {

struct DisplayStudyConfig {
    std::string camera = "paper";           // libsim camera preset
    int windowPx = 500;                     // the paper's 500 x 500 window
    std::vector<int> volumeSizes{128, 256}; // skull:N, all at the physical size of skull:128
    int dbiFrames = 200;                    // timed frames of the DBI composite
    int volumeFrames = 30;                  // timed frames of each local volume rendering
    int warmupFrames = 3;                   // untimed frames before each series
};

// Frame times of one way of displaying the view (each frame ends with glFinish).
struct DisplayRate {
    std::string method; // "dbi" or "volume"
    int volumeSize = 0; // N of skull:N (the DBI was rendered from skull:volumeSizes[0])
    int frames = 0;
    double medianMs = 0, p99Ms = 0, meanMs = 0;
    double fps = 0; // 1000 / medianMs
};

struct DisplayStudyResult {
    std::string glRenderer, glVersion; // GL_RENDERER / GL_VERSION ("llvmpipe ..." without a GPU)
    std::string cameraDescription;     // libsim describe(camera)
    int windowPx = 0;
    DisplayRate dbi;
    std::vector<DisplayRate> volume; // one per config.volumeSizes, in that order
    // dbi.fps / volume[i].fps: how many times faster the DBI client displays (issue target >= 20;
    // the paper: 990 / 57 = 17 at 128^3).
    double ratio(size_t i) const { return volume.at(i).fps > 0 ? dbi.fps / volume.at(i).fps : 0; }
};

// Opens a hidden GLFW window (OpenGL 3.3 core), renders the DBI of the view once with the CPU
// Renderer (the server's work, not timed), then times the DBI composite (pass 1 + a burr mesh +
// blit + glFinish) and, for each volume size, the same frame with VolumeView's ray cast in place
// of pass 1. Throws trephine::Error with one line when no window can open (no DISPLAY: run it
// under xvfb-run) or when the configuration is unusable.
DisplayStudyResult measureDisplayRates(const DisplayStudyConfig& config);

} // namespace trephine::study

#include "study/display_study.h"

#include "libsim/camera.h"
#include "libsim/error.h"
#include "libsim/renderer.h"
#include "libsim/skull.h"
#include "libsim/stats.h"
#include "libsim/thread_pool.h"
#include "ui/compositor.h"
#include "ui/mesh.h"
#include "ui/volume_view.h"
#include "ui/window.h"

#include <chrono>
#include <glm/gtc/matrix_transform.hpp>
#include <glm/gtx/quaternion.hpp>
#include <memory>
#include <numeric>

namespace trephine::study {

using namespace trephine::ui;

namespace {

DisplayRate summarise(std::string method, int volumeSize, const std::vector<double>& ms) {
    DisplayRate r;
    r.method = std::move(method);
    r.volumeSize = volumeSize;
    r.frames = int(ms.size());
    r.medianMs = percentile(ms, 50);
    r.p99Ms = percentile(ms, 99);
    r.meanMs = std::accumulate(ms.begin(), ms.end(), 0.0) / double(ms.size());
    r.fps = r.medianMs > 0 ? 1000.0 / r.medianMs : 0.0;
    return r;
}

// Times `frames` calls of `frame` (after `warmup` untimed ones); each ends with glFinish.
template <typename F>
std::vector<double> timeFrames(int warmup, int frames, F&& frame) {
    for (int i = 0; i < warmup; ++i) {
        frame();
        glFinish();
    }
    std::vector<double> ms;
    ms.reserve(size_t(frames));
    for (int i = 0; i < frames; ++i) {
        auto t0 = std::chrono::steady_clock::now();
        frame();
        glFinish(); // the frame is done, not just queued
        ms.push_back(
            std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0)
                .count());
    }
    return ms;
}

// A skull of n voxels a side at the physical size of the paper's 128^3 volume, so that every size
// shows the same view.
Volume paperSkull(int n) {
    Volume v = makeSkull(n);
    float edgeMm = paperSpacingMm(128) * 128.0f;
    v.setSpacing(glm::vec3(edgeMm / float(n)));
    return v;
}

} // namespace

DisplayStudyResult measureDisplayRates(const DisplayStudyConfig& config) {
    if (config.volumeSizes.empty() || config.windowPx < 16 || config.dbiFrames < 1 ||
        config.volumeFrames < 1 || config.warmupFrames < 0)
        throw Error("study display: need at least one volume size, a window of 16 px or more "
                    "and at least one frame per series");
    std::string why;
    if (!displayAvailable(&why))
        throw Error("study display: no display for OpenGL (" + why + "); run it under xvfb-run -a");
    WindowConfig wc;
    wc.width = wc.height = config.windowPx;
    wc.visible = false;
    wc.imgui = false;
    wc.title = "Trephine display study";
    Window window(wc);

    DisplayStudyResult result;
    result.glRenderer = reinterpret_cast<const char*>(glGetString(GL_RENDERER));
    result.glVersion = reinterpret_cast<const char*>(glGetString(GL_VERSION));
    result.windowPx = config.windowPx;

    // The server's side, done once and not timed: the view and its full DBI.
    Volume base = paperSkull(config.volumeSizes.front());
    const Camera cam = cameraPreset(config.camera, base, {config.windowPx, config.windowPx});
    result.cameraDescription = describe(cam);
    ThreadPool pool;
    Renderer renderer(base, &pool);
    Dbi dbi = renderer.render(cam);
    // The user's burr resting on the bone in the middle of the view, its shaft toward the eye.
    RayHit h = renderer.castRay(cam, cam.width / 2, cam.height / 2);
    glm::vec3 tip = h.hit ? glm::vec3(h.position) : cam.target;
    glm::vec3 axis = h.hit ? h.normal : glm::normalize(cam.eye - cam.target);
    glm::mat4 model = glm::translate(glm::mat4(1), tip + axis * 2.5f) *
                      glm::mat4_cast(glm::rotation(glm::vec3(0, 0, 1), axis));
    const glm::vec4 owner(0.2f, 0.4f, 0.9f, 1.0f);

    Compositor comp;
    comp.uploadFull(dbi);
    GpuMesh burr = comp.upload(makeToolMesh(ToolShape::burr(5.0f)));

    // (a) the DBI client: pass 1 restores the DBI, pass 2 draws the tool, blit. Its frames are
    // timed in blocks between the volume series (before, between, after), so a slow spell of a
    // shared machine falls on both sides of the ratio rather than on one.
    std::vector<double> dbiMs;
    const int blocks = int(config.volumeSizes.size()) + 1;
    auto dbiBlock = [&](int block) {
        const int frames = config.dbiFrames / blocks + (block < config.dbiFrames % blocks ? 1 : 0);
        if (frames <= 0)
            return;
        comp.uploadFull(dbi);
        auto ms = timeFrames(config.warmupFrames, frames, [&] {
            comp.begin(cam);
            comp.draw(burr, model, owner);
            comp.blitTo(0, 0);
        });
        dbiMs.insert(dbiMs.end(), ms.begin(), ms.end());
    };

    // (b) the replicated-volume client: the window's volume frame, the local ray cast in place of
    // the DBI restore (Compositor::beginEmpty), then the same tool and blit.
    dbiBlock(0);
    {
        VolumeView view;
        for (size_t i = 0; i < config.volumeSizes.size(); ++i) {
            const int n = config.volumeSizes[i];
            Volume v = i == 0 ? base : paperSkull(n);
            view.upload(v);
            auto ms = timeFrames(config.warmupFrames, config.volumeFrames, [&] {
                comp.beginEmpty(cam);
                view.draw(cam);
                comp.draw(burr, model, owner);
                comp.blitTo(0, 0);
            });
            result.volume.push_back(summarise("volume", n, ms));
            dbiBlock(int(i) + 1);
        }
    }
    result.dbi = summarise("dbi", config.volumeSizes.front(), dbiMs);
    comp.destroy(burr);
    return result;
}

} // namespace trephine::study

// Client-side cost of the paper's hybrid rendering on this machine's OpenGL (Mesa llvmpipe under
// xvfb-run here): a composite frame at 500x500 with tools and anatomy, and the sub-upload of an
// update rectangle. The paper reports 990 FPS (1.01 ms a frame) for the client on its GPU.
#include "ui/compositor.h"
#include "ui/window.h"

#include "libsim/skull.h"

#include <benchmark/benchmark.h>
#include <glm/gtc/matrix_transform.hpp>
#include <glm/gtx/quaternion.hpp>

#include <memory>

using namespace trephine;
using namespace trephine::ui;

namespace {

constexpr double kPaperClientFps = 990.0;

struct Gl {
    std::unique_ptr<Window> window;
    std::unique_ptr<Compositor> comp;
    std::string why;
    static Gl& get() {
        static Gl g = [] {
            Gl x;
            if (!displayAvailable(&x.why))
                return x;
            WindowConfig wc;
            wc.width = wc.height = 500;
            wc.visible = false;
            wc.imgui = false;
            x.window = std::make_unique<Window>(wc);
            x.comp = std::make_unique<Compositor>();
            return x;
        }();
        return g;
    }
};

Dbi testDbi(int size) {
    Dbi d(size, size);
    for (int y = 0; y < size; ++y)
        for (int x = 0; x < size; ++x) {
            uint8_t* c = d.color(x, y);
            c[0] = uint8_t(200 + x % 40), c[1] = uint8_t(190 + y % 40), c[2] = 170, c[3] = 255;
            d.depth()[d.index(x, y)] = 0.5f + 0.3f * float(x + y) / float(2 * size);
        }
    return d;
}

void BM_CompositeFrame500(benchmark::State& state) {
    Gl& gl = Gl::get();
    if (!gl.comp) {
        state.SkipWithError(("no display: " + gl.why).c_str());
        return;
    }
    Volume skull = makeSkull(128);
    SurfaceSite site = defaultBurrSite(skull);
    Camera cam = cameraLookingAt(site.position, site.normal, 170.0f, 45.0f, {500, 500}, skull);
    gl.comp->uploadFull(testDbi(500));
    GpuMesh field = gl.comp->upload(makeSurgicalField(skull, site));
    GpuMesh burr = gl.comp->upload(makeToolMesh(ToolShape::burr(5.0f)));
    GpuMesh perf = gl.comp->upload(makeToolMesh(ToolShape::perforator()));
    glm::mat4 a = glm::translate(glm::mat4(1), site.position) *
                  glm::mat4_cast(glm::rotation(glm::vec3(0, 0, 1), site.normal));
    glm::mat4 b = glm::translate(a, glm::vec3(15, 0, 5));
    for (auto _ : state) {
        gl.comp->begin(cam);
        gl.comp->draw(field, glm::mat4(1));
        gl.comp->draw(burr, a, {0.2f, 0.4f, 0.9f, 1});
        gl.comp->draw(perf, b, {0.9f, 0.4f, 0.2f, 1});
        gl.comp->blitTo(0, 0);
        glFinish(); // the frame is done, not just queued
    }
    state.counters["fps"] =
        benchmark::Counter(double(state.iterations()), benchmark::Counter::kIsRate);
    state.counters["paper_fps"] = kPaperClientFps;
    gl.comp->destroy(field);
    gl.comp->destroy(burr);
    gl.comp->destroy(perf);
}
BENCHMARK(BM_CompositeFrame500)->Unit(benchmark::kMillisecond)->UseRealTime();

// One image update: colour + float depth of a side x side rectangle into the DBI textures.
void BM_UploadRect(benchmark::State& state) {
    Gl& gl = Gl::get();
    if (!gl.comp) {
        state.SkipWithError(("no display: " + gl.why).c_str());
        return;
    }
    const int side = int(state.range(0));
    gl.comp->uploadFull(testDbi(500));
    Dbi patch = testDbi(side);
    int i = 0;
    for (auto _ : state) {
        int off = (i++ * 7) % (500 - side);
        gl.comp->uploadRect({off, off, side, side}, patch);
        glFinish();
    }
    state.SetBytesProcessed(int64_t(state.iterations()) * side * side * 8);
    state.counters["paper_frame_ms"] = 1000.0 / kPaperClientFps;
}
BENCHMARK(BM_UploadRect)->Arg(64)->Arg(128)->Arg(193)->Unit(benchmark::kMicrosecond)->UseRealTime();

} // namespace

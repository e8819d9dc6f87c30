// The image coding of one update on its own, without the session around it: the update study's
// 80^3 hole (paper camera, paper-spaced skull:128, 500^2 window), its BB_screen coded against the
// pixels the client held there before the cut. Encode (server) and decode (client) are timed
// apart, for the predicted form (zstd) and the planar form (lz4, zstd), with bytes and raw bytes.
#include "libsim/camera.h"
#include "libsim/dirty_rect.h"
#include "libsim/renderer.h"
#include "libsim/skull.h"
#include "libsim/thread_pool.h"
#include "net/codec.h"
#include "net/image_delta.h"

#include <benchmark/benchmark.h>

#include <map>
#include <memory>

using namespace trephine;
using namespace trephine::net;

namespace {

struct HoleImages {
    Camera camera;
    Dbi before; // BB_screen as the client holds it
    Dbi after;  // BB_screen after the cut
};

const HoleImages& holeImages(int n) {
    static std::map<int, std::unique_ptr<HoleImages>> cache;
    std::unique_ptr<HoleImages>& h = cache[n];
    if (!h) {
        h = std::make_unique<HoleImages>();
        Volume volume = makeSkull(128);
        volume.setSpacing(glm::vec3(paperSpacingMm(128)));
        h->camera = cameraPreset("paper", volume, {500, 500});
        ThreadPool pool(1);
        Renderer renderer(volume, &pool);
        const Dbi full = renderer.render(h->camera);
        const Box3i box = surfaceBox(volume, n);
        const PixelRect rect = dirtyScreenRect(h->camera, volume, box);
        h->before = full.extract(rect);
        volume.fill(box, 0, Material::Air);
        renderer.volumeChanged(box);
        h->after = renderer.render(h->camera).extract(rect);
    }
    return *h;
}

void predictedEncode(benchmark::State& state) {
    const HoleImages& h = holeImages(int(state.range(0)));
    const DepthQuantizer q(h.camera);
    PredictedImage p;
    for (auto _ : state) {
        p = encodePredicted(h.after, h.before, Codec::Zstd, q);
        benchmark::DoNotOptimize(p.payload.data());
    }
    state.counters["bytes"] = double(p.payload.size());
    state.counters["raw_bytes"] = double(p.rawBytes);
    state.counters["px"] = double(h.after.width()) * h.after.height();
}

void predictedDecode(benchmark::State& state) {
    const HoleImages& h = holeImages(int(state.range(0)));
    const DepthQuantizer q(h.camera);
    const PredictedImage p = encodePredicted(h.after, h.before, Codec::Zstd, q);
    Dbi image;
    for (auto _ : state) {
        state.PauseTiming();
        image = h.before;
        state.ResumeTiming();
        if (decodePredicted(p.payload, p.rawBytes, Codec::Zstd, p.baseHash, q, image) !=
            PredictedStatus::Ok)
            state.SkipWithError("decode failed");
    }
}

void planarEncode(benchmark::State& state, Codec codec) {
    const HoleImages& h = holeImages(int(state.range(0)));
    EncodedImage e;
    for (auto _ : state) {
        e = encodeImage(h.after, codec, h.camera);
        benchmark::DoNotOptimize(e.payload.data());
    }
    state.counters["bytes"] = double(e.payload.size());
    state.counters["raw_bytes"] = double(e.rawBytes);
}

void planarDecode(benchmark::State& state, Codec codec) {
    const HoleImages& h = holeImages(int(state.range(0)));
    const EncodedImage e = encodeImage(h.after, codec, h.camera);
    Dbi out;
    for (auto _ : state)
        if (!decodeImage(e.payload, e.rawBytes, codec, h.after.width(), h.after.height(), h.camera,
                         out))
            state.SkipWithError("decode failed");
}

} // namespace

BENCHMARK(predictedEncode)->Arg(40)->Arg(80)->Unit(benchmark::kMicrosecond);
BENCHMARK(predictedDecode)->Arg(40)->Arg(80)->Unit(benchmark::kMicrosecond);
BENCHMARK_CAPTURE(planarEncode, lz4, Codec::Lz4)->Arg(40)->Arg(80)->Unit(benchmark::kMicrosecond);
BENCHMARK_CAPTURE(planarDecode, lz4, Codec::Lz4)->Arg(40)->Arg(80)->Unit(benchmark::kMicrosecond);
BENCHMARK_CAPTURE(planarEncode, zstd, Codec::Zstd)->Arg(40)->Arg(80)->Unit(benchmark::kMicrosecond);
BENCHMARK_CAPTURE(planarDecode, zstd, Codec::Zstd)->Arg(40)->Arg(80)->Unit(benchmark::kMicrosecond);

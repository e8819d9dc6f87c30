// First pictures of a new view (issue 34, docs/session.md "Progressive first pictures"), skull:80.
// firstPicturesStep: the simulation step alone (no ENet), a new view's request to its preview
// posted and to its exact frame posted, with previews and without (StepConfig::previewPixels 0),
// in one run. firstPictures: over loopback on the threaded server, a client's view request to
// its first picture (the preview) and to its first exact picture, medians of 6 view changes, and
// to the exact picture of a view asked for again (4 changes back and forth: a kept view, docs/
// session.md "Kept views"), 1920 x 1080 and 2048 x 2048, alone or beside a 500^2 trainee drilling a
// state every 10 ms, whose update p99 is printed for the quiet half of its run and for the half the
// view changes fall in (target: first exact 1080p picture <= 0.25 s).
#include "libsim/skull.h"
#include "libsim/stats.h"
#include "net/executor.h"
#include "net/session_client.h"
#include "net/session_server.h"
#include "net/sim_step.h"
#include "net/view.h"

#include <benchmark/benchmark.h>
#include <glm/gtx/quaternion.hpp>

#include <algorithm>
#include <atomic>
#include <thread>
#include <vector>

using namespace trephine;
using namespace trephine::net;

namespace {

double median(std::vector<double> v) {
    if (v.empty())
        return 0;
    std::sort(v.begin(), v.end());
    return v[v.size() / 2];
}

// [SECTION] the step alone

// Steps a new width x height view until its last full image is coded: the seconds to the first
// full image ready to send and to the last (the exact frame), medians of 6 view changes after the
// join. Full images are coded on a worker of low priority, as the server's runner does.
void stepRun(const Volume& skull, int width, int height, int64_t previewPixels, double& firstS,
             double& exactS) {
    ReportBook book;
    Outbox outbox{1 << 30, book, steadyNowUs};
    WorkerExecutor coder{"bench-coder", 10};
    outbox.codeFullImagesApart(StepConfig{}.slicePixels + 1, coder);
    StepConfig config{0.05f, 10.0f, 2};
    config.previewPixels = previewPixels;
    SimulationStep step(skull, config, outbox, book, steadyNowUs);
    const Camera base = cameraPreset("paper", skull, {width, height});
    JoinEvent join{.client = 1, .view = toViewSpec(base), .volumeCodec = Codec::Lz4};
    join.inFlight = std::make_shared<std::atomic<int64_t>>(0);
    std::vector<LogRecord> batch{{0, join}};
    std::vector<double> firsts, exacts;
    uint64_t now = 1'000'000;
    const auto all = [](uint16_t) { return true; };
    for (uint32_t id = 0; id < 7; ++id) {
        if (id > 0) {
            ViewSpec moved = toViewSpec(base);
            moved.eye.x += 0.5f * float(id);
            batch = {{0, ViewEvent{1, moved, id}}};
        }
        const uint64_t t0 = steadyNowUs();
        double first = -1;
        do {
            step.step(batch, now += 10000);
            batch.clear();
            if (first < 0 && !outbox.take(all).updates.empty())
                first = double(steadyNowUs() - t0) * 1e-6;
        } while (step.rendering());
        outbox.finishCoding();
        outbox.take(all);
        const double exact = double(steadyNowUs() - t0) * 1e-6;
        if (id == 0)
            continue;                                // the join's frame pays its page faults once
        firsts.push_back(first < 0 ? exact : first); // none before: the exact frame came first
        exacts.push_back(exact);
    }
    firstS = median(firsts);
    exactS = median(exacts);
}

void firstPicturesStep(benchmark::State& state) {
    const Volume skull = makeSkull(80);
    const int width = int(state.range(0)), height = int(state.range(1));
    double firstS = 0, exactS = 0, plainS = 0, plainFirstS = 0;
    for (auto _ : state) {
        stepRun(skull, width, height, StepConfig{}.previewPixels, firstS, exactS);
        stepRun(skull, width, height, 0, plainFirstS, plainS);
    }
    state.counters["preview_s"] = firstS;
    state.counters["exact_s"] = exactS;
    state.counters["exact_without_preview_s"] = plainS;
    state.counters["preview_ratio"] = plainS > 0 ? firstS / plainS : 0;
    state.counters["exact_ratio"] = plainS > 0 ? exactS / plainS : 0;
}

// [SECTION] over loopback

// A 500^2 trainee drilling a state every 10 ms (ten 20 mm strokes, as bench_availability's) for
// `states` states; the update p99 of the first and of the second half.
struct Driller {
    double quietP99Us = 0, busyP99Us = 0;
    std::atomic<bool> halfway{false};

    void run(uint16_t port, const Volume& skull, int states) {
        ClientConfig cc;
        cc.name = "driller";
        cc.view = toViewSpec(cameraPreset("paper", skull, {500, 500}));
        SessionClient client(cc);
        client.connect(parseAddress("127.0.0.1:" + std::to_string(port)));
        const uint64_t j0 = steadyNowUs();
        while (!client.hasFullImage() && !client.closed() && steadyNowUs() - j0 < 30000000)
            client.poll(1);
        SampleWindow quiet(65536), busy(65536);
        client.setUpdateCallback([&](const ImageUpdate& u, const PixelRect&, bool full) {
            if (!full)
                (halfway ? busy : quiet).add(double(steadyNowUs() - u.causeServerUs));
        });
        const SurfaceSite site = defaultBurrSite(skull);
        const glm::vec3 n = site.normal;
        const glm::vec3 along = glm::normalize(glm::cross(n, glm::vec3(1, 0, 0)));
        const glm::vec3 across = glm::cross(n, along);
        const uint64_t start = steadyNowUs();
        for (int i = 0; i < states; ++i) {
            halfway = i >= states / 2;
            ToolState t;
            t.sequence = uint32_t(i + 1);
            t.clientTimeUs = 1000000 + uint64_t(i) * 10000;
            t.diameterMm = 5.0f;
            const int stroke = (i / 100) % 10;
            t.position = site.position - n * (1.0f + 2.5f * float(stroke / 5)) +
                         across * (5.5f * float(stroke % 5 - 2)) +
                         along * (0.2f * float(i % 100) - 10.0f);
            t.orientation = glm::rotation(glm::vec3(0, 0, 1), n);
            t.speed = 1.0f;
            t.drilling = true;
            client.sendToolState(t);
            while (steadyNowUs() < start + uint64_t(i + 1) * 10000)
                client.poll(1);
        }
        quietP99Us = quiet.size() ? quiet.percentile(99) : 0;
        busyP99Us = busy.size() ? busy.percentile(99) : 0;
        client.disconnect(50);
    }
};

// range(0) x range(1): the view; range(2): 1 with the drilling trainee beside it.
void firstPictures(benchmark::State& state) {
    const Volume skull = makeSkull(80);
    const int width = int(state.range(0)), height = int(state.range(1));
    const bool beside = state.range(2) != 0;
    std::vector<double> firsts, exacts, backs;
    Driller driller;
    for (auto _ : state) {
        ServerConfig config;
        config.port = 0;
        config.volumeName = "skull:80";
        SessionServer server(skull, config);
        server.start();
        std::thread drilling;
        if (beside)
            drilling = std::thread([&] { driller.run(server.port(), skull, 1200); });
        ClientConfig cc;
        cc.name = "viewer";
        cc.view = toViewSpec(cameraPreset("paper", skull, {width, height}));
        SessionClient client(cc);
        uint32_t asked = 0;
        uint64_t askedAt = 0, firstAt = 0, exactAt = 0;
        client.setUpdateCallback([&](const ImageUpdate& u, const PixelRect&, bool full) {
            if (!full || u.viewId != asked || !asked)
                return;
            const uint64_t now = steadyNowUs();
            if (!firstAt)
                firstAt = now;
            if (!exactAt && !u.preview)
                exactAt = now;
        });
        client.connect(parseAddress("127.0.0.1:" + std::to_string(server.port())));
        const uint64_t j0 = steadyNowUs();
        while (!client.hasFullImage() && !client.closed() && steadyNowUs() - j0 < 30000000)
            client.poll(1);
        // In the drilling trainee's second half when it is there; six view changes 0.4 s apart.
        while (beside && !driller.halfway)
            client.poll(1);
        // A view asked for, to its exact picture; the next asked 0.4 s after this one.
        auto ask = [&](float dx, std::vector<double>* first, std::vector<double>& exact) {
            ViewSpec moved = cc.view;
            moved.eye.x += dx;
            firstAt = exactAt = 0;
            askedAt = steadyNowUs();
            asked = client.requestView(moved);
            while (!exactAt && !client.closed() && steadyNowUs() - askedAt < 10000000)
                client.poll(1);
            if (first)
                first->push_back(double(firstAt - askedAt) * 1e-6);
            exact.push_back(double(exactAt - askedAt) * 1e-6);
            while (steadyNowUs() - askedAt < 400000)
                client.poll(1);
        };
        for (int i = 1; i <= 6; ++i)
            ask(0.5f * float(i), &firsts, exacts);
        // Back and forth between the last two views (a preset toggled): each was seen before.
        for (int i = 0; i < 4; ++i)
            ask(0.5f * float(5 + i % 2), nullptr, backs);
        client.disconnect(50);
        if (drilling.joinable())
            drilling.join();
    }
    state.counters["first_picture_s"] = median(firsts);
    state.counters["first_exact_s"] = median(exacts);
    state.counters["target_exact_s"] = 0.25;
    state.counters["exact_again_s"] = median(backs); // a view seen 0.4 s before (a kept view)
    if (beside) {
        state.counters["driller_quiet_p99_us"] = driller.quietP99Us;
        state.counters["driller_busy_p99_us"] = driller.busyP99Us;
        state.counters["driller_p99_ratio"] =
            driller.quietP99Us > 0 ? driller.busyP99Us / driller.quietP99Us : 0;
    }
}

} // namespace

BENCHMARK(firstPicturesStep)
    ->Args({1920, 1080})
    ->Args({2048, 2048})
    ->Iterations(1)
    ->UseRealTime()
    ->Unit(benchmark::kMillisecond);
BENCHMARK(firstPictures)
    ->Args({1920, 1080, 0})
    ->Args({1920, 1080, 1})
    ->Args({2048, 2048, 0})
    ->Args({2048, 2048, 1})
    ->Iterations(1)
    ->UseRealTime()
    ->Unit(benchmark::kMillisecond);

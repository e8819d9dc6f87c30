// The server's simulation step on its own: no ENet, no threads, no sleeps. A test hands it
// batches of events with the time, takes what it posted from the outbox and applies it as a
// client would, then compares with a fresh render of the step's volume.
#include "net/sim_step.h"

#include "counting_renderer.h"
#include "libsim/error.h"
#include "libsim/skull.h"
#include "libsim/tool.h"
#include "manual_executor.h"
#include "net/codec.h"
#include "net/view.h"

#include <gtest/gtest.h>

#include <malloc.h>

using namespace trephine;
using namespace trephine::net;
using trephine::testing::CountingRenderer;

namespace {

bool live(uint16_t) {
    return true;
}

struct StepRig {
    ReportBook book;
    Outbox outbox{1 << 30, book, steadyNowUs};
    Volume original;
    SimulationStep step;
    uint64_t now = 1'000'000;

    explicit StepRig(Volume v, DbiRendererFactory renderer = {})
        : StepRig(std::move(v), StepConfig{.maxStepS = 0.05f,
                                           .maxSweepMm = 10.0f,
                                           .renderThreads = 1,
                                           .renderer = std::move(renderer)}) {}
    StepRig(Volume v, const StepConfig& config)
        : original(v), step(std::move(v), config, outbox, book, steadyNowUs) {}

    void run(std::vector<LogRecord> batch) {
        now += 10000;
        step.step(batch, now);
    }
    LogRecord join(uint16_t id, const Camera& camera, Codec codec, Sync sync = Sync::Dbi) {
        JoinEvent ev{.client = id,
                     .view = toViewSpec(camera),
                     .codec = codec,
                     .sync = sync,
                     .volumeCodec = Codec::Lz4};
        ev.inFlight = std::make_shared<std::atomic<int64_t>>(0);
        return {0, ev};
    }
    LogRecord cut(const Box3i& box) { return {now, CutEvent{box}}; }
    uint64_t applied() const {
        return book.read([](const ServerReport& r) { return r.counters.toolStatesApplied; });
    }
};

// Applies an image update to `dbi` as SessionClient does (raw codec: bit for bit).
void applyImage(const Outbox::Ready& r, const Camera& camera, Dbi& dbi) {
    ImageUpdate u;
    ASSERT_TRUE(decodeMessage(r.message, u));
    Dbi patch;
    ASSERT_TRUE(decodeImage(u.payload, u.rawBytes, u.codec, u.width, u.height, camera, patch));
    if (u.full)
        dbi = patch;
    else
        dbi.apply(patch, u.x, u.y);
}

void applyVolume(const Outbox::Ready& r, Volume& copy, const Volume& like) {
    VolumeUpdate u;
    ASSERT_TRUE(decodeMessage(r.message, u));
    if (u.full) {
        ASSERT_TRUE(
            decodeVolumeFull(u.payload, u.rawBytes, u.codec, like.dims(), like.spacing(), copy));
        return;
    }
    std::vector<uint8_t> bytes;
    ASSERT_TRUE(decompressBytes(u.payload, u.codec, u.rawBytes, bytes));
    const Box3i box{{u.x, u.y, u.z}, {u.x + u.sizeX, u.y + u.sizeY, u.z + u.sizeZ}};
    ASSERT_TRUE(applyVolumeBox(copy, box, bytes));
}

// The CPU ray caster's pictures, each red level one off (a GPU's pixels differ from the CPU's
// within a tolerance), until its `failAt`th render; then it throws, as a GPU that runs out of
// memory or loses its device mid-session does, leaving the rectangle half done.
class FailingRenderer final : public DbiRenderer {
public:
    FailingRenderer(const Volume& v, ThreadPool* pool, int failAt)
        : m_cpu(v, pool), m_left(failAt) {}
    void volumeChanged(const Box3i& changed) override { m_cpu.volumeChanged(changed); }
    void rebuild() override { m_cpu.rebuild(); }
    void render(const Camera& camera, const PixelRect& rect, Dbi& frame, HitCache*) override {
        const PixelRect in = intersect(rect, frame.bounds());
        if (--m_left < 0) {
            frame.apply(Dbi(in.w, in.h), in.x, in.y);
            throw Error("gpu: the device was lost");
        }
        m_cpu.render(camera, rect, frame, nullptr);
        for (int y = in.y; y < in.y + in.h; ++y)
            for (int x = in.x; x < in.x + in.w; ++x)
                frame.color(x, y)[0] ^= 1;
    }
    Dbi render(const Camera& camera) override {
        Dbi d(camera.width, camera.height);
        render(camera, d.bounds(), d, nullptr);
        return d;
    }
    std::string describe() const override { return "GPU: failing"; }

private:
    CpuDbiRenderer m_cpu;
    int m_left;
};

size_t heapInUse() {
    const struct mallinfo2 m = mallinfo2();
    return m.uordblks + m.hblkhd;
}

} // namespace

// A DBI client joining gets its whole view; a cut gets it BB_screen only, and its copy is then a
// fresh render bit for bit. A volume client beside it gets the whole volume, then the box.
TEST(SimulationStep, JoinsGetTheWholeViewOrVolumeAndCutsOnlyWhatChanged) {
    StepRig rig(makeSphere(32));
    const Camera cam = cameraPreset("top", rig.original, {48, 48});
    rig.run({rig.join(1, cam, Codec::Raw), rig.join(2, cam, Codec::Raw, Sync::Volume)});
    Outbox::Taken t = rig.outbox.take(live);
    ASSERT_EQ(t.updates.size(), 2u);
    Dbi dbi;
    Volume copy;
    EXPECT_EQ(t.updates[0].mode, Sync::Dbi);
    EXPECT_TRUE(t.updates[0].full);
    applyImage(t.updates[0], cam, dbi);
    applyVolume(t.updates[1], copy, rig.original);
    EXPECT_TRUE(copy == rig.step.volume());
    EXPECT_EQ(rig.step.viewCount(), 1u);

    rig.run({rig.cut(surfaceBox(rig.original, 6))});
    t = rig.outbox.take(live);
    ASSERT_EQ(t.updates.size(), 2u);
    ImageUpdate u;
    ASSERT_TRUE(decodeMessage(t.updates[0].message, u));
    EXPECT_FALSE(u.full);
    EXPECT_LT(int(u.width) * u.height, 48 * 48) << "BB_screen, not the whole view";
    EXPECT_EQ(u.causeServerUs, rig.now - 10000) << "the cut's arrival";
    applyImage(t.updates[0], cam, dbi);
    applyVolume(t.updates[1], copy, rig.original);
    EXPECT_TRUE(compare(dbi, rig.step.render(cam)).identical());
    EXPECT_TRUE(copy == rig.step.volume());
    EXPECT_FALSE(rig.step.volume() == rig.original);

    // A switch to DBI: the volume client now gets the whole view, sharing the frame.
    rig.run({{0, SyncEvent{2, Sync::Dbi}}});
    t = rig.outbox.take(live);
    ASSERT_EQ(t.updates.size(), 1u);
    EXPECT_EQ(t.updates[0].client, 2);
    EXPECT_TRUE(t.updates[0].full);
    EXPECT_EQ(rig.step.viewCount(), 1u);
    // A view change to a smaller window: the full image of the new view, and nothing outside it.
    rig.run({{0, ViewEvent{1, toViewSpec(cameraPreset("top", rig.original, {24, 16})), 3}}});
    t = rig.outbox.take(live);
    ASSERT_EQ(t.updates.size(), 1u);
    ASSERT_TRUE(decodeMessage(t.updates[0].message, u));
    EXPECT_TRUE(u.full);
    EXPECT_EQ(u.viewId, 3u);
    EXPECT_EQ(u.width, 24);
    EXPECT_EQ(u.height, 16);
    EXPECT_EQ(rig.step.viewCount(), 2u) << "client 2 keeps the first view";
    // A leave: nothing more for it.
    rig.run({{0, LeaveEvent{2}}, rig.cut(surfaceBox(rig.original, 8))});
    t = rig.outbox.take(live);
    ASSERT_EQ(t.updates.size(), 1u);
    EXPECT_EQ(t.updates[0].client, 1);
    EXPECT_EQ(rig.step.viewCount(), 1u) << "the frame nobody holds is dropped";
}

// Two drilling tool states 6 mm apart: the step sweeps the burr along the path between them, so
// the bone half-way is cut although neither sampled pose reaches it; after a pause in drilling the
// next state is drilled where it is. A state older than the last applied is dropped.
TEST(SimulationStep, TheCutterSweepsBetweenDrillingToolStates) {
    StepRig rig(makeSphere(48));
    const Volume& sphere = rig.original;
    rig.run({rig.join(1, cameraPreset("top", sphere, {32, 32}), Codec::Raw)});
    const float top = sphereRadiusMm(48);
    auto state = [&](uint32_t seq, float x, float y, bool drilling) {
        ToolEvent ev{1, {}};
        ev.tool.sequence = seq;
        ev.tool.clientTimeUs = 1000000 + uint64_t(seq) * 20000;
        ev.tool.toolKind = uint8_t(ToolKind::Burr);
        ev.tool.diameterMm = 4.0f;
        ev.tool.position = {x, y, top - 1.0f};
        ev.tool.speed = 1.0f;
        ev.tool.drilling = drilling;
        return LogRecord{rig.now, ev};
    };
    auto cutAt = [&](float x, float y) {
        const glm::ivec3 v = glm::ivec3(glm::round(sphere.toVoxel({x, y, top - 1.0f})));
        return rig.step.volume().density(v.x, v.y, v.z) < sphere.density(v.x, v.y, v.z);
    };
    // A swept stroke along x at y = -5, then the drill lifted off, moved, and restarted at y = +5.
    rig.run({state(1, -3.0f, -5.0f, true), state(2, 3.0f, -5.0f, true)});
    rig.run({state(3, -3.0f, 5.0f, false)});
    rig.run({state(4, 3.0f, 5.0f, true)});
    EXPECT_EQ(rig.applied(), 4u);
    EXPECT_TRUE(cutAt(0.0f, -5.0f)) << "swept: the groove is continuous";
    EXPECT_TRUE(cutAt(3.0f, 5.0f)) << "drilled where it restarted";
    EXPECT_FALSE(cutAt(0.0f, 5.0f)) << "no sweep across a pause in drilling";
    EXPECT_FALSE(cutAt(-3.0f, 5.0f)) << "nor where the drill was off";

    const Volume before = rig.step.volume();
    rig.run({state(2, 0.0f, 0.0f, true)});
    EXPECT_EQ(rig.applied(), 4u) << "late: newest wins";
    EXPECT_TRUE(rig.step.volume() == before);
}

// A drilling trainee's large view, whose changed pixels are rendered a chunk a step while it
// drills on (events always wait): each chunk's re-render keeps the pixels whose cached hit is
// clear of every change since they were rendered, not only the newest, so the client's copy is a
// fresh render bit for bit whenever the step has caught up, and at the end.
TEST(SimulationStep, ChangesPiledUpWhileAViewRendersAreAllKeptInMind) {
    StepRig rig(makeSphere(48), StepConfig{.renderThreads = 1,
                                           .slicePixels = 1024,
                                           .chunkPixels = 32,
                                           .previewPixels = 0,
                                           .yield = [] { return true; }});
    const Volume& sphere = rig.original;
    const Camera cam = cameraPreset("top", sphere, {64, 64});
    Dbi dbi;
    auto runAndApply = [&](std::vector<LogRecord> batch) {
        rig.run(std::move(batch));
        for (const Outbox::Ready& r : rig.outbox.take(live).updates)
            applyImage(r, cam, dbi);
    };
    runAndApply({rig.join(1, cam, Codec::Raw)});
    for (int i = 0; i < 200 && rig.step.rendering(); ++i)
        runAndApply({});
    ASSERT_TRUE(compare(dbi, rig.step.render(cam)).identical());
    const float top = sphereRadiusMm(48);
    int caughtUp = 0;
    // Strokes far apart, one tool state a step: a stroke's rows are still to render when the next
    // lands elsewhere.
    for (uint32_t seq = 1; seq <= 24; ++seq) {
        ToolEvent ev{1, {}};
        ev.tool.sequence = seq;
        ev.tool.clientTimeUs = 1000000 + uint64_t(seq) * 20000;
        ev.tool.toolKind = uint8_t(ToolKind::Burr);
        ev.tool.diameterMm = 3.0f;
        const float x = seq % 2 ? -6.0f : 6.0f, y = -6.0f + 0.5f * float(seq);
        ev.tool.position = {x, y, top - 1.0f};
        ev.tool.speed = 1.0f;
        ev.tool.drilling = seq % 4 != 0; // lifted now and then: no sweep across the sphere
        runAndApply({{rig.now, ev}});
        if (!rig.step.rendering()) {
            ++caughtUp;
            ASSERT_TRUE(compare(dbi, rig.step.render(cam)).identical()) << "state " << seq;
        }
    }
    for (int i = 0; i < 200 && rig.step.rendering(); ++i)
        runAndApply({});
    EXPECT_FALSE(rig.step.rendering());
    EXPECT_FALSE(rig.step.volume() == rig.original) << "the strokes should have cut";
    EXPECT_TRUE(compare(dbi, rig.step.render(cam)).identical());
    EXPECT_LT(caughtUp, 24) << "changes should have piled up";
    EXPECT_GT(rig.book.counter(&ServerCounters::pixelsKept), 0u) << "re-renders kept pixels";
}

// A view nobody holds any more is handed whole to the freer, which frees it as its task goes, not
// in the step (a 2048 x 2048 view's frame, hit cache and preview took 4-7 ms); a view changed to
// one of the same size keeps the frame, and nothing goes. (Views are not kept here.)
TEST(SimulationStep, ADroppedViewIsFreedByTheFreerAndASameSizedOneIsReused) {
    trephine::testing::ManualExecutor freer; // outlives the step that holds it
    StepRig rig(makeSphere(32), StepConfig{.renderThreads = 1, .keepViewUs = 0});
    rig.step.renderBulkApart(10, freer);
    const Camera big = cameraPreset("top", rig.original, {256, 256});
    rig.run({rig.join(1, big, Codec::Raw)});
    rig.outbox.take(live);
    rig.run({{0, ViewEvent{1, toViewSpec(cameraPreset("front", rig.original, {256, 256})), 2}}});
    rig.outbox.take(live);
    EXPECT_TRUE(freer.tasks.empty()) << "the same size: the frame is reused";

    const Camera small = cameraPreset("front", rig.original, {24, 16});
    rig.run({{0, ViewEvent{1, toViewSpec(small), 3}}});
    ASSERT_EQ(freer.tasks.size(), 1u);
    Outbox::Taken t = rig.outbox.take(live);
    ASSERT_EQ(t.updates.size(), 1u);
    Dbi dbi;
    applyImage(t.updates[0], small, dbi);
    EXPECT_TRUE(compare(dbi, rig.step.render(small)).identical());

    const int64_t held = int64_t(heapInUse());
    freer.tasks.clear();
    EXPECT_GE(held - int64_t(heapInUse()), int64_t(256) * 256 * 8)
        << "the task owned the 256 x 256 frame";
}

// A view its last client lets go (here, a switch to volume) is kept: nothing renders it, but what
// changes is noted, so the switch back gets the whole view for the re-render of the changed
// rectangle alone, and it is a fresh render bit for bit. Its time over, it goes to the freer.
TEST(SimulationStep, AViewLetGoIsKeptAndTakenUpAgainForItsChangesOnly) {
    trephine::testing::ManualExecutor freer;
    auto pixels = std::make_shared<uint64_t>(0);
    StepRig rig(makeSphere(32), StepConfig{.renderThreads = 1,
                                           .keepViewUs = 5'000'000,
                                           .renderer = [pixels](const Volume& v, ThreadPool* pool) {
                                               return std::make_unique<CountingRenderer>(v, pool,
                                                                                         pixels);
                                           }});
    rig.step.renderBulkApart(10, freer);
    const Camera cam = cameraPreset("top", rig.original, {48, 48});
    rig.run({rig.join(1, cam, Codec::Raw)});
    rig.outbox.take(live);
    EXPECT_EQ(*pixels, 48u * 48u);

    rig.run({{0, SyncEvent{1, Sync::Volume}}});
    rig.outbox.take(live);
    EXPECT_EQ(rig.step.viewCount(), 0u);
    EXPECT_EQ(rig.step.keptViewCount(), 1u);
    rig.run({rig.cut(surfaceBox(rig.original, 6))});
    rig.run({rig.cut(surfaceBox(rig.original, 8))});
    rig.outbox.take(live);
    EXPECT_EQ(*pixels, 48u * 48u) << "a kept view is not rendered";

    rig.run({{0, SyncEvent{1, Sync::Dbi}}});
    Outbox::Taken t = rig.outbox.take(live);
    ASSERT_EQ(t.updates.size(), 1u);
    EXPECT_TRUE(t.updates[0].full);
    Dbi dbi;
    applyImage(t.updates[0], cam, dbi);
    EXPECT_TRUE(compare(dbi, rig.step.render(cam)).identical());
    const int64_t rerendered = int64_t(*pixels) - 48 * 48;
    EXPECT_GT(rerendered, 0) << "the cuts are in view";
    EXPECT_LT(rerendered, 48 * 48 / 2) << "only the changed rectangle";
    EXPECT_EQ(rig.book.counter(&ServerCounters::viewsReused), 1u);
    EXPECT_EQ(rig.step.keptViewCount(), 0u);

    rig.run({{0, LeaveEvent{1}}});
    EXPECT_EQ(rig.step.keptViewCount(), 1u);
    EXPECT_TRUE(freer.tasks.empty());
    rig.now += 5'000'000;
    rig.run({});
    EXPECT_EQ(rig.step.keptViewCount(), 0u);
    EXPECT_EQ(freer.tasks.size(), 1u) << "its time over, the kept view is freed";
}

// Past keptPixels, the kept views go oldest first from the peer keeping the most: a peer that
// changes views every frame spends its own kept views, not another's older one.
TEST(SimulationStep, KeptViewsPastTheirPixelsGoFromThePeerKeepingTheMost) {
    constexpr int64_t kView = StepConfig::kKeptViewFloorPixels; // what a 32 x 32 view counts
    StepRig rig(makeSphere(32), StepConfig{.renderThreads = 1, .keptPixels = 3 * kView});
    auto eye = [&](float dx) {
        ViewSpec s = toViewSpec(cameraPreset("top", rig.original, {32, 32}));
        s.eye.x += dx;
        return s;
    };
    rig.run({rig.join(1, toCamera(eye(0)), Codec::Raw),
             rig.join(2, cameraPreset("front", rig.original, {32, 32}), Codec::Raw)});
    rig.run({{0, SyncEvent{2, Sync::Volume}}}); // the oldest kept view: client 2's
    for (uint32_t i = 1; i <= 3; ++i)           // client 1's views 0, 1, 2 kept
        rig.run({{0, ViewEvent{1, eye(float(i)), i}}});
    EXPECT_EQ(rig.step.keptViewCount(), 3u) << "client 1's oldest went";

    rig.run({{0, SyncEvent{2, Sync::Dbi}}});
    EXPECT_EQ(rig.book.counter(&ServerCounters::viewsReused), 1u) << "client 2's was kept";
    rig.run({{0, ViewEvent{1, eye(0), 4}}});
    EXPECT_EQ(rig.book.counter(&ServerCounters::viewsReused), 1u) << "client 1's oldest is gone";
    const uint64_t renders = rig.book.counter(&ServerCounters::renders);
    rig.run({{0, ViewEvent{1, eye(1), 5}}});
    EXPECT_EQ(rig.book.counter(&ServerCounters::viewsReused), 2u);
    EXPECT_EQ(rig.book.counter(&ServerCounters::renders), renders) << "nothing changed in it";

    // A view taken up is held, not kept, whatever the budget: with room for one kept view,
    // toggling between two renders neither again.
    StepRig one(makeSphere(32), StepConfig{.renderThreads = 1, .keptPixels = kView});
    one.run({one.join(1, toCamera(eye(0)), Codec::Raw)});
    for (uint32_t i = 1; i <= 4; ++i)
        one.run({{0, ViewEvent{1, eye(float(i % 2)), i}}});
    EXPECT_EQ(one.book.counter(&ServerCounters::renders), 2u);
    EXPECT_EQ(one.book.counter(&ServerCounters::viewsReused), 3u);

    // A newcomer given the id of a peer gone does not spend that peer's kept view.
    StepRig two(makeSphere(32), StepConfig{.renderThreads = 1, .keptPixels = 2 * kView});
    two.run({two.join(1, toCamera(eye(0)), Codec::Raw)});
    two.run({{0, LeaveEvent{1}}});
    two.run({two.join(1, toCamera(eye(1)), Codec::Raw)});
    for (uint32_t i = 2; i <= 3; ++i) // its views 1, 2 kept: one too many
        two.run({{0, ViewEvent{1, eye(float(i)), i}}});
    two.run({{0, ViewEvent{1, eye(0), 4}}});
    EXPECT_EQ(two.book.counter(&ServerCounters::viewsReused), 1u) << "the gone peer's is kept";
}

// A configured renderer (the GPU's) that fails mid-session: the render it failed and every one
// after are the CPU's, the view's other pixels are rendered again and sent, so the client's copy
// is a fresh CPU render bit for bit once the step is done; the report counts the fallback once.
TEST(SimulationStep, AConfiguredRendererThatFailsGivesWayToTheCpus) {
    StepRig rig(makeSphere(32), [](const Volume& v, ThreadPool* pool) {
        return std::make_unique<FailingRenderer>(v, pool, 1);
    });
    const Camera cam = cameraPreset("top", rig.original, {48, 48});
    Dbi dbi;
    auto runAndApply = [&](std::vector<LogRecord> batch) {
        rig.run(std::move(batch));
        for (int i = 0; i < 50 && rig.step.rendering(); ++i)
            rig.run({});
        for (const Outbox::Ready& r : rig.outbox.take(live).updates)
            applyImage(r, cam, dbi);
    };
    runAndApply({rig.join(1, cam, Codec::Raw)});
    EXPECT_FALSE(compare(dbi, Renderer(rig.step.volume()).render(cam)).identical())
        << "the failing renderer's own pictures first";
    EXPECT_EQ(rig.step.rendererName(), "GPU: failing");
    for (int i = 6; i <= 8; ++i) {
        SCOPED_TRACE(i);
        runAndApply({rig.cut(surfaceBox(rig.original, i))});
        EXPECT_TRUE(compare(dbi, Renderer(rig.step.volume()).render(cam)).identical());
    }
    EXPECT_EQ(rig.book.counter(&ServerCounters::rendererFallbacks), 1u);
    EXPECT_EQ(rig.step.rendererName(), "CPU, 1 thread");
}

// One that cannot even be made (a volume too large for the GPU): the CPU's renders from the start.
TEST(SimulationStep, AConfiguredRendererThatCannotBeMadeGivesWayToTheCpus) {
    StepRig rig(makeSphere(32), [](const Volume&, ThreadPool*) -> std::unique_ptr<DbiRenderer> {
        throw Error("gpu: OpenGL refused the volume's textures: out of memory");
    });
    const Camera cam = cameraPreset("top", rig.original, {48, 48});
    rig.run({rig.join(1, cam, Codec::Raw)});
    Dbi dbi;
    for (const Outbox::Ready& r : rig.outbox.take(live).updates)
        applyImage(r, cam, dbi);
    EXPECT_TRUE(compare(dbi, Renderer(rig.step.volume()).render(cam)).identical());
    EXPECT_EQ(rig.book.counter(&ServerCounters::rendererFallbacks), 1u);
}

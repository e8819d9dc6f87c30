// Progressive first pictures (docs/session.md): a new view larger than StepConfig::previewPixels
// gets a half-resolution preview, upsampled, as its first full image, then the exact frame, which
// is a full render bit for bit. The step is driven directly (no ENet) but for the last test, which
// runs a client over loopback against a pumped server.
#include "net/sim_step.h"

#include "counting_renderer.h"
#include "libsim/dbi_preview.h"
#include "libsim/skull.h"
#include "loopback.h"
#include "net/codec.h"
#include "net/view.h"

#include <gtest/gtest.h>

#include <memory>
#include <vector>

using namespace trephine;
using namespace trephine::net;
using trephine::testing::CountingRenderer;

namespace {

constexpr int64_t kPreviewAbove = 64 * 64;
constexpr int64_t kChunk = 256 * 4;

// A step whose views of more than 64 x 64 pixels get previews, slices of 128^2 pixels, chunks of
// 1024, with raw clients (bit for bit) and the pixel clock.
struct PreviewRig {
    std::shared_ptr<uint64_t> pixels = std::make_shared<uint64_t>(0);
    ReportBook book;
    Outbox outbox{1 << 30, book, steadyNowUs};
    bool eventsWait = false; // what the step's `yield` says
    SimulationStep step;
    uint64_t now = 1'000'000;

    explicit PreviewRig(Volume v)
        : step(std::move(v),
               StepConfig{.maxStepS = 0.05f,
                          .maxSweepMm = 10.0f,
                          .renderThreads = 1,
                          .slicePixels = 128 * 128,
                          .chunkPixels = kChunk,
                          .previewPixels = kPreviewAbove,
                          .workClock = [p = pixels] { return *p; },
                          .yield = [this] { return eventsWait; },
                          .renderer =
                              [p = pixels](const Volume& vol, ThreadPool* pool) {
                                  return std::make_unique<CountingRenderer>(vol, pool, p);
                              }},
               outbox, book, steadyNowUs) {}
    LogRecord join(uint16_t id, const Camera& camera) {
        JoinEvent ev{.client = id, .view = toViewSpec(camera), .volumeCodec = Codec::Lz4};
        ev.inFlight = std::make_shared<std::atomic<int64_t>>(0);
        return {0, ev};
    }
    std::vector<Outbox::Ready> run(std::vector<LogRecord> batch) {
        now += 10000;
        step.step(batch, now);
        outbox.finishCoding();
        return outbox.take([](uint16_t) { return true; }).updates;
    }
};

// A full image or rectangle a client got, decoded (a preview shown as a client does, its pixels
// as 2 x 2 blocks).
struct Got {
    ImageUpdate update;
    Dbi pixels;
    int step = 0; // the rig's step it came in
};

std::vector<Got> imagesOf(const std::vector<Outbox::Ready>& updates, uint16_t id,
                          const Camera& camera, int step) {
    std::vector<Got> out;
    for (const Outbox::Ready& r : updates) {
        if (r.client != id)
            continue;
        Got g;
        g.step = step;
        EXPECT_TRUE(decodeMessage(r.message, g.update));
        const Camera coded = g.update.preview ? previewCamera(camera) : camera;
        EXPECT_TRUE(decodeImage(g.update.payload, g.update.rawBytes, g.update.codec, g.update.width,
                                g.update.height, coded, g.pixels));
        if (g.update.preview) {
            Dbi blocks(camera.width, camera.height);
            upsampleRows(g.pixels, 0, g.pixels.height(), blocks);
            g.pixels = std::move(blocks);
        }
        out.push_back(std::move(g));
    }
    return out;
}

// Steps until nothing is left to render, gathering client `id`'s images of `camera`.
std::vector<Got> runToTheEnd(PreviewRig& rig, uint16_t id, const Camera& camera,
                             std::vector<LogRecord> first = {}) {
    std::vector<Got> got;
    std::vector<LogRecord> batch = std::move(first);
    for (int step = 0; step == 0 || (rig.step.rendering() && step < 1000); ++step) {
        for (Got& g : imagesOf(rig.run(std::move(batch)), id, camera, step))
            got.push_back(std::move(g));
        batch.clear();
    }
    return got;
}

// What a view's preview is: the half-size render, each pixel a 2 x 2 block.
Dbi expectedPreview(SimulationStep& step, const Camera& view) {
    const Dbi half = step.render(previewCamera(view));
    Dbi full(view.width, view.height);
    upsampleRows(half, 0, half.height(), full);
    return full;
}

} // namespace

// A large new view's first full image is the upsampled preview, in an earlier step than the
// exact frame, which follows as a second full image equal to the full render bit for bit. Both
// are charged to the view's peer: the preview costs a quarter of the view's rays.
TEST(ProgressivePictures, ALargeNewViewGetsItsPreviewFirstThenTheExactFrame) {
    const Volume skull = makeSkull(48);
    PreviewRig rig(skull);
    const Camera view = cameraPreset("paper", skull, {160, 120});
    const std::vector<Got> got = runToTheEnd(rig, 1, view, {rig.join(1, view)});
    ASSERT_EQ(got.size(), 2u) << "the preview, then the exact frame";
    EXPECT_TRUE(got[0].update.full);
    EXPECT_TRUE(got[1].update.full);
    EXPECT_LT(got[0].step, got[1].step);
    const Dbi exact = rig.step.render(view);
    EXPECT_TRUE(compare(got[0].pixels, expectedPreview(rig.step, view)).identical());
    EXPECT_FALSE(compare(got[0].pixels, exact).identical()) << "a preview, not the picture";
    EXPECT_TRUE(compare(got[1].pixels, exact).identical());
    EXPECT_TRUE(got[0].update.preview) << "said to be one";
    EXPECT_EQ(got[0].update.width, 80) << "sent at half size";
    EXPECT_EQ(got[0].update.height, 60);
    EXPECT_FALSE(got[1].update.preview);
    EXPECT_EQ(rig.step.share().charged(1), uint64_t(160 * 120 + 80 * 60));
}

// A view of at most StepConfig::previewPixels renders whole quickly: one exact full image.
TEST(ProgressivePictures, ASmallViewGetsNoPreview) {
    const Volume skull = makeSkull(48);
    PreviewRig rig(skull);
    const Camera view = cameraPreset("paper", skull, {64, 64});
    const std::vector<Got> got = runToTheEnd(rig, 1, view, {rig.join(1, view)});
    ASSERT_EQ(got.size(), 1u);
    EXPECT_TRUE(got[0].update.full);
    EXPECT_TRUE(compare(got[0].pixels, rig.step.render(view)).identical());
    EXPECT_EQ(rig.step.share().charged(1), uint64_t(64 * 64)) << "no preview rendered";
}

// A view changed before its exact picture (once during its preview, once after the preview was
// sent): nothing of a view left is sent after the change, and the newest view gets its own
// preview and exact frame.
TEST(ProgressivePictures, AViewChangedBeforeItsExactPictureGetsNothingOfTheOldView) {
    const Volume skull = makeSkull(48);
    PreviewRig rig(skull);
    rig.eventsWait = true; // a chunk a step: the changes land mid-way
    const Camera first = cameraPreset("paper", skull, {160, 120});
    const Camera second = cameraPreset("top", skull, {160, 120});
    const Camera third = cameraPreset("front", skull, {160, 120});
    EXPECT_TRUE(rig.run({rig.join(1, first)}).empty());
    EXPECT_TRUE(rig.step.rendering()) << "the preview takes several chunks";
    // During the first view's preview.
    std::vector<Got> got =
        imagesOf(rig.run({{0, ViewEvent{1, toViewSpec(second), 1}}}), 1, second, 0);
    EXPECT_TRUE(got.empty());
    // Until the second view's preview has been sent, then to the third.
    for (int i = 0; got.empty() && i < 100; ++i)
        got = imagesOf(rig.run({}), 1, second, 0);
    ASSERT_EQ(got.size(), 1u);
    EXPECT_EQ(got[0].update.viewId, 1u);
    EXPECT_TRUE(compare(got[0].pixels, expectedPreview(rig.step, second)).identical());
    rig.eventsWait = false;
    got = runToTheEnd(rig, 1, third, {{0, ViewEvent{1, toViewSpec(third), 2}}});
    ASSERT_EQ(got.size(), 2u);
    for (const Got& g : got)
        EXPECT_EQ(g.update.viewId, 2u) << "nothing of the second view after the change";
    EXPECT_TRUE(compare(got[0].pixels, expectedPreview(rig.step, third)).identical());
    EXPECT_TRUE(compare(got[1].pixels, rig.step.render(third)).identical());
}

// While a newcomer's view previews, with events always waiting, a drilling peer's rectangle goes
// in every step and the preview takes one chunk a step, charged to the newcomer.
TEST(ProgressivePictures, APreviewGoesAPieceAStepChargedToItsPeer) {
    const Volume skull = makeSkull(48);
    PreviewRig rig(skull);
    const Camera small = cameraPreset("top", skull, {64, 64});
    const Camera large = cameraPreset("paper", skull, {160, 120});
    Dbi seen;
    {
        const std::vector<Got> joined = runToTheEnd(rig, 1, small, {rig.join(1, small)});
        ASSERT_EQ(joined.size(), 1u);
        seen = joined[0].pixels;
    }
    rig.eventsWait = true;
    std::vector<LogRecord> batch{rig.join(2, large)};
    int steps = 0;
    bool previewed = false;
    for (; !previewed && steps < 100; ++steps) {
        Box3i box{skull.dims() / 2 - glm::ivec3(6), skull.dims() / 2 + glm::ivec3(6)};
        box.lo.z = skull.dims().z - 12 - steps % 6; // deeper each step: a change every step
        box.hi.z = skull.dims().z;
        batch.push_back({rig.now, CutEvent{box}});
        const uint64_t charged = rig.step.share().charged(2);
        const std::vector<Outbox::Ready> out = rig.run(std::move(batch));
        batch.clear();
        const std::vector<Got> mine = imagesOf(out, 1, small, steps);
        ASSERT_EQ(mine.size(), 1u) << "step " << steps;
        seen.apply(mine[0].pixels, mine[0].update.x, mine[0].update.y);
        EXPECT_LE(rig.step.share().charged(2) - charged, uint64_t(kChunk)) << "step " << steps;
        previewed = !imagesOf(out, 2, large, steps).empty();
    }
    EXPECT_TRUE(previewed);
    EXPECT_GE(steps, 80 * 60 / kChunk) << "a chunk a step";
    EXPECT_EQ(rig.step.share().charged(2), uint64_t(80 * 60)) << "the preview, all its own";
    EXPECT_TRUE(compare(seen, rig.step.render(small)).identical());
}

// Over loopback: a client asking for a view larger than a slice shows the upsampled preview as
// soon as it comes (its first full image), then holds the server's full render bit for bit.
TEST(ProgressivePictures, AClientShowsThePreviewThenHoldsTheExactFrame) {
    const Volume skull = makeSkull(48);
    SessionServer server(skull, trephine::testing::loopbackServerConfig("skull:48", 2));
    trephine::testing::Pumped pumped(server);
    ClientConfig cc;
    cc.codec = Codec::Raw;
    cc.view = toViewSpec(cameraPreset("paper", skull, {640, 480})); // over 512^2 pixels
    ASSERT_GT(int64_t(640) * 480, StepConfig{}.previewPixels);
    SessionClient client(cc);
    std::vector<Dbi> shown;                 // the client's picture after each full image
    std::vector<std::pair<bool, bool>> had; // hasPicture(), hasFullImage() after each
    client.setUpdateCallback([&](const ImageUpdate&, const PixelRect&, bool full) {
        if (full) {
            shown.push_back(client.dbi());
            had.emplace_back(client.hasPicture(), client.hasFullImage());
        }
    });
    client.connect(trephine::testing::loopback(server.port()));
    ASSERT_TRUE(trephine::testing::pumpUntil({&client},
                                             [&] { return shown.size() >= 2 && server.idle(); }));
    EXPECT_EQ(shown.size(), 2u);
    EXPECT_EQ(had.front(), std::make_pair(true, false)) << "a picture to show, not the exact one";
    EXPECT_EQ(had.back(), std::make_pair(true, true));
    Dbi preview(640, 480);
    const Dbi half = server.renderView(toViewSpec(previewCamera(toCamera(cc.view))));
    upsampleRows(half, 0, half.height(), preview);
    EXPECT_TRUE(compare(shown.front(), preview).identical()) << "the preview, shown at once";
    const Dbi exact = server.renderView(cc.view);
    EXPECT_TRUE(compare(shown.back(), exact).identical());
    EXPECT_TRUE(compare(client.dbi(), exact).identical());
}

// Drilling rectangles as lossy state (docs/protocol.md, "Lossy rectangles"): the outbox on its own
// with a clock the test moves (what a rectangle carries, repairs, acknowledgements, the window),
// then a SessionClient fed by a fake server in every order the two image channels allow.
#include "net/outbox.h"
#include "net/scene.h"
#include "net/session_client.h"
#include "net/view.h"

#include "libsim/dbi_preview.h"
#include "libsim/skull.h"
#include "net/codec.h"
#include "net/image_delta.h"

#include "loopback.h"

#include <gtest/gtest.h>

#include <memory>

using namespace trephine;
using namespace trephine::net;

namespace {

// [SECTION] the outbox

struct Clock {
    std::shared_ptr<uint64_t> now = std::make_shared<uint64_t>(1'000'000);
    ServerClock fn() const {
        return [t = now] { return *t; };
    }
    void advance(uint64_t us) const { *now += us; }
};

bool live(uint16_t) {
    return true;
}

Camera cameraFor(int width, int height) {
    return cameraPreset("top", makeSphere(16), {width, height});
}

// A picture with every pixel its own colour and depth; `seed` changes them all.
Dbi picture(int width, int height, int seed) {
    Dbi d(width, height);
    for (int y = 0; y < height; ++y)
        for (int x = 0; x < width; ++x) {
            uint8_t* c = d.color(x, y);
            c[0] = uint8_t(x * 7 + seed);
            c[1] = uint8_t(y * 3 + seed);
            c[2] = uint8_t(x + y + seed);
            c[3] = 255;
            d.depth()[d.index(x, y)] = 0.5f + 0.001f * float((x + 2 * y + seed) % 300);
        }
    return d;
}

Dbi with(const Dbi& frame, const Dbi& from, PixelRect rect) {
    Dbi out = frame;
    out.apply(from.extract(rect), rect.x, rect.y);
    return out;
}

ImageUpdate decoded(const Outbox::Ready& r) {
    ImageUpdate u;
    EXPECT_TRUE(decodeMessage(r.message, u));
    return u;
}

// A raw client's copy: what it applies is exact.
void applyTo(Dbi& dbi, const Outbox::Ready& r, const Camera& camera) {
    const ImageUpdate u = decoded(r);
    ASSERT_FALSE(u.predicted);
    Dbi patch;
    ASSERT_TRUE(decodeImage(u.payload, u.rawBytes, u.codec, u.width, u.height, camera, patch));
    if (u.full)
        dbi = patch;
    else
        dbi.apply(patch, u.x, u.y);
}

struct Rig {
    Clock clock;
    ReportBook book;
    Outbox outbox;
    Camera cam = cameraFor(64, 48);
    Dbi frame = picture(64, 48, 0);
    Channel fullChannel = Channel::Control; // the last full image's, and the loss of its parity
    uint32_t fullLoss = 0;
    explicit Rig(int64_t maxInFlight = 1 << 20, Codec codec = Codec::Raw)
        : outbox(maxInFlight, book, clock.fn()) {
        outbox.join(1, std::make_shared<std::atomic<int64_t>>(0), codec, Codec::Lz4);
    }
    // Posts the whole frame and takes it: the full image rectangles build on, acknowledged as a
    // client does when it arrives unless `acknowledged` is false.
    ImageUpdate full(bool acknowledged = true) {
        outbox.postImage(1, cam, frame, frame.bounds(), true, 1, {});
        Outbox::Taken t = outbox.take(live);
        EXPECT_EQ(t.updates.size(), 1u);
        fullChannel = t.updates.at(0).channel;
        fullLoss = t.updates.at(0).lossPermille;
        const ImageUpdate u = decoded(t.updates.at(0));
        if (acknowledged)
            outbox.acknowledge(1, ImageAck{u.viewId, u.sequence});
        return u;
    }
    // Changes `rect` (new pixels of `seed`), posts it and takes what goes.
    Outbox::Taken cut(PixelRect rect, int seed) {
        frame = with(frame, picture(64, 48, seed), rect);
        outbox.postImage(1, cam, frame, rect, false, 2, {});
        return outbox.take(live);
    }
    // The client holds image `held` and reports `unusable`, chained on one it lacks; the step's
    // repair (SimulationStep::postRepairs) posts the frame with no change, and it is taken.
    Outbox::Taken reportLoss(uint32_t held, uint32_t unusable) {
        outbox.acknowledge(1, ImageAck{0, held, unusable});
        EXPECT_EQ(outbox.repairsWanted(), std::vector<uint16_t>{1});
        outbox.postImage(1, cam, frame, {}, false, 0, {});
        EXPECT_TRUE(outbox.repairsWanted().empty());
        return outbox.take(live);
    }
};

PixelRect rectOf(const ImageUpdate& u) {
    return {u.x, u.y, u.width, u.height};
}

} // namespace

// After a full image each rectangle goes lossy, names that full image and is chained: it carries
// its own pixels and builds on the one before it, so a client that got them all holds the frame.
TEST(LossyOutbox, RectanglesAreChainedWhileNoLossIsReported) {
    Rig rig;
    const ImageUpdate f = rig.full();
    Dbi client = rig.frame;
    const PixelRect a{4, 4, 10, 6}, b{30, 20, 8, 8};
    Outbox::Taken t = rig.cut(a, 1);
    ASSERT_EQ(t.updates.size(), 1u);
    EXPECT_EQ(t.updates[0].channel, Channel::ImageLossy);
    const ImageUpdate first = decoded(t.updates[0]);
    EXPECT_EQ(first.fullSequence, f.sequence);
    EXPECT_EQ(first.baseSequence, f.sequence);
    EXPECT_EQ(rectOf(first), a);
    applyTo(client, t.updates[0], rig.cam);
    t = rig.cut(b, 2);
    ASSERT_EQ(t.updates.size(), 1u);
    const ImageUpdate second = decoded(t.updates[0]);
    EXPECT_EQ(second.baseSequence, first.sequence) << "unacknowledged, still built on";
    EXPECT_EQ(rectOf(second), b);
    applyTo(client, t.updates[0], rig.cam);
    EXPECT_TRUE(compare(client, rig.frame).identical());
    EXPECT_TRUE(rig.outbox.repairsWanted().empty());
}

// A client that lost a chained rectangle reports the next as unusable: the repair carries every
// rectangle not acknowledged at current pixels, and the frame is exact from it. The rectangles
// after it are chained on it (parity makes a lost one rare; carrying every unacknowledged one
// filled a 20 Mbit/s link at 80^3).
TEST(LossyOutbox, AReportedLossIsRepairedSelfContainedAndTheChainGoesOn) {
    Rig rig;
    const ImageUpdate f = rig.full();
    Dbi client = rig.frame;
    const PixelRect a{4, 4, 10, 6}, b{30, 20, 8, 8}, c{50, 2, 6, 6}, d{40, 30, 4, 4};
    rig.cut(a, 1); // lost
    const ImageUpdate second = decoded(rig.cut(b, 2).updates.at(0));
    ASSERT_NE(second.baseSequence, f.sequence);
    Outbox::Taken t = rig.reportLoss(f.sequence, second.sequence);
    ASSERT_EQ(t.updates.size(), 1u);
    const ImageUpdate repair = decoded(t.updates[0]);
    EXPECT_EQ(repair.baseSequence, 0u);
    EXPECT_EQ(rectOf(repair), unite(a, b));
    EXPECT_EQ(repair.causeServerUs, 2u) << "caused when the rectangles it carries were";
    applyTo(client, t.updates[0], rig.cam);
    EXPECT_TRUE(compare(client, rig.frame).identical());
    EXPECT_EQ(rig.outbox.gapsReported(), 1u);
    // The same loss reported of the chained one that went before the repair is not repaired
    // twice.
    rig.outbox.acknowledge(1, ImageAck{0, f.sequence, second.sequence});
    EXPECT_TRUE(rig.outbox.repairsWanted().empty());

    t = rig.cut(c, 3);
    const ImageUpdate chained = decoded(t.updates.at(0));
    EXPECT_EQ(rectOf(chained), c);
    EXPECT_EQ(chained.baseSequence, repair.sequence);
    applyTo(client, t.updates[0], rig.cam);
    rig.outbox.acknowledge(1, ImageAck{0, chained.sequence});
    t = rig.cut(d, 4);
    EXPECT_EQ(rectOf(decoded(t.updates.at(0))), d);
    applyTo(client, t.updates[0], rig.cam);
    EXPECT_TRUE(compare(client, rig.frame).identical());
    EXPECT_EQ(rig.outbox.acksIgnored(), 0u);
}

// With no further drilling, the newest unacknowledged rectangle goes again once the repair
// timeout passes (the same bytes: its pixels are current), then after twice the timeout (one more
// a repair), and never once acknowledged.
TEST(LossyOutbox, AnUnacknowledgedRectangleIsResentAfterTheTimeout) {
    Rig rig;
    rig.full();
    Outbox::Taken t = rig.cut({10, 10, 12, 12}, 1);
    ASSERT_EQ(t.updates.size(), 1u);
    const std::vector<uint8_t> lost = t.updates[0].message;
    const uint64_t timeout = rig.outbox.repairTimeoutUs(1);
    EXPECT_EQ(timeout, 250'000u) << "before a round trip is measured";
    rig.clock.advance(timeout - 1000);
    EXPECT_TRUE(rig.outbox.take(live).updates.empty());
    rig.clock.advance(2000);
    t = rig.outbox.take(live);
    ASSERT_EQ(t.updates.size(), 1u);
    EXPECT_EQ(t.updates[0].channel, Channel::ImageLossy);
    EXPECT_EQ(t.updates[0].message, lost);
    EXPECT_EQ(rig.outbox.repairs(), 1u);
    rig.clock.advance(timeout + 1000);
    EXPECT_TRUE(rig.outbox.take(live).updates.empty()) << "the second waits twice as long";
    rig.clock.advance(timeout);
    EXPECT_EQ(rig.outbox.take(live).updates.size(), 1u);
    EXPECT_EQ(rig.outbox.repairs(), 2u);

    rig.outbox.acknowledge(1, ImageAck{0, decoded(t.updates[0]).sequence});
    rig.clock.advance(10 * timeout);
    EXPECT_TRUE(rig.outbox.take(live).updates.empty());
    EXPECT_EQ(rig.outbox.repairs(), 2u);
    EXPECT_TRUE(rig.outbox.empty());
}

// An acknowledgement times the round trip: the repair timeout follows the path, not 250 ms.
TEST(LossyOutbox, AcknowledgementsTimeTheRepairs) {
    Rig rig;
    rig.full();
    for (int i = 0; i < 8; ++i) {
        Outbox::Taken t = rig.cut({i, 0, 8, 8}, i + 1);
        ASSERT_EQ(t.updates.size(), 1u);
        rig.clock.advance(40'000);
        rig.outbox.acknowledge(1, ImageAck{0, decoded(t.updates[0]).sequence});
    }
    const uint64_t timeout = rig.outbox.repairTimeoutUs(1);
    EXPECT_GE(timeout, 60'000u) << "1.5 round trips at least";
    EXPECT_LT(timeout, 120'000u);
}

// Acknowledgements the client cannot honestly send are ignored, and what they claim stays
// unacknowledged (it is repaired): another view's, one older than the full image, one of a
// sequence never sent, one of a client that left.
TEST(LossyOutbox, AForgedOrStaleAcknowledgementIsIgnored) {
    Rig rig;
    const ImageUpdate f = rig.full();
    Outbox::Taken t = rig.cut({10, 10, 12, 12}, 1);
    const uint32_t sent = decoded(t.updates.at(0)).sequence;
    rig.outbox.acknowledge(1, ImageAck{7, sent});           // a view it does not hold
    rig.outbox.acknowledge(1, ImageAck{0, f.sequence - 1}); // before its full image
    rig.outbox.acknowledge(1, ImageAck{0, sent + 1});       // never sent
    rig.outbox.acknowledge(1, ImageAck{0, sent + 0x80000000u});
    rig.outbox.acknowledge(9, ImageAck{0, sent}); // nobody
    EXPECT_EQ(rig.outbox.acksIgnored(), 5u);
    rig.outbox.acknowledge(1, ImageAck{0, f.sequence, sent + 5}); // reports one never sent
    EXPECT_TRUE(rig.outbox.repairsWanted().empty());
    rig.clock.advance(rig.outbox.repairTimeoutUs(1));
    EXPECT_EQ(rig.outbox.take(live).updates.size(), 1u) << "still repaired";
    rig.outbox.leave(1);
    rig.outbox.acknowledge(1, ImageAck{0, sent});
    EXPECT_EQ(rig.outbox.acksIgnored(), 6u);
}

// A full image says everything: the rectangles before it are forgotten (an acknowledgement of
// one is stale), and those after it name it and carry nothing older.
TEST(LossyOutbox, AFullImageForgetsTheRectanglesBeforeIt) {
    Rig rig;
    rig.full();
    const PixelRect a{4, 4, 10, 6}, b{40, 30, 8, 8};
    const uint32_t old = decoded(rig.cut(a, 1).updates.at(0)).sequence;
    const ImageUpdate f = rig.full();
    rig.outbox.acknowledge(1, ImageAck{0, old});
    EXPECT_EQ(rig.outbox.acksIgnored(), 1u);
    const ImageUpdate next = decoded(rig.cut(b, 2).updates.at(0));
    EXPECT_EQ(next.fullSequence, f.sequence);
    EXPECT_EQ(rectOf(next), b);
    // A new view: rectangles wait for its full image (until then they go reliably, as before).
    rig.outbox.viewChanged(1, 5);
    const ImageUpdate before = decoded(rig.cut(a, 3).updates.at(0));
    EXPECT_EQ(before.fullSequence, 0u);
}

// Lossy bytes pass ENet's window, so the outbox keeps its own: past it a client's next rectangle
// waits, merging newer ones, until acknowledgements come or the sent ones time out as lost.
TEST(LossyOutbox, AClientPastTheLossyWindowWaitsMerging) {
    Rig rig(2000); // maxInFlightBytes: the window is the smaller of it and kLossyWindowBytes
    rig.full();
    const PixelRect a{0, 0, 30, 20}, b{32, 0, 10, 10}, c{32, 20, 10, 10};
    const ImageUpdate first = decoded(rig.cut(a, 1).updates.at(0)); // 4.8 kB raw: past 2000
    EXPECT_TRUE(rig.cut(b, 2).updates.empty());
    EXPECT_TRUE(rig.cut(c, 3).updates.empty());
    rig.outbox.acknowledge(1, ImageAck{0, first.sequence});
    Outbox::Taken t = rig.outbox.take(live);
    ASSERT_EQ(t.updates.size(), 1u);
    // One update, the newest pixels, built on the first.
    const ImageUpdate merged = decoded(t.updates[0]);
    EXPECT_EQ(rectOf(merged), unite(b, c));
    EXPECT_EQ(merged.baseSequence, first.sequence);
    // Unacknowledged, it counts until the repair timeout; then the waiting one goes.
    EXPECT_TRUE(rig.cut(a, 4).updates.empty());
    rig.clock.advance(rig.outbox.repairTimeoutUs(1));
    t = rig.outbox.take(live);
    ASSERT_EQ(t.updates.size(), 1u);
    EXPECT_EQ(rectOf(decoded(t.updates[0])), a);
}

// A zstd client's chained rectangles are predicted against the picture they build on, whether
// or not anything is acknowledged; a self-contained one is planar (what the client holds under
// it is not known), and the one chained after it builds on it.
TEST(LossyOutbox, ChainedRectanglesArePredictedSelfContainedOnesPlanar) {
    Rig rig(1 << 20, Codec::Zstd);
    rig.full(false);
    const ImageUpdate first = decoded(rig.cut({4, 4, 10, 10}, 1).updates.at(0));
    EXPECT_TRUE(first.predicted) << "behind the full image, reliably";
    rig.outbox.acknowledge(1, ImageAck{0, first.sequence});
    const ImageUpdate second = decoded(rig.cut({8, 8, 10, 10}, 2).updates.at(0));
    EXPECT_TRUE(second.predicted);
    const ImageUpdate third = decoded(rig.cut({30, 8, 10, 10}, 3).updates.at(0));
    const ImageUpdate repair =
        decoded(rig.reportLoss(first.sequence, third.sequence).updates.at(0));
    EXPECT_FALSE(repair.predicted);
    EXPECT_EQ(rectOf(repair), unite(PixelRect{8, 8, 10, 10}, PixelRect{30, 8, 10, 10}));
    rig.outbox.acknowledge(1, ImageAck{0, repair.sequence});
    const ImageUpdate fourth = decoded(rig.cut({20, 8, 10, 10}, 4).updates.at(0));
    EXPECT_TRUE(fourth.predicted);
    EXPECT_EQ(fourth.baseSequence, repair.sequence);
    EXPECT_EQ(rectOf(fourth), (PixelRect{20, 8, 10, 10}));
}

// A full image that fits a lossy message goes lossy once a round trip is measured, to a client
// that has not measured a clean link, and so do the rectangles after it before its
// acknowledgement, chained on it (a reliable one could overtake it, be ignored and never be
// repaired). Unacknowledged past the repair timeout it goes again; once acknowledged, not.
TEST(LossyOutbox, ASmallFullImageAndTheRectanglesAfterItGoLossyAndItIsResent) {
    Rig rig;
    const ImageUpdate join = rig.full(false); // the join's: it goes reliably
    EXPECT_EQ(rig.fullChannel, Channel::Image);
    rig.clock.advance(50'000);
    rig.outbox.acknowledge(1, ImageAck{0, join.sequence, 0, 30}); // the first round trip
    const ImageUpdate f = rig.full(false);
    EXPECT_EQ(rig.fullChannel, Channel::ImageLossy);
    const PixelRect a{4, 4, 10, 6};
    Outbox::Taken t = rig.cut(a, 1);
    ASSERT_EQ(t.updates.size(), 1u);
    EXPECT_EQ(t.updates[0].channel, Channel::ImageLossy);
    EXPECT_EQ(decoded(t.updates[0]).fullSequence, f.sequence);
    EXPECT_EQ(decoded(t.updates[0]).baseSequence, f.sequence);
    rig.clock.advance(rig.outbox.repairTimeoutUs(1) + 1);
    t = rig.outbox.take(live);
    ASSERT_EQ(t.updates.size(), 2u) << "the full image and the rectangle, again";
    EXPECT_TRUE(t.updates[0].full);
    EXPECT_EQ(t.updates[0].channel, Channel::ImageLossy);
    EXPECT_EQ(decoded(t.updates[0]).sequence, f.sequence);
    EXPECT_EQ(t.updates[0].lossPermille, Outbox::kAssumedLossPermille) << "not measured yet";
    EXPECT_EQ(rig.outbox.repairs(), 2u);
    // Acknowledged: the loss the client reports sizes the parity once it has acknowledged
    // kLossMeasuredBytes sent lossy (BeforeTheClientsLossCounts...), not yet.
    rig.outbox.acknowledge(1, ImageAck{0, f.sequence, 0, 50});
    rig.clock.advance(10 * rig.outbox.repairTimeoutUs(1));
    t = rig.outbox.take(live);
    ASSERT_EQ(t.updates.size(), 1u) << "only the rectangle";
    EXPECT_FALSE(t.updates[0].full);
    EXPECT_EQ(t.updates[0].lossPermille, Outbox::kAssumedLossPermille);
}

// Until the client has acknowledged kLossMeasuredBytes sent lossy, its loss figure (smoothed from
// zero) says little, and parity is for kAssumedLossPermille. A full image then goes lossy once a
// round trip is measured (a view change right after a join over a long lossy link does not wait
// for ENet's resend), but not the join's, which ENet's window paces and whose acknowledgement
// gives that round trip; a preview before it does not count as the join's. Once the client's
// figure counts and reads a clean link, full images go reliably and rectangles carry no parity.
TEST(LossyOutbox, BeforeTheClientsLossCountsAFullImageButTheJoinsGoesLossy) {
    Rig rig;
    rig.outbox.postFullImage(1, previewCamera(rig.cam), Dbi(32, 24), 1, true);
    Outbox::Taken t = rig.outbox.take(live);
    ASSERT_EQ(t.updates.size(), 1u);
    EXPECT_EQ(t.updates[0].channel, Channel::Image) << "the join's preview";
    const ImageUpdate join = rig.full(false);
    EXPECT_EQ(rig.fullChannel, Channel::Image) << "the join's exact picture";
    rig.clock.advance(120'000);
    rig.outbox.acknowledge(1, ImageAck{0, join.sequence, 0, 0}); // nothing lossy received yet
    const uint64_t timeout = rig.outbox.repairTimeoutUs(1);
    EXPECT_GE(timeout, 180'000u) << "its round trip, delivery included, times the repairs";
    t = rig.cut({4, 4, 10, 6}, 1);
    ASSERT_EQ(t.updates.size(), 1u);
    EXPECT_EQ(t.updates[0].channel, Channel::ImageLossy);
    EXPECT_EQ(t.updates[0].lossPermille, Outbox::kAssumedLossPermille);
    const ImageUpdate moved = rig.full(false); // a view change's
    EXPECT_EQ(rig.fullChannel, Channel::ImageLossy);
    EXPECT_EQ(rig.fullLoss, Outbox::kAssumedLossPermille);
    // A first report of no loss over a few datagrams is not yet a measurement.
    rig.outbox.acknowledge(1, ImageAck{0, moved.sequence, 0, 0});
    rig.full(false);
    EXPECT_EQ(rig.fullChannel, Channel::ImageLossy);
    // Whole-frame rectangles acknowledged with no loss until the figure counts.
    int64_t acked = 0;
    for (int seed = 2; acked < Outbox::kLossMeasuredBytes; ++seed) {
        rig.clock.advance(1000);
        t = rig.cut(rig.frame.bounds(), seed);
        ASSERT_EQ(t.updates.size(), 1u);
        ASSERT_EQ(t.updates[0].channel, Channel::ImageLossy);
        acked += int64_t(t.updates[0].message.size());
        rig.outbox.acknowledge(1, ImageAck{0, decoded(t.updates[0]).sequence, 0, 0});
    }
    t = rig.cut({30, 20, 8, 8}, 1);
    ASSERT_EQ(t.updates.size(), 1u);
    EXPECT_EQ(t.updates[0].lossPermille, 0u);
    rig.full();
    EXPECT_EQ(rig.fullChannel, Channel::Image) << "a clean link: ENet's window paces it";
    EXPECT_EQ(rig.fullLoss, 0u);
}

// A rectangle of more than ~100 datagrams goes reliably, as do those after a full image too
// large to go lossy until it is acknowledged (behind it), still naming it; none is repaired.
TEST(LossyOutbox, RectanglesBehindAReliableFullImageOrLargeGoReliably) {
    Outbox::Taken t;
    // A raw frame of 300 x 200 is 480 kB: past kLossyMaxMessageBytes, so it goes reliably.
    Rig big;
    big.cam = cameraFor(300, 200);
    big.frame = picture(300, 200, 0);
    const ImageUpdate f = big.full(false);
    t = big.cut({4, 4, 10, 6}, 1);
    ASSERT_EQ(t.updates.size(), 1u);
    EXPECT_EQ(t.updates[0].channel, Channel::Image) << "behind its full image";
    EXPECT_EQ(decoded(t.updates[0]).fullSequence, f.sequence);
    big.outbox.acknowledge(1, ImageAck{0, decoded(t.updates[0]).sequence});
    big.frame = with(big.frame, picture(300, 200, 5), big.frame.bounds());
    big.outbox.postImage(1, big.cam, big.frame, {0, 0, 300, 100}, false, 2, {});
    t = big.outbox.take(live);
    ASSERT_EQ(t.updates.size(), 1u);
    EXPECT_GT(t.updates[0].message.size(), Outbox::kLossyMaxMessageBytes);
    EXPECT_EQ(t.updates[0].channel, Channel::Image);
    big.clock.advance(10 * big.outbox.repairTimeoutUs(1));
    EXPECT_TRUE(big.outbox.take(live).updates.empty()) << "ENet delivers it: no repair";
}

// A chained rectangle too large to go lossy goes reliably, and ENet delivers it; but on a lost base
// it is unusable, and the client's one report of that may be lost as well. Unacknowledged past the
// timeout it asks the step for a self-contained repair, which carries both.
TEST(LossyOutbox, AReliableChainedRectangleUnacknowledgedIsRepairedSelfContained) {
    Rig big;
    big.cam = cameraFor(300, 200);
    big.frame = picture(300, 200, 0);
    big.full();
    const PixelRect small{4, 4, 10, 10}, large{0, 50, 300, 100};
    big.frame = with(big.frame, picture(300, 200, 1), small);
    big.outbox.postImage(1, big.cam, big.frame, small, false, 2, {});
    ASSERT_EQ(big.outbox.take(live).updates.at(0).channel, Channel::ImageLossy); // lost
    big.frame = with(big.frame, picture(300, 200, 2), large);
    big.outbox.postImage(1, big.cam, big.frame, large, false, 3, {});
    Outbox::Taken t = big.outbox.take(live);
    ASSERT_EQ(t.updates.size(), 1u);
    EXPECT_EQ(t.updates[0].channel, Channel::Image);
    EXPECT_NE(decoded(t.updates[0]).baseSequence, 0u);
    big.clock.advance(big.outbox.repairTimeoutUs(1) + 1);
    EXPECT_TRUE(big.outbox.take(live).updates.empty()) << "nothing to re-send as it was";
    EXPECT_EQ(big.outbox.repairsWanted(), std::vector<uint16_t>{1});
    big.outbox.postImage(1, big.cam, big.frame, {}, false, 0, {});
    t = big.outbox.take(live);
    ASSERT_EQ(t.updates.size(), 1u);
    const ImageUpdate repair = decoded(t.updates[0]);
    EXPECT_EQ(repair.baseSequence, 0u);
    EXPECT_EQ(rectOf(repair), unite(small, large));
}

// A previewed view's exact frame finds the coder's frame-sized buffer still there: a preview's
// half-size pixels are never kept as the spare, and buffer() of another size leaves it.
TEST(LossyOutbox, APreviewLeavesTheFrameSizedBufferForTheExactFrame) {
    Rig rig;
    rig.outbox.postFullImage(1, rig.cam, Dbi(rig.frame), 1); // coded inline: its pixels kept
    const Camera half = cameraFor(32, 24);
    rig.outbox.postFullImage(1, half, picture(32, 24, 3), 1, true);
    // A new one (its pixels unset): the one spare is still the frame's, below.
    const Dbi fresh = rig.outbox.buffer(32, 24);
    EXPECT_EQ(fresh.bounds(), PixelRect(0, 0, 32, 24));
    const Dbi spare = rig.outbox.buffer(64, 48);
    EXPECT_EQ(spare, rig.frame) << "the last frame's buffer, kept";
}

// A client that never acknowledges costs a bounded list (the oldest merge), and a repair still
// carries every rectangle it was sent.
TEST(LossyOutbox, AClientThatNeverAcknowledgesKeepsABoundedList) {
    Rig rig;
    const ImageUpdate f = rig.full();
    PixelRect all;
    uint32_t newest = 0;
    for (int i = 0; i < 3 * int(Outbox::kMaxUnacked); ++i) {
        const PixelRect r{i % 60, (i * 7) % 44, 3, 3};
        all = all.empty() ? r : unite(all, r);
        Outbox::Taken t = rig.cut(r, i + 1);
        ASSERT_EQ(t.updates.size(), 1u) << i;
        const ImageUpdate u = decoded(t.updates[0]);
        EXPECT_EQ(rectOf(u), r) << i;
        newest = u.sequence;
    }
    Outbox::Taken t = rig.reportLoss(f.sequence, newest);
    ASSERT_EQ(t.updates.size(), 1u);
    EXPECT_EQ(rectOf(decoded(t.updates[0])), all);
}

// [SECTION] the client, fed by a fake server

namespace {

const Volume& sphere() {
    static const Volume v = makeSphere(16);
    return v;
}

// Raw pixels of one colour, so each image is told apart by its pixels.
Dbi solid(int w, int h, uint8_t value) {
    Dbi d(w, h);
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
            uint8_t* c = d.color(x, y);
            c[0] = c[1] = c[2] = value;
            c[3] = 255;
            d.depth()[d.index(x, y)] = 0.5f;
        }
    return d;
}

struct FedClient {
    trephine::testing::FakeServer fake;
    ViewSpec view = toViewSpec(cameraPreset("top", sphere(), {16, 16}));
    std::unique_ptr<SessionClient> client;
    std::vector<ImageAck> acks;

    FedClient() {
        ClientConfig c;
        c.codec = Codec::Raw;
        c.view = view;
        client = std::make_unique<SessionClient>(c);
        client->connect(trephine::testing::loopback(fake.port()));
        EXPECT_TRUE(pump([&] { return fake.peer && client->connected(); }));
        Welcome w;
        w.clientId = 1;
        w.volumeDims = sphere().dims();
        w.spacing = sphere().spacing();
        fake.send(Channel::Control, encodeMessage(w));
        Scene scene = buildScene(sphere());
        fake.send(Channel::Control, encodeMessage(scene));
        EXPECT_TRUE(pump([&] { return client->scene() != nullptr; }));
    }
    // Services both ends until pred(), keeping the acknowledgements the client sends.
    bool pump(const std::function<bool()>& pred) {
        const uint64_t deadline = steadyNowUs() + 10'000'000;
        while (steadyNowUs() < deadline) {
            fake.host.service(1, [&](const ENetEvent& e) {
                if (e.type == ENET_EVENT_TYPE_CONNECT)
                    fake.peer = e.peer;
                ImageAck a;
                if (e.type == ENET_EVENT_TYPE_RECEIVE &&
                    decodeMessage({e.packet->data, e.packet->dataLength}, a))
                    acks.push_back(a);
            });
            client->poll(1);
            if (pred())
                return true;
        }
        return false;
    }
    // An image of view `viewId`: full, or a lossy rectangle at (x, y) on full image `on`,
    // chained on image `base` (0: self-contained).
    void image(uint32_t sequence, uint32_t viewId, bool full, uint32_t on, PixelRect r,
               uint8_t value, uint32_t base = 0) {
        ImageUpdate u;
        u.sequence = sequence;
        u.viewId = viewId;
        u.full = full;
        u.fullSequence = on;
        u.baseSequence = base;
        u.x = uint16_t(r.x);
        u.y = uint16_t(r.y);
        u.width = uint16_t(r.w);
        u.height = uint16_t(r.h);
        u.codec = Codec::Raw;
        EncodedImage e = encodeImage(solid(r.w, r.h, value), Codec::Raw, toCamera(view));
        u.rawBytes = e.rawBytes;
        u.payload = std::move(e.payload);
        const Channel channel = full ? Channel::Image : Channel::ImageLossy;
        const uint64_t in = client->stats().totalBytesIn(channel);
        fake.send(channel, encodeMessage(u));
        // Received (then applied or ignored), and an acknowledgement, if any, back.
        EXPECT_TRUE(pump([&] { return client->stats().totalBytesIn(channel) > in; }));
        for (int i = 0; i < 20; ++i)
            pump([] { return true; });
    }
    uint8_t pixel(int x, int y) const { return client->dbi().color(x, y)[0]; }
};

} // namespace

// A rectangle on the full image held applies, once, and each image applied is acknowledged.
TEST(LossyClient, ARectangleOnTheFullImageHeldAppliesAndIsAcknowledged) {
    FedClient f;
    f.image(5, 0, true, 0, {0, 0, 16, 16}, 10);
    ASSERT_TRUE(f.client->hasFullImage());
    f.image(6, 0, false, 5, {2, 2, 4, 4}, 20);
    EXPECT_EQ(f.pixel(3, 3), 20);
    EXPECT_EQ(f.pixel(8, 8), 10);
    ASSERT_EQ(f.acks.size(), 2u);
    EXPECT_EQ(f.acks[0].sequence, 5u);
    EXPECT_EQ(f.acks[1].sequence, 6u);
    EXPECT_EQ(f.client->lossyIgnored(), 0u);
}

// Lossy and reliable images are not ordered with each other. A rectangle that names a full image
// not here yet is ignored and not acknowledged (the server repairs it); once the full image
// comes, a newer rectangle applies.
TEST(LossyClient, ARectangleAheadOfItsFullImageIsIgnored) {
    FedClient f;
    f.image(5, 0, true, 0, {0, 0, 16, 16}, 10);
    f.image(8, 0, false, 7, {2, 2, 4, 4}, 30); // on full image 7, still on its way
    EXPECT_EQ(f.pixel(3, 3), 10);
    EXPECT_EQ(f.client->lossyIgnored(), 1u);
    EXPECT_EQ(f.acks.size(), 1u);
    f.image(7, 0, true, 0, {0, 0, 16, 16}, 11);
    f.image(8, 0, false, 7, {2, 2, 4, 4}, 30); // the repair
    EXPECT_EQ(f.pixel(3, 3), 30);
    EXPECT_EQ(f.pixel(8, 8), 11);
    EXPECT_EQ(f.acks.back().sequence, 8u);
}

// A rectangle older than the newest image applied never rolls pixels back: a late one is
// ignored; a repeat of the newest (the server's repair after a lost acknowledgement) is
// acknowledged again.
TEST(LossyClient, ALateOrRepeatedRectangleIsNotApplied) {
    FedClient f;
    f.image(5, 0, true, 0, {0, 0, 16, 16}, 10);
    f.image(7, 0, false, 5, {2, 2, 4, 4}, 70);
    f.image(6, 0, false, 5, {2, 2, 4, 4}, 60); // overtaken
    EXPECT_EQ(f.pixel(3, 3), 70);
    const size_t acks = f.acks.size();
    f.image(7, 0, false, 5, {2, 2, 4, 4}, 70); // the same again
    EXPECT_EQ(f.client->lossyIgnored(), 2u);
    ASSERT_GT(f.acks.size(), acks);
    EXPECT_EQ(f.acks.back().sequence, 7u);
}

// A chained rectangle applies only on the image it builds on. One that builds on an image that
// never came is ignored and reported unusable beside the newest image applied; a self-contained
// one then applies, and the chain goes on from it.
TEST(LossyClient, AChainedRectangleOnAnImageNotHeldIsReported) {
    FedClient f;
    f.image(5, 0, true, 0, {0, 0, 16, 16}, 10);
    f.image(6, 0, false, 5, {2, 2, 4, 4}, 60, 5);
    EXPECT_EQ(f.pixel(3, 3), 60);
    f.image(8, 0, false, 5, {8, 8, 4, 4}, 80, 7); // 7 was lost
    EXPECT_EQ(f.pixel(9, 9), 10);
    EXPECT_EQ(f.client->lossyIgnored(), 1u);
    ASSERT_FALSE(f.acks.empty());
    EXPECT_EQ(f.acks.back().sequence, 6u);
    EXPECT_EQ(f.acks.back().unusable, 8u);
    f.image(9, 0, false, 5, {2, 2, 10, 10}, 90); // the repair: every one not acknowledged
    f.image(10, 0, false, 5, {0, 0, 2, 2}, 100, 9);
    EXPECT_EQ(f.pixel(9, 9), 90);
    EXPECT_EQ(f.pixel(1, 1), 100);
    EXPECT_EQ(f.acks.back().sequence, 10u);
    EXPECT_EQ(f.acks.back().unusable, 0u);
}

// A rectangle of a view the client has left, or arriving after the full image that replaced
// the one it names, is ignored: it would land on another picture.
TEST(LossyClient, ARectangleOfAnotherPictureIsIgnored) {
    FedClient f;
    f.image(5, 0, true, 0, {0, 0, 16, 16}, 10);
    ViewSpec turned = f.view;
    turned.eye.x += 10.0f;
    const uint32_t id = f.client->requestView(turned);
    f.image(6, id, true, 0, {0, 0, 16, 16}, 40); // the new view's full image
    ASSERT_EQ(f.client->viewId(), id);
    f.image(7, 0, false, 5, {2, 2, 4, 4}, 50);  // the old view's, late
    f.image(8, id, false, 5, {2, 2, 4, 4}, 50); // on a full image it no longer holds
    EXPECT_EQ(f.pixel(3, 3), 40);
    EXPECT_EQ(f.client->lossyIgnored(), 1u) << "the old view's is stale before any check";
    EXPECT_EQ(f.acks.back().sequence, 6u);
}

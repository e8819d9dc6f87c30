// Drilling rectangles as lossy state (docs/protocol.md, "Lossy rectangles"): the outbox on its own
// with a clock the test moves (what a rectangle carries, repairs, acknowledgements, the window),
// then a SessionClient fed by a fake server in every order the two image channels allow.
#include "net/outbox.h"
#include "net/scene.h"
#include "net/session_client.h"
#include "net/view.h"

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
        EXPECT_EQ(t.updates.at(0).channel, Channel::Image);
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
};

PixelRect rectOf(const ImageUpdate& u) {
    return {u.x, u.y, u.width, u.height};
}

} // namespace

// After a full image each rectangle goes lossy, names that full image and carries every rectangle
// not acknowledged at current pixels: a client that lost the first still gets the frame exactly
// from the second. Once everything is acknowledged, a rectangle carries itself alone.
TEST(LossyOutbox, ARectangleCarriesEveryOneNotAcknowledged) {
    Rig rig;
    rig.outbox.postImage(1, rig.cam, rig.frame, rig.frame.bounds(), true, 1, {});
    Outbox::Taken t = rig.outbox.take(live);
    Dbi client;
    applyTo(client, t.updates.at(0), rig.cam);
    const uint32_t fullSeq = decoded(t.updates.at(0)).sequence;
    rig.outbox.acknowledge(1, ImageAck{0, fullSeq});

    const PixelRect a{4, 4, 10, 6}, b{30, 20, 8, 8}, c{50, 2, 6, 6};
    t = rig.cut(a, 1);
    ASSERT_EQ(t.updates.size(), 1u);
    EXPECT_EQ(t.updates[0].channel, Channel::ImageLossy);
    const ImageUpdate first = decoded(t.updates[0]);
    EXPECT_EQ(first.fullSequence, fullSeq);
    EXPECT_EQ(rectOf(first), a);
    // Lost. The next carries both.
    t = rig.cut(b, 2);
    ASSERT_EQ(t.updates.size(), 1u);
    const ImageUpdate second = decoded(t.updates[0]);
    EXPECT_EQ(rectOf(second), unite(a, b));
    applyTo(client, t.updates[0], rig.cam);
    EXPECT_TRUE(compare(client, rig.frame).identical());

    rig.outbox.acknowledge(1, ImageAck{0, second.sequence});
    t = rig.cut(c, 3);
    ASSERT_EQ(t.updates.size(), 1u);
    EXPECT_EQ(rectOf(decoded(t.updates[0])), c);
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
    // One update, the newest pixels; a was unacknowledged when b came, so it is carried too.
    EXPECT_EQ(rectOf(decoded(t.updates[0])), unite(a, unite(b, c)));
    // Unacknowledged, it counts until the repair timeout; then the waiting one goes.
    EXPECT_TRUE(rig.cut(a, 4).updates.empty());
    rig.clock.advance(rig.outbox.repairTimeoutUs(1));
    t = rig.outbox.take(live);
    ASSERT_EQ(t.updates.size(), 1u);
    EXPECT_EQ(rectOf(decoded(t.updates[0])), unite(a, unite(b, c)));
}

// A zstd client's rectangles are predicted only when it has acknowledged everything: then the
// outbox knows the pixels it holds. Otherwise planar, whatever it got.
TEST(LossyOutbox, PredictedOnlyWhenEverythingIsAcknowledged) {
    Rig rig(1 << 20, Codec::Zstd);
    const ImageUpdate f = rig.full(false);
    const ImageUpdate first = decoded(rig.cut({4, 4, 10, 10}, 1).updates.at(0));
    EXPECT_FALSE(first.predicted) << "the full image is not acknowledged yet";
    rig.outbox.acknowledge(1, ImageAck{0, f.sequence});
    const ImageUpdate second = decoded(rig.cut({8, 8, 10, 10}, 2).updates.at(0));
    EXPECT_FALSE(second.predicted) << "the first is not acknowledged";
    rig.outbox.acknowledge(1, ImageAck{0, second.sequence});
    const ImageUpdate third = decoded(rig.cut({20, 8, 10, 10}, 3).updates.at(0));
    EXPECT_TRUE(third.predicted);
    EXPECT_EQ(rectOf(third), (PixelRect{20, 8, 10, 10}));
    (void)f;
}

// Until the client acknowledges its full image, and for a rectangle of more than a few
// datagrams, rectangles go reliably behind the full image (a lossy one would overtake it, or be
// lost whole with any fragment), still naming it; later lossy ones carry them until
// acknowledged, and none is repaired.
TEST(LossyOutbox, RectanglesBeforeTheFullImagesAckOrLargeGoReliably) {
    Rig rig;
    const ImageUpdate f = rig.full(false);
    const PixelRect a{4, 4, 10, 6}, b{30, 20, 8, 8};
    Outbox::Taken t = rig.cut(a, 1);
    ASSERT_EQ(t.updates.size(), 1u);
    EXPECT_EQ(t.updates[0].channel, Channel::Image) << "behind its full image";
    EXPECT_EQ(decoded(t.updates[0]).fullSequence, f.sequence);
    rig.outbox.acknowledge(1, ImageAck{0, f.sequence});
    t = rig.cut(b, 2);
    ASSERT_EQ(t.updates.size(), 1u);
    EXPECT_EQ(t.updates[0].channel, Channel::ImageLossy);
    EXPECT_EQ(rectOf(decoded(t.updates[0])), unite(a, b)) << "the reliable one is carried";

    // A raw frame of 300 x 200 is 480 kB: past kLossyMaxMessageBytes, so it goes reliably.
    Rig big;
    big.cam = cameraFor(300, 200);
    big.frame = picture(300, 200, 0);
    big.full();
    big.frame = with(big.frame, picture(300, 200, 5), big.frame.bounds());
    big.outbox.postImage(1, big.cam, big.frame, {0, 0, 300, 100}, false, 2, {});
    t = big.outbox.take(live);
    ASSERT_EQ(t.updates.size(), 1u);
    EXPECT_GT(t.updates[0].message.size(), Outbox::kLossyMaxMessageBytes);
    EXPECT_EQ(t.updates[0].channel, Channel::Image);
    big.clock.advance(10 * big.outbox.repairTimeoutUs(1));
    EXPECT_TRUE(big.outbox.take(live).updates.empty()) << "ENet delivers it: no repair";
}

// A client that never acknowledges costs a bounded list: every rectangle still carries all.
TEST(LossyOutbox, AClientThatNeverAcknowledgesKeepsABoundedList) {
    Rig rig;
    rig.full();
    PixelRect all;
    for (int i = 0; i < 3 * int(Outbox::kMaxUnacked); ++i) {
        const PixelRect r{i % 60, (i * 7) % 44, 3, 3};
        all = all.empty() ? r : unite(all, r);
        rig.clock.advance(rig.outbox.repairTimeoutUs(1) + 1); // the window: earlier ones lost
        Outbox::Taken t = rig.cut(r, i + 1);
        ASSERT_EQ(t.updates.size(), 1u) << i;
        EXPECT_EQ(rectOf(decoded(t.updates[0])), all) << i;
    }
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
    // An image of view `viewId`: full, or a lossy rectangle at (x, y) on full image `on`.
    void image(uint32_t sequence, uint32_t viewId, bool full, uint32_t on, PixelRect r,
               uint8_t value) {
        ImageUpdate u;
        u.sequence = sequence;
        u.viewId = viewId;
        u.full = full;
        u.fullSequence = on;
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

// The server's outbox on its own: no ENet, no threads, no sleeps. A test posts as the simulation
// step would, takes as the network thread would, sets a client's bytes in flight by hand, and
// applies what it takes to a client's copy, as a client would.
#include "net/outbox.h"

#include "libsim/skull.h"
#include "net/codec.h"
#include "net/image_delta.h"

#include <gtest/gtest.h>

#include <chrono>
#include <future>
#include <map>

using namespace trephine;
using namespace trephine::net;

namespace {

// A clock that moves 10 us each time it is read.
ServerClock fakeClock() {
    auto t = std::make_shared<uint64_t>(1'000'000);
    return [t] { return *t += 10; };
}

Host::InFlight inFlight(int64_t bytes = 0) {
    return std::make_shared<std::atomic<int64_t>>(bytes);
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
            c[2] = uint8_t(x + y);
            c[3] = 255;
            d.depth()[d.index(x, y)] = 0.5f + 0.001f * float((x + 2 * y + seed) % 300);
        }
    return d;
}

// `frame` with `rect` taken from `from`.
Dbi with(const Dbi& frame, const Dbi& from, PixelRect rect) {
    Dbi out = frame;
    out.apply(from.extract(rect), rect.x, rect.y);
    return out;
}

bool live(uint16_t) {
    return true;
}

// A client's copy of its DBI, updated as SessionClient applies ImageUpdates.
struct ClientCopy {
    Camera camera;
    Dbi dbi;
    int resyncs = 0;

    void apply(const Outbox::Ready& r) {
        ASSERT_EQ(r.mode, Sync::Dbi);
        ImageUpdate u;
        ASSERT_TRUE(decodeMessage(r.message, u));
        Dbi patch;
        if (u.predicted) {
            patch = dbi.extract({u.x, u.y, u.width, u.height});
            const PredictedStatus s = decodePredicted(u.payload, u.rawBytes, u.codec, u.baseHash,
                                                      DepthQuantizer(camera), patch);
            if (s == PredictedStatus::BaseMismatch)
                ++resyncs;
            ASSERT_EQ(s, PredictedStatus::Ok);
        } else {
            ASSERT_TRUE(
                decodeImage(u.payload, u.rawBytes, u.codec, u.width, u.height, camera, patch));
        }
        if (u.full)
            dbi = patch;
        else
            dbi.apply(patch, u.x, u.y);
    }
};

// What a zstd or lz4 client holds of `d`: depths through the quantiser.
Dbi quantised(const Dbi& d, const Camera& camera) {
    DepthQuantizer q(camera);
    Dbi out = d;
    for (size_t i = 0; i < size_t(d.width()) * size_t(d.height()); ++i)
        out.depth()[i] = q.dequantize(q.quantize(d.depth()[i]));
    return out;
}

ImageUpdate decoded(const Outbox::Ready& r) {
    ImageUpdate u;
    EXPECT_TRUE(decodeMessage(r.message, u));
    return u;
}

struct OutboxRig {
    ReportBook book;
    Outbox outbox;
    explicit OutboxRig(int64_t maxInFlight = 1 << 20) : outbox(maxInFlight, book, fakeClock()) {}
    uint64_t encodes(Sync mode) const {
        return book.read(
            [&](const ServerReport& r) { return r.modes[size_t(mode)].encodeUs.totalCount(); });
    }
};

} // namespace

// Two rectangles posted before the network takes the first go as one update: their union, taken
// from the newest frame, with the older cause; the client's copy is the frame bit for bit.
TEST(Outbox, RectanglesPostedBeforeTheyLeaveGoAsOneUpdate) {
    OutboxRig rig;
    const Camera cam = cameraFor(64, 48);
    rig.outbox.join(7, inFlight(), Codec::Raw, Codec::Lz4);
    Dbi frame = picture(64, 48, 0);
    rig.outbox.postImage(7, cam, frame, frame.bounds(), true, 5, {});
    ClientCopy client{cam, {}, 0};
    Outbox::Taken t = rig.outbox.take(live);
    ASSERT_EQ(t.updates.size(), 1u);
    EXPECT_TRUE(t.updates[0].full);
    client.apply(t.updates[0]);
    EXPECT_TRUE(rig.outbox.empty());

    const PixelRect a{4, 4, 10, 6}, b{30, 20, 8, 8};
    frame = with(frame, picture(64, 48, 1), a);
    rig.outbox.postImage(7, cam, frame, a, false, 10, {1, 2, 0});
    frame = with(frame, picture(64, 48, 2), b);
    rig.outbox.postImage(7, cam, frame, b, false, 20, {1, 2, 0});
    EXPECT_FALSE(rig.outbox.empty());
    t = rig.outbox.take(live);
    ASSERT_EQ(t.updates.size(), 1u) << "merged";
    const ImageUpdate u = decoded(t.updates[0]);
    EXPECT_EQ(PixelRect({u.x, u.y, u.width, u.height}), unite(a, b));
    EXPECT_EQ(u.causeServerUs, 10u) << "the older cause: latency is never under-reported";
    EXPECT_GT(u.sequence, 1u);
    client.apply(t.updates[0]);
    EXPECT_TRUE(compare(client.dbi, frame).identical());
    EXPECT_EQ(rig.encodes(Sync::Dbi), 3u);
}

// A client held back (ENet still holds more than maxInFlightBytes of its updates) gets nothing;
// what comes meanwhile merges into its waiting update, which goes once its link has caught up.
// A client that is not live (gone, or sent away) loses what waits for it.
TEST(Outbox, AHeldBackClientGetsOneMergedUpdateWhenItCatchesUp) {
    OutboxRig rig(1000);
    const Camera cam = cameraFor(32, 32);
    Host::InFlight held = inFlight(5000);
    rig.outbox.join(1, held, Codec::Lz4, Codec::Lz4);
    rig.outbox.join(2, inFlight(), Codec::Lz4, Codec::Lz4);
    Dbi frame = picture(32, 32, 0);
    for (uint16_t id : {1, 2})
        rig.outbox.postImage(id, cam, frame, frame.bounds(), true, 1, {});
    Outbox::Taken t = rig.outbox.take(live);
    ASSERT_EQ(t.updates.size(), 1u);
    EXPECT_EQ(t.updates[0].client, 2);
    for (int i = 0; i < 10; ++i) {
        const PixelRect r{i * 2, i, 4, 4};
        frame = with(frame, picture(32, 32, i + 1), r);
        rig.outbox.postImage(1, cam, frame, r, false, 100 + uint64_t(i), {});
        EXPECT_TRUE(rig.outbox.take(live).updates.empty()) << "held back";
    }
    held->store(1000); // not over the bound any more
    t = rig.outbox.take(live);
    ASSERT_EQ(t.updates.size(), 1u);
    ClientCopy client{cam, {}, 0};
    client.apply(t.updates[0]);
    EXPECT_TRUE(decoded(t.updates[0]).full) << "the join's full image, with every change in it";
    EXPECT_TRUE(compare(client.dbi, quantised(frame, cam)).identical());

    held->store(5000);
    rig.outbox.postImage(1, cam, frame, {0, 0, 4, 4}, false, 200, {});
    EXPECT_TRUE(rig.outbox.take([](uint16_t id) { return id != 1; }).updates.empty());
    EXPECT_TRUE(rig.outbox.empty()) << "a client sent away keeps nothing waiting";

    rig.outbox.postImage(2, cam, frame, {0, 0, 4, 4}, false, 300, {});
    EXPECT_FALSE(rig.outbox.empty());
    rig.outbox.clear(); // the server stopped: nobody will take it
    EXPECT_TRUE(rig.outbox.empty());
    EXPECT_TRUE(rig.outbox.take(live).updates.empty());
}

// A client asks for a smaller window under the id of the view it has while an update of the old
// one waits: the waiting update is dropped with the view, and the new window's full image is all
// that goes; no pixel is read from outside it.
TEST(Outbox, AViewChangeDropsTheWaitingImageOfTheViewLeft) {
    OutboxRig rig(0);
    const Camera big = cameraFor(256, 256), small = cameraFor(64, 64);
    Host::InFlight held = inFlight(1);
    rig.outbox.join(3, held, Codec::Lz4, Codec::Lz4);
    Dbi frame = picture(256, 256, 0);
    rig.outbox.postImage(3, big, frame, frame.bounds(), true, 1, {});
    rig.outbox.postImage(3, big, frame, {100, 100, 43, 43}, false, 2, {});
    rig.outbox.viewChanged(3, 0); // the hello's id again
    const Dbi smaller = picture(64, 64, 1);
    rig.outbox.postImage(3, small, smaller, smaller.bounds(), true, 3, {});
    held->store(0);
    Outbox::Taken t = rig.outbox.take(live);
    ASSERT_EQ(t.updates.size(), 1u);
    ImageUpdate u = decoded(t.updates[0]);
    EXPECT_TRUE(u.full);
    EXPECT_EQ(u.width, 64);
    EXPECT_EQ(u.height, 64);

    // The safety net: a waiting rectangle of the same view id that the frame no longer holds is
    // never merged; the client gets the whole frame.
    held->store(1);
    rig.outbox.postImage(3, big, frame, {100, 100, 43, 43}, false, 4, {});
    rig.outbox.postImage(3, small, smaller, {0, 0, 8, 8}, false, 5, {});
    held->store(0);
    t = rig.outbox.take(live);
    ASSERT_EQ(t.updates.size(), 1u);
    u = decoded(t.updates[0]);
    EXPECT_TRUE(u.full);
    EXPECT_LE(u.x + u.width, 64);
    EXPECT_LE(u.y + u.height, 64);
}

// zstd clients get rectangles coded against the pixels they hold (the outbox's shadow). A
// rectangle merged into a newer update before it left was never seen: its pixels go back into
// the shadow first, so the merged update is coded against what the client really holds.
TEST(Outbox, PredictedUpdatesAreCodedAgainstWhatTheClientReallyHolds) {
    OutboxRig rig(0);
    const Camera cam = cameraFor(48, 48);
    Host::InFlight held = inFlight(0);
    rig.outbox.join(4, held, Codec::Zstd, Codec::Lz4);
    Dbi frame = picture(48, 48, 0);
    rig.outbox.postImage(4, cam, frame, frame.bounds(), true, 1, {});
    ClientCopy client{cam, {}, 0};
    Outbox::Taken t = rig.outbox.take(live);
    ASSERT_EQ(t.updates.size(), 1u);
    client.apply(t.updates[0]);
    // Acknowledged: the outbox knows the client holds exactly its copy (rectangles after a full
    // image go lossy, and are predicted only then).
    rig.outbox.acknowledge(4, ImageAck{0, decoded(t.updates[0]).sequence});

    held->store(1); // what follows waits, merging
    const PixelRect a{2, 2, 12, 12}, b{8, 8, 20, 10};
    frame = with(frame, picture(48, 48, 3), a);
    rig.outbox.postImage(4, cam, frame, a, false, 10, {});
    frame = with(frame, picture(48, 48, 4), b);
    rig.outbox.postImage(4, cam, frame, b, false, 20, {});
    held->store(0);
    t = rig.outbox.take(live);
    ASSERT_EQ(t.updates.size(), 1u);
    EXPECT_TRUE(decoded(t.updates[0]).predicted);
    client.apply(t.updates[0]);
    EXPECT_EQ(client.resyncs, 0);
    EXPECT_TRUE(compare(client.dbi, quantised(frame, cam)).identical());
    ASSERT_NE(rig.outbox.shadow(4), nullptr);
    EXPECT_TRUE(compare(*rig.outbox.shadow(4), frame).identical());

    // A switch to volume mode forgets the copy: the next DBI is a full one.
    rig.outbox.modeChanged(4, Sync::Volume, Codec::Lz4);
    EXPECT_TRUE(rig.outbox.shadow(4)->empty());
}

// Clients of one view that hold the same pixels get one coding of a change (a classroom's
// watchers share views); a client that holds other pixels gets its own. Each copy ends as the
// frame, bit for bit through the quantiser.
TEST(Outbox, ClientsHoldingTheSamePixelsShareOneCodingOfAChange) {
    OutboxRig rig(0);
    const Camera cam = cameraFor(48, 48);
    const Dbi first = picture(48, 48, 0), other = picture(48, 48, 9);
    std::map<uint16_t, ClientCopy> clients;
    for (uint16_t id : {1, 2, 3}) {
        rig.outbox.join(id, inFlight(0), Codec::Zstd, Codec::Lz4);
        rig.outbox.postImage(id, cam, id == 3 ? other : first, first.bounds(), true, 1, {},
                             id != 3);
        clients[id] = ClientCopy{cam, {}, 0};
    }
    auto deliver = [&] {
        std::map<uint16_t, ImageUpdate> sent;
        for (const Outbox::Ready& r : rig.outbox.take(live).updates) {
            clients[r.client].apply(r);
            sent[r.client] = decoded(r);
            rig.outbox.acknowledge(r.client, ImageAck{0, sent[r.client].sequence});
        }
        return sent;
    };
    auto shared = [&] {
        return rig.book.read([](const ServerReport& r) { return r.counters.codingsShared; });
    };
    ASSERT_EQ(deliver().size(), 3u);
    EXPECT_EQ(shared(), 1u); // client 2's full image is client 1's

    const PixelRect change{6, 4, 20, 14};
    const Dbi frame = with(first, picture(48, 48, 5), change);
    for (uint16_t id : {1, 2, 3})
        rig.outbox.postImage(id, cam, frame, change, false, 10, {}, id != 3);
    std::map<uint16_t, ImageUpdate> sent = deliver();
    ASSERT_EQ(sent.size(), 3u);
    EXPECT_EQ(shared(), 2u);
    EXPECT_TRUE(sent[1].predicted && sent[2].predicted && sent[3].predicted);
    EXPECT_EQ(sent[1].payload, sent[2].payload);
    EXPECT_EQ(sent[1].baseHash, sent[2].baseHash);
    EXPECT_NE(sent[1].baseHash, sent[3].baseHash); // coded against what client 3 holds
    EXPECT_NE(sent[1].sequence, sent[2].sequence);
    for (uint16_t id : {1, 2}) {
        EXPECT_EQ(clients[id].resyncs, 0);
        EXPECT_TRUE(compare(clients[id].dbi, quantised(frame, cam)).identical()) << id;
    }
    EXPECT_TRUE(
        compare(clients[3].dbi.extract(change), quantised(frame, cam).extract(change)).identical());

    // A coding is kept only for clients that follow (keeping it costs copies).
    const Dbi next = with(frame, picture(48, 48, 6), change);
    for (uint16_t id : {1, 2})
        rig.outbox.postImage(id, cam, next, change, false, 20, {});
    sent = deliver();
    EXPECT_EQ(shared(), 2u);
    EXPECT_EQ(sent[1].payload, sent[2].payload);
    EXPECT_TRUE(compare(clients[2].dbi, quantised(next, cam)).identical());
}

// A volume client held back with an update waiting: newer changes are only noted, not merged and
// coded again at every batch, and go coded once, in one update, when the waiting one has gone.
// Nothing is lost: the client's copy ends as the server's volume.
TEST(Outbox, AHeldBackVolumeClientsChangesAreCodedOnceNotAtEveryBatch) {
    OutboxRig rig(1);
    Volume volume = makeSphere(32);
    Host::InFlight held = inFlight(0);
    rig.outbox.join(9, held, Codec::Lz4, Codec::Lz4);
    rig.outbox.offerVolume(9, volume, VolumeChange{volume.bounds(), true, true, 1, 0});
    Volume copy;
    auto apply = [&](const Outbox::Ready& r) {
        ASSERT_EQ(r.mode, Sync::Volume);
        VolumeUpdate u;
        ASSERT_TRUE(decodeMessage(r.message, u));
        if (u.full) {
            ASSERT_TRUE(decodeVolumeFull(u.payload, u.rawBytes, u.codec, volume.dims(),
                                         volume.spacing(), copy));
            return;
        }
        std::vector<uint8_t> bytes;
        ASSERT_TRUE(decompressBytes(u.payload, u.codec, u.rawBytes, bytes));
        const Box3i box{{u.x, u.y, u.z}, {u.x + u.sizeX, u.y + u.sizeY, u.z + u.sizeZ}};
        ASSERT_TRUE(applyVolumeBox(copy, box, bytes));
    };
    Outbox::Taken t = rig.outbox.take(live);
    ASSERT_EQ(t.updates.size(), 1u);
    apply(t.updates[0]);
    EXPECT_EQ(rig.encodes(Sync::Volume), 1u) << "the whole volume at the join";

    held->store(100); // from here nothing sent to it is acknowledged
    auto cut = [&](int i) {
        const Box3i box{{10 + i, 10, 26}, {14 + i, 14, 32}};
        volume.fill(box, 0, Material::Air);
        rig.outbox.offerVolume(9, volume, VolumeChange{box, false, false, uint64_t(10 + i), 3});
        EXPECT_TRUE(rig.outbox.take(live).updates.empty()) << "held back";
    };
    for (int i = 0; i < 10; ++i)
        cut(i);
    EXPECT_EQ(rig.encodes(Sync::Volume), 2u) << "the first cut, coded and waiting; the rest noted";
    EXPECT_FALSE(rig.outbox.empty()) << "changes noted and not yet sent";
    rig.outbox.offerNoted(volume);
    EXPECT_EQ(rig.encodes(Sync::Volume), 2u) << "still held: still only noted";

    held->store(0);
    t = rig.outbox.take(live);
    ASSERT_EQ(t.updates.size(), 1u);
    apply(t.updates[0]);
    rig.outbox.offerNoted(volume);
    t = rig.outbox.take(live);
    ASSERT_EQ(t.updates.size(), 1u);
    apply(t.updates[0]);
    VolumeUpdate last;
    ASSERT_TRUE(decodeMessage(t.updates[0].message, last));
    EXPECT_EQ(last.causeServerUs, 11u) << "the oldest noted cause";
    EXPECT_EQ(last.erodeUs, 27u) << "every noted batch's erosion";
    EXPECT_EQ(rig.encodes(Sync::Volume), 3u);
    EXPECT_TRUE(copy == volume);
    EXPECT_TRUE(rig.outbox.empty());
}

namespace {

// An outbox coding full images over 64 x 64 on a coder thread, as the threaded server does, with
// client 1 joined (lz4) on a 128 x 128 view.
struct CodedApart {
    ReportBook book;
    WorkerExecutor coder{"test-coder", 10};
    Outbox outbox{1 << 20, book, steadyNowUs};
    const Camera cam = cameraFor(128, 128);
    CodedApart() {
        outbox.codeFullImagesApart(64 * 64, coder);
        outbox.join(1, inFlight(), Codec::Lz4, Codec::Lz4);
    }
};

} // namespace

// A full image of a large view is coded on the coder thread from the pixels at the post; a change
// posted meanwhile goes after it as a rectangle of its own (the full image is never coded again),
// and the client's copy ends as the frame. A small full image is still coded at the post.
TEST(Outbox, AFullImageCodedApartGoesFirstAndALaterChangeWaitsBehindIt) {
    CodedApart rig;
    Outbox& outbox = rig.outbox;
    const Camera& cam = rig.cam;
    Dbi frame = picture(128, 128, 0);
    const Dbi posted = frame;
    outbox.postImage(1, cam, frame, frame.bounds(), true, 10, {});
    const PixelRect rect{20, 30, 16, 8};
    frame = with(frame, picture(128, 128, 5), rect);
    outbox.postImage(1, cam, frame, rect, false, 20, {});
    outbox.finishCoding();
    Outbox::Taken t = outbox.take(live);
    ASSERT_EQ(t.updates.size(), 2u);
    const ImageUpdate first = decoded(t.updates[0]), second = decoded(t.updates[1]);
    EXPECT_TRUE(first.full);
    EXPECT_EQ(first.causeServerUs, 10u);
    EXPECT_FALSE(second.full);
    EXPECT_EQ(second.causeServerUs, 20u);
    EXPECT_EQ(second.width, 16) << "the rectangle alone, not merged into the full image";
    EXPECT_LT(first.sequence, second.sequence);
    ClientCopy copy{cam, {}};
    copy.apply(t.updates[0]);
    EXPECT_TRUE(compare(copy.dbi, quantised(posted, cam)).identical()) << "the pixels posted";
    copy.apply(t.updates[1]);
    EXPECT_TRUE(compare(copy.dbi, quantised(frame, cam)).identical());
    EXPECT_TRUE(outbox.empty());

    outbox.join(2, inFlight(), Codec::Lz4, Codec::Lz4);
    const Camera small = cameraFor(32, 32);
    const Dbi smallFrame = picture(32, 32, 1);
    outbox.postImage(2, small, smallFrame, smallFrame.bounds(), true, 30, {});
    t = outbox.take(live); // no waiting for the coder
    ASSERT_EQ(t.updates.size(), 1u);
    EXPECT_TRUE(decoded(t.updates[0]).full);
}

// A newer full image supersedes one being coded (with the older cause), and a view change drops
// it: what the coder made of them never leaves.
TEST(Outbox, AFullImageBeingCodedIsSupersededOrDroppedLikeAnyWaitingImage) {
    CodedApart rig;
    Outbox& outbox = rig.outbox;
    const Camera& cam = rig.cam;
    const Dbi older = picture(128, 128, 0), newer = picture(128, 128, 9);
    outbox.postImage(1, cam, older, older.bounds(), true, 10, {});
    outbox.postImage(1, cam, newer, newer.bounds(), true, 20, {});
    outbox.finishCoding();
    Outbox::Taken t = outbox.take(live);
    ASSERT_EQ(t.updates.size(), 1u);
    EXPECT_EQ(decoded(t.updates[0]).causeServerUs, 10u);
    ClientCopy copy{cam, {}};
    copy.apply(t.updates[0]);
    EXPECT_TRUE(compare(copy.dbi, quantised(newer, cam)).identical());

    outbox.postImage(1, cam, older, older.bounds(), true, 30, {});
    outbox.viewChanged(1, 1);
    outbox.finishCoding();
    EXPECT_TRUE(outbox.take(live).updates.empty());
    EXPECT_TRUE(outbox.empty());
}

// What a task owns is freed before the worker takes its lock again: freeing a dropped view's
// frames takes milliseconds, and a post meanwhile (the simulation thread's) must not wait for it.
TEST(WorkerExecutor, ATasksCapturesAreFreedOutsideTheLockAPostTakes) {
    WorkerExecutor worker{"test-worker", 0};
    std::promise<void> freeing, released;
    std::shared_future<void> release = released.get_future().share();
    struct SlowToFree {
        std::promise<void>* freeing = nullptr;
        std::shared_future<void> release;
        ~SlowToFree() {
            if (!freeing)
                return;
            freeing->set_value();
            release.wait_for(std::chrono::seconds(10)); // a bound, should the lock be held
        }
    };
    auto owned = std::make_shared<SlowToFree>();
    owned->freeing = &freeing;
    owned->release = release;
    worker.post([owned = std::move(owned)] {});
    freeing.get_future().wait();
    std::atomic<bool> ran{false};
    const auto t0 = std::chrono::steady_clock::now();
    worker.post([&] { ran = true; }); // returns at once unless the freeing task holds the lock
    const auto waited = std::chrono::steady_clock::now() - t0;
    released.set_value();
    worker.drain();
    EXPECT_TRUE(ran);
    EXPECT_LT(waited, std::chrono::seconds(5)) << "the post waited for the free";
}

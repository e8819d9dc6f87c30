// ClientThread against an in-process session server over loopback: snapshots, applied
// rectangles, a failed connection that retries instead of crashing, and the replicated-volume
// design (requestSync, per-mode figures, drained voxel boxes, the local volume). No GL.
#include "net/client_thread.h"

#include "libsim/skull.h"
#include "libsim/tool.h"
#include "net/session_server.h"
#include "net/view.h"

#include "loopback.h"
#include <glm/gtx/quaternion.hpp>

#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <memory>
#include <random>
#include <stdexcept>
#include <thread>

using namespace trephine;
using namespace trephine::net;

using trephine::testing::drillThrough;
using trephine::testing::loopbackServerConfig;
using trephine::testing::Pumped;
using trephine::testing::waitFor;

namespace {

// Pumps until the server has sent everything and the client thread has applied (or rejected)
// every update the server sent (one client).
bool caughtUp(SessionServer& server, ClientThread& client) {
    return waitFor([&] {
        const uint64_t sent =
            server.modeTotals(Sync::Dbi).updates + server.modeTotals(Sync::Volume).updates;
        auto s = client.snapshot();
        return server.idle() && s->updatesApplied + s->updatesRejected >= sent;
    });
}

} // namespace

TEST(ClientThread, PublishesSnapshotsAndDrilledRectangles) {
    Volume skull = makeSkull(64);
    SurfaceSite site = defaultBurrSite(skull);
    ServerConfig sc = loopbackServerConfig("skull:64");
    SessionServer server(skull, sc);
    Pumped pumped(server);

    ClientThreadConfig cc;
    cc.address = "127.0.0.1:" + std::to_string(server.port());
    Camera cam = cameraLookingAt(site.position, site.normal, 150.0f, 45.0f, {128, 128}, skull);
    cc.client.view = toViewSpec(cam);
    ClientThread client(cc);
    client.start();
    ASSERT_TRUE(waitFor([&] { return client.snapshot()->hasFullImage; }, 20.0));
    auto snap = client.snapshot();
    EXPECT_EQ(snap->state, LinkState::Connected);
    ASSERT_TRUE(snap->welcome.has_value());
    EXPECT_EQ(snap->welcome->volumeName, "skull:64");

    Dbi mirror;
    auto drain = [&] {
        for (AppliedRect& r : client.drainRects()) {
            if (r.full)
                mirror = r.pixels;
            else {
                ASSERT_FALSE(mirror.empty());
                ASSERT_TRUE(mirror.bounds().contains(r.rect));
                ASSERT_EQ(r.pixels.width(), r.rect.w);
                mirror.apply(r.pixels, r.rect.x, r.rect.y);
            }
        }
    };
    drain();
    ASSERT_FALSE(mirror.empty());
    const Dbi first = mirror;
    // Drill in at the site for 0.5 s of tool states.
    drillThrough(client, site, 50);
    ASSERT_TRUE(waitFor([&] { return client.rectsPublished() > 1 && server.idle(); }, 20.0));
    ASSERT_TRUE(caughtUp(server, client));
    drain();
    EXPECT_FALSE(compare(first, mirror).identical()) << "drilling changed the image";
    // The mirror built from rectangles matches a fresh render of the drilled volume.
    Dbi truth = server.renderView(cc.client.view);
    // Colour exactly; depth to the codec's precision.
    DbiDiff diff = compare(mirror, truth);
    EXPECT_EQ(diff.maxColorError, 0) << diff.describe();
    EXPECT_LT(diff.maxDepthError, 1e-5f) << diff.describe();
    EXPECT_GT(client.snapshot()->hapticModels, 0u);
    client.stop();
    EXPECT_EQ(client.snapshot()->state, LinkState::Stopped);
    server.stop();
}

TEST(ClientThread, NoServerMeansRetryingWithAReason) {
    ClientThreadConfig cc;
    cc.address = "127.0.0.1:1"; // nothing listens there
    cc.connectTimeoutS = 0.3;
    cc.retryS = 0.1;
    ClientThread client(cc);
    client.start();
    ASSERT_TRUE(waitFor([&] { return client.snapshot()->attempts >= 2; }, 10.0));
    auto snap = client.snapshot();
    EXPECT_NE(snap->state, LinkState::Connected);
    EXPECT_FALSE(snap->closeReason.empty());
    client.stop();
}

TEST(ClientThread, ViewChangeWaitsThenDeliversAFullImage) {
    Volume skull = makeSkull(64);
    ServerConfig sc = loopbackServerConfig("skull:64");
    SessionServer server(skull, sc);
    Pumped pumped(server);
    ClientThreadConfig cc;
    cc.address = "127.0.0.1:" + std::to_string(server.port());
    cc.client.view = toViewSpec(cameraPreset("top", skull, {96, 96}));
    ClientThread client(cc);
    client.start();
    ASSERT_TRUE(waitFor([&] { return client.snapshot()->hasFullImage; }, 20.0));
    client.drainRects();
    ViewSpec side = toViewSpec(cameraPreset("left", skull, {80, 64}));
    ASSERT_TRUE(client.requestView(side));
    ASSERT_TRUE(waitFor(
        [&] {
            auto s = client.snapshot();
            return s->hasFullImage && s->view == side;
        },
        20.0));
    EXPECT_FALSE(client.snapshot()->waitingForView);
    bool gotFull = false;
    for (AppliedRect& r : client.drainRects())
        if (r.full && r.pixels.width() == 80 && r.pixels.height() == 64) {
            gotFull = true;
            EXPECT_EQ(compare(r.pixels, server.renderView(side)).maxColorError, 0);
        }
    EXPECT_TRUE(gotFull);
    client.stop();
    server.stop();
}

namespace {
// A client thread of the top view of skull:64 on `port` that retries every 0.2 s.
ClientThreadConfig reconnectingClient(const Volume& skull, uint16_t port) {
    ClientThreadConfig cc;
    cc.address = "127.0.0.1:" + std::to_string(port);
    cc.client.view = toViewSpec(cameraPreset("top", skull, {64, 64}));
    cc.retryS = 0.2;
    cc.connectTimeoutS = 1.0;
    return cc;
}

// Whether the thread is connected with a whole picture within `seconds`.
bool connectedWithPicture(const ClientThread& client, double seconds) {
    return waitFor(
        [&] {
            auto s = client.snapshot();
            return s->state == LinkState::Connected && s->hasFullImage;
        },
        seconds);
}
} // namespace

TEST(ClientThread, ReconnectsToANewServerOnTheSamePort) {
    Volume skull = makeSkull(64);
    ServerConfig sc = loopbackServerConfig("skull:64");
    auto server = std::make_unique<SessionServer>(skull, sc);
    const uint16_t port = server->port();
    auto pumped = std::make_unique<Pumped>(*server);

    ClientThreadConfig cc = reconnectingClient(skull, port);
    ClientThread client(cc);
    client.start();
    ASSERT_TRUE(waitFor([&] { return client.snapshot()->hasFullImage; }, 20.0));
    const int attemptsBefore = client.snapshot()->attempts;
    EXPECT_GE(client.snapshot()->packetLoss, 0.0) << "ENet's loss estimate, once connected";
    client.drainRects();

    // The server goes away: the thread says why and retries.
    server->stop();
    pumped.reset();
    server.reset();
    std::shared_ptr<const ClientSnapshot> dropped;
    ASSERT_TRUE(waitFor(
        [&] {
            dropped = client.snapshot();
            return dropped->state == LinkState::Retrying;
        },
        10.0));
    EXPECT_EQ(dropped->closeReason, refuseReasonText(uint32_t(RefuseReason::Shutdown)));
    EXPECT_FALSE(dropped->hasFullImage);
    // The view stays the one asked for (a default one jumped a volume-mode window elsewhere).
    EXPECT_TRUE(dropped->view == cc.client.view);
    ASSERT_TRUE(waitFor([&] { return client.snapshot()->attempts > attemptsBefore; }, 10.0));
    EXPECT_NE(client.snapshot()->state, LinkState::Connected);

    // A new server on the same port: the thread reconnects and gets a whole image again.
    sc.port = port;
    server = std::make_unique<SessionServer>(skull, sc);
    pumped = std::make_unique<Pumped>(*server);
    ASSERT_TRUE(connectedWithPicture(client, 20.0));
    EXPECT_TRUE(client.snapshot()->closeReason.empty());
    EXPECT_GT(client.snapshot()->attempts, attemptsBefore);
    bool gotFull = false;
    for (AppliedRect& r : client.drainRects())
        if (r.full) {
            gotFull = true;
            EXPECT_EQ(compare(r.pixels, server->renderView(cc.client.view)).maxColorError, 0);
        }
    EXPECT_TRUE(gotFull) << "a full image after reconnecting";
    client.stop();
    server->stop();
}

// An instructor's snapshot carries the session's codes; a new instructor code it asks for is
// published, and is the one its reconnects prove (the old one joins nobody any more).
TEST(ClientThread, AnInstructorSeesTheCodesAndReconnectsWithTheNewOneItIssued) {
    Volume skull = makeSkull(64);
    ServerConfig sc = loopbackServerConfig("skull:64");
    sc.traineeCode = "QX7M-4KTD";
    sc.instructorCode = "HW2R-9PZE";
    auto server = std::make_unique<SessionServer>(skull, sc);
    const uint16_t port = server->port();
    auto pumped = std::make_unique<Pumped>(*server);
    ClientThreadConfig cc = reconnectingClient(skull, port);
    cc.client.role = Role::Instructor;
    cc.client.code = sc.instructorCode;
    ClientThread client(cc);
    client.start();
    ASSERT_TRUE(waitFor([&] { return client.snapshot()->codes.has_value(); }, 20.0));
    EXPECT_EQ(client.snapshot()->codes->trainee, sc.traineeCode);
    EXPECT_EQ(client.snapshot()->codes->instructor, sc.instructorCode);
    ASSERT_TRUE(client.newCode(Role::Instructor));
    ASSERT_TRUE(waitFor([&] { return client.snapshot()->codes->instructor != "HW2R-9PZE"; }, 20.0));
    const std::string fresh = client.snapshot()->codes->instructor;
    EXPECT_EQ(client.snapshot()->codes->trainee, sc.traineeCode);

    // A server on the same port that knows only the new code: the thread joins it with that.
    server->stop();
    pumped.reset();
    server.reset();
    ASSERT_TRUE(waitFor([&] { return client.snapshot()->state != LinkState::Connected; }, 10.0));
    sc.port = port;
    sc.instructorCode = fresh;
    server = std::make_unique<SessionServer>(skull, sc);
    pumped = std::make_unique<Pumped>(*server);
    ASSERT_TRUE(waitFor(
        [&] {
            auto s = client.snapshot();
            return s->state == LinkState::Connected && s->codes.has_value();
        },
        20.0))
        << client.snapshot()->closeReason;
    EXPECT_EQ(client.snapshot()->codes->instructor, fresh);
    client.stop();
    server->stop();
}

// A switch and a view asked for while the link is down are not lost: the thread makes them on
// the next connection (its hello, or right after the welcome when the request came later).
TEST(ClientThread, ASwitchAndAViewAskedWhileDisconnectedAreMadeOnReconnect) {
    Volume skull = makeSkull(64);
    ServerConfig sc = loopbackServerConfig("skull:64");
    auto server = std::make_unique<SessionServer>(skull, sc);
    const uint16_t port = server->port();
    auto pumped = std::make_unique<Pumped>(*server);

    ClientThreadConfig cc = reconnectingClient(skull, port);
    cc.client.renderLocally = false;
    ClientThread client(cc);
    client.start();
    ASSERT_TRUE(waitFor([&] { return client.snapshot()->hasFullImage; }, 20.0));

    server->stop();
    pumped.reset();
    server.reset();
    ASSERT_TRUE(waitFor([&] { return client.snapshot()->state == LinkState::Retrying; }, 10.0));
    const ViewSpec side = toViewSpec(cameraPreset("working", skull, {64, 64}));
    ASSERT_FALSE(side == cc.client.view);
    ASSERT_TRUE(client.requestSync(Sync::Volume));
    ASSERT_TRUE(client.requestView(side));

    sc.port = port;
    server = std::make_unique<SessionServer>(skull, sc);
    pumped = std::make_unique<Pumped>(*server);
    std::shared_ptr<const ClientSnapshot> s;
    ASSERT_TRUE(waitFor(
        [&] {
            s = client.snapshot();
            return s->state == LinkState::Connected && s->sync == Sync::Volume && s->view == side;
        },
        20.0))
        << "sync " << int(s->sync) << ", requested " << int(s->requestedSync)
        << ", view matches: " << (s->view == side);
    bool fullVolume = false;
    ASSERT_TRUE(waitFor(
        [&] {
            for (const AppliedVolumeBox& b : client.drainVolumeBoxes())
                fullVolume = fullVolume || b.full;
            return fullVolume;
        },
        20.0))
        << "the whole volume, once the switch is made";
    client.stop();
    server->stop();
}

namespace {

// Drills at `site` for `states` tool states 10 ms apart, feeding `depthStart` + 0.08 mm a state.
void drillThrough(ClientThread& client, const SurfaceSite& site, int states, float depthStart) {
    for (int i = 0; i < states; ++i) {
        ToolState t;
        t.toolKind = uint8_t(ToolKind::Burr);
        t.diameterMm = 5.0f;
        t.position = site.position - site.normal * (depthStart + 0.08f * float(i));
        t.orientation = glm::rotation(glm::vec3(0, 0, 1), site.normal);
        t.speed = 1.0f;
        t.drilling = true;
        EXPECT_TRUE(client.sendToolState(t));
        trephine::testing::pumpFor(0.010);
    }
}

// A window's copy of the volume, rebuilt from drained boxes as the trainer window does.
struct VolumeMirror {
    Volume volume;
    int fulls = 0, boxes = 0;
    void apply(const AppliedVolumeBox& b) {
        if (b.full) {
            ASSERT_EQ(b.box.lo, glm::ivec3(0));
            ASSERT_EQ(b.box.hi, b.dims);
            volume = Volume(b.dims, b.spacing);
            ++fulls;
        } else {
            ASSERT_FALSE(volume.empty()) << "a box before the whole volume";
            ++boxes;
        }
        ASSERT_EQ(b.density.size(), size_t(b.box.count()));
        ASSERT_EQ(b.material.size(), size_t(b.box.count()));
        size_t o = 0;
        for (int z = b.box.lo.z; z < b.box.hi.z; ++z)
            for (int y = b.box.lo.y; y < b.box.hi.y; ++y)
                for (int x = b.box.lo.x; x < b.box.hi.x; ++x, ++o) {
                    const size_t i = volume.index(x, y, z);
                    volume.densityData()[i] = b.density[o];
                    volume.materialData()[i] = b.material[o];
                }
    }
};

int64_t differingVoxels(const Volume& a, const Volume& b) {
    if (a.dims() != b.dims())
        return -1;
    int64_t n = 0;
    for (size_t i = 0; i < a.voxelCount(); ++i)
        n += a.densityData()[i] != b.densityData()[i] || a.materialData()[i] != b.materialData()[i];
    return n;
}

} // namespace

// A window's client thread (renderLocally off) switched DBI -> volume -> DBI while drilling: the
// snapshot says which design feeds the picture, the drained boxes rebuild exactly the server's
// volume, the local volume is readable for haptics only in volume mode, each mode keeps its
// figures while the other runs, and the DBI after the switch back is the server's render.
TEST(ClientThread, RequestSyncDrainsVolumeBoxesAndKeepsPerModeFigures) {
    Volume skull = makeSkull(64);
    SurfaceSite site = defaultBurrSite(skull);
    ServerConfig sc = loopbackServerConfig("skull:64");
    SessionServer server(skull, sc);
    Pumped pumped(server);

    ClientThreadConfig cc;
    cc.address = "127.0.0.1:" + std::to_string(server.port());
    Camera cam = cameraLookingAt(site.position, site.normal, 150.0f, 45.0f, {96, 96}, skull);
    cc.client.view = toViewSpec(cam);
    cc.client.renderLocally = false;
    ClientThread client(cc);
    client.start();
    ASSERT_TRUE(waitFor([&] { return client.snapshot()->hasFullImage; }, 20.0));
    EXPECT_EQ(client.snapshot()->sync, Sync::Dbi);
    EXPECT_FALSE(client.withLocalVolume([](const Volume&) {})) << "no volume in DBI mode";
    drillThrough(client, site, 20, -1.0f);
    ASSERT_TRUE(waitFor([&] { return client.snapshot()->modes[0].updatesApplied > 1; }, 20.0));
    ASSERT_TRUE(waitFor([&] { return server.idle(); }, 20.0));
    EXPECT_TRUE(client.drainVolumeBoxes().empty()) << "no voxel boxes in DBI mode";

    // To volume: the switch waits for the whole volume, then boxes follow the drilling.
    ASSERT_TRUE(client.requestSync(Sync::Volume));
    ASSERT_TRUE(waitFor([&] { return client.snapshot()->sync == Sync::Volume; }, 20.0));
    EXPECT_EQ(client.snapshot()->requestedSync, Sync::Volume);
    VolumeMirror mirror;
    for (const AppliedVolumeBox& b : client.drainVolumeBoxes())
        mirror.apply(b);
    ASSERT_EQ(mirror.fulls, 1) << "the whole volume at the switch";
    EXPECT_EQ(mirror.volume.dims(), skull.dims());
    EXPECT_EQ(differingVoxels(mirror.volume, server.volumeSnapshot()), 0)
        << "the whole volume includes the drilling done in DBI mode";
    const ModeFigures dbiBefore = client.snapshot()->modes[size_t(Sync::Dbi)];
    EXPECT_GT(dbiBefore.meanBytes, 0.0);

    SurfaceSite beside = site; // a fresh spot next to the first hole
    beside.position += glm::normalize(glm::cross(site.normal, glm::vec3(1, 0, 0))) * 8.0f;
    drillThrough(client, beside, 25, -1.0f);
    ASSERT_TRUE(waitFor([&] { return client.volumeBoxesPublished() > 1 && server.idle(); }, 20.0))
        << client.volumeBoxesPublished() << " boxes, volume updates "
        << client.snapshot()->modes[1].updatesApplied << ", sync " << int(client.snapshot()->sync)
        << " tool states " << client.snapshot()->toolStatesSent << " server volume updates "
        << server.modeTotals(Sync::Volume).updates;
    ASSERT_TRUE(caughtUp(server, client));
    for (const AppliedVolumeBox& b : client.drainVolumeBoxes())
        mirror.apply(b);
    EXPECT_GT(mirror.boxes, 0) << "drilling in volume mode sends boxes";
    EXPECT_EQ(differingVoxels(mirror.volume, server.volumeSnapshot()), 0)
        << "boxes rebuild the server's volume exactly";
    // The haptic thread's view of the local volume: the same voxels.
    int64_t localDiff = -2;
    EXPECT_TRUE(client.withLocalVolume(
        [&](const Volume& v) { localDiff = differingVoxels(v, mirror.volume); }));
    EXPECT_EQ(localDiff, 0);

    auto inVolume = client.snapshot();
    const ModeFigures& vol = inVolume->modes[size_t(Sync::Volume)];
    EXPECT_GE(vol.updatesApplied, uint64_t(mirror.fulls + mirror.boxes));
    EXPECT_GT(vol.meanRawBytes, 0.0);
    EXPECT_GT(vol.latencyP50Us, 0.0) << "box updates carry their latency";
    EXPECT_GE(vol.latencyP99Us, vol.latencyP50Us);
    EXPECT_EQ(inVolume->modes[size_t(Sync::Dbi)].updatesApplied, dbiBefore.updatesApplied)
        << "the DBI's figures stay while the volume runs";
    EXPECT_EQ(inVolume->modes[size_t(Sync::Dbi)].meanBytes, dbiBefore.meanBytes);

    // Back to DBI: a full image of the drilled skull, the local volume is dropped.
    client.drainRects();
    ASSERT_TRUE(client.requestSync(Sync::Dbi));
    ASSERT_TRUE(waitFor([&] { return client.snapshot()->sync == Sync::Dbi; }, 20.0));
    bool gotFull = false;
    for (AppliedRect& r : client.drainRects())
        if (r.full) {
            gotFull = true;
            EXPECT_EQ(compare(r.pixels, server.renderView(cc.client.view)).maxColorError, 0)
                << "no drilling lost across the switches";
        }
    EXPECT_TRUE(gotFull);
    EXPECT_FALSE(client.withLocalVolume([](const Volume&) {}));
    EXPECT_EQ(client.snapshot()->modes[size_t(Sync::Volume)].updatesApplied, vol.updatesApplied)
        << "the volume's figures stay while the DBI runs";
    client.stop();
    server.stop();
}

// A client thread asked for volume mode from the start gets the whole volume at join, and a
// box queue that overflows becomes one whole copy of the volume (nothing lost).
TEST(ClientThread, StartsInVolumeModeAndOverflowBecomesOneFullCopy) {
    Volume skull = makeSkull(64);
    SurfaceSite site = defaultBurrSite(skull);
    ServerConfig sc = loopbackServerConfig("skull:64");
    SessionServer server(skull, sc);
    Pumped pumped(server);
    ClientThreadConfig cc;
    cc.address = "127.0.0.1:" + std::to_string(server.port());
    cc.client.view = toViewSpec(cameraPreset("top", skull, {64, 64}));
    cc.client.sync = Sync::Volume;
    cc.client.renderLocally = false;
    cc.maxQueuedRects = 2; // a window that falls behind
    ClientThread client(cc);
    client.start();
    ASSERT_TRUE(waitFor([&] { return client.volumeBoxesPublished() > 0; }, 20.0));
    auto snap = client.snapshot();
    EXPECT_EQ(snap->sync, Sync::Volume);
    EXPECT_EQ(snap->requestedSync, Sync::Volume);
    EXPECT_EQ(client.rectsPublished(), 0u) << "no images in volume mode";

    // Drill without draining: more boxes than the queue holds.
    drillThrough(client, site, 40, -1.0f);
    ASSERT_TRUE(waitFor([&] { return client.volumeBoxesPublished() > 4 && server.idle(); }, 20.0));
    ASSERT_TRUE(caughtUp(server, client));
    VolumeMirror mirror;
    for (const AppliedVolumeBox& b : client.drainVolumeBoxes())
        mirror.apply(b);
    EXPECT_GE(mirror.fulls, 1) << "the overflow (or the join) as one whole volume";
    EXPECT_EQ(differingVoxels(mirror.volume, server.volumeSnapshot()), 0);
    client.stop();
    server.stop();
}

// An undo of a cleared list re-adds every mark in one frame, beside a tool state and a view
// request: the command queue takes them all (it held 256, so the last mark was dropped).
TEST(ClientThread, AWholeListOfMarksFitsTheCommandQueueInOneFrame) {
    ClientThreadConfig config;
    ClientThread thread(config); // not started: commands only queue
    EXPECT_TRUE(thread.sendToolState(ToolState{}));
    EXPECT_TRUE(thread.requestView(ViewSpec{}));
    int refused = 0;
    for (int i = 0; i < kMaxAnnotations; ++i) {
        Annotate a;
        a.op = Annotate::Op::Add;
        a.position = glm::vec3(float(i), 0.0f, 0.0f);
        refused += !thread.annotate(a);
    }
    EXPECT_EQ(refused, 0);
}

// A volume the server cannot send whole (noise that does not compress into a message): the
// volume design is refused with VolumeTooLarge. The thread asked for it again at every reconnect,
// for good (each refusal a whole volume's encode for the server, and no picture ever); it now
// goes on in DBI and says how many refusals there were.
TEST(ClientThread, AVolumeDesignTheServerRefusesIsNotAskedForAgain) {
    const Volume noise = trephine::testing::incompressibleVolume();
    SessionServer server(noise, loopbackServerConfig("noise", 2));
    Pumped pumped(server);
    ClientThreadConfig cc = reconnectingClient(noise, server.port());
    cc.client.sync = Sync::Volume;
    cc.client.volumeCodec = Codec::Zstd;
    cc.client.renderLocally = false;
    cc.retryS = 0.1;
    ClientThread client(cc);
    client.start();
    ASSERT_TRUE(waitFor([&] { return client.snapshot()->volumeRefusals == 1; }, 60.0));
    ASSERT_TRUE(connectedWithPicture(client, 30.0)) << "a DBI picture after the refusal";
    trephine::testing::pumpFor(1.0); // a second to see that it does not ask again
    auto s = client.snapshot();
    EXPECT_EQ(s->volumeRefusals, 1);
    EXPECT_EQ(s->attempts, 2);
    EXPECT_EQ(s->state, LinkState::Connected);
    EXPECT_EQ(s->sync, Sync::Dbi);
    EXPECT_EQ(s->requestedSync, Sync::Dbi);
    client.stop();
    server.stop();
}

// A view past the session's total is refused by the server: the snapshot keeps the view held,
// says why, and a reconnect asks for the view held (the refused one would have the hello refused).
TEST(ClientThread, AViewTheServerRefusesIsNotTheNextHellos) {
    Volume skull = makeSkull(64);
    ServerConfig sc = loopbackServerConfig("skull:64");
    sc.maxTotalViewPixels = 96 * 96 + 10;
    auto server = std::make_unique<SessionServer>(skull, sc);
    auto pumped = std::make_unique<Pumped>(*server);
    ClientThreadConfig cc = reconnectingClient(skull, server->port());
    const ViewSpec held = toViewSpec(cameraPreset("top", skull, {96, 96}));
    cc.client.view = held;
    ClientThread client(cc);
    client.start();
    ASSERT_TRUE(waitFor([&] { return client.snapshot()->hasFullImage; }, 20.0));
    const ViewSpec wide = toViewSpec(cameraPreset("top", skull, {128, 128}));
    ASSERT_TRUE(client.requestView(wide));
    ASSERT_TRUE(waitFor([&] { return client.snapshot()->viewRefusal.has_value(); }, 20.0));
    auto s = client.snapshot();
    EXPECT_EQ(*s->viewRefusal, (ViewRefusal{128, 128, 96 * 96 + 10}));
    EXPECT_EQ(s->view, held);
    EXPECT_EQ(viewNotServedText(*s, 128, 128, "--size"),
              "The session's views are full: the server has 9226 pixels free for your view and "
              "this one is 128 x 128");
    // A new server on the same port: the hello asks for the held view, and is let in.
    sc.port = server->port();
    server->stop();
    pumped.reset();
    server.reset();
    ASSERT_TRUE(waitFor([&] { return client.snapshot()->state != LinkState::Connected; }, 10.0));
    server = std::make_unique<SessionServer>(skull, sc);
    pumped = std::make_unique<Pumped>(*server);
    ASSERT_TRUE(connectedWithPicture(client, 30.0)) << client.snapshot()->closeReason;
    EXPECT_EQ(client.snapshot()->view, held);
    client.stop();
    server->stop();
}

// An exception on the client thread (here from the haptic callback; in the field memory for a
// whole volume, or a render pool that cannot start its threads) escaped the thread's body and
// terminated the window without a word: it now ends that connection with its reason, and the
// thread reconnects.
TEST(ClientThread, AnExceptionOnTheClientThreadEndsTheConnectionNotTheProgram) {
    Volume skull = makeSkull(64);
    SessionServer server(skull, loopbackServerConfig("skull:64"));
    Pumped pumped(server);
    ClientThreadConfig cc = reconnectingClient(skull, server.port());
    std::atomic<int> thrown{0};
    cc.onHapticModel = [&](const HapticModel&) {
        if (thrown++ == 0)
            throw std::runtime_error("out of something");
    };
    ClientThread client(cc);
    client.start();
    ASSERT_TRUE(waitFor([&] { return client.snapshot()->hasFullImage; }, 20.0));
    const SurfaceSite site = defaultBurrSite(skull);
    ToolState t;
    t.toolKind = uint8_t(ToolKind::Burr);
    t.diameterMm = 4.0f;
    t.position = site.position;
    ASSERT_TRUE(client.sendToolState(t));
    ASSERT_TRUE(waitFor(
        [&] {
            return client.snapshot()->closeReason.find("out of something") != std::string::npos;
        },
        20.0));
    EXPECT_NE(client.snapshot()->closeReason.find("the connection failed"), std::string::npos);
    // Reconnected, with a picture again.
    EXPECT_TRUE(waitFor(
        [&] {
            auto s = client.snapshot();
            return s->state == LinkState::Connected && s->hasFullImage && s->attempts >= 2;
        },
        20.0));
    client.stop();
    server.stop();
}

// One picture rule for the window and the headless trainee: a full image of the view's size is
// the whole picture; a rectangle counts only for the picture held, of its view and inside it.
TEST(PictureRule, AFullImageOfTheViewIsWholeAndARectCountsOnlyForThePictureHeld) {
    const glm::ivec2 view{64, 48};
    AppliedRect full;
    full.full = true;
    full.viewId = 3;
    full.rect = {0, 0, 64, 48};
    full.pixels = Dbi(64, 48);
    EXPECT_EQ(picturePart(full, view, std::nullopt), PicturePart::Whole);
    AppliedRect placeholder = full;
    placeholder.pixels = Dbi(1, 1);
    placeholder.rect = {0, 0, 1, 1};
    EXPECT_EQ(picturePart(placeholder, view, std::nullopt), PicturePart::None)
        << "the hello's 1 x 1 view";
    AppliedRect rect;
    rect.viewId = 3;
    rect.rect = {10, 10, 8, 8};
    rect.pixels = Dbi(8, 8);
    const HeldPicture held{3, view};
    EXPECT_EQ(picturePart(rect, view, held), PicturePart::Rect);
    EXPECT_EQ(picturePart(rect, view, std::nullopt), PicturePart::None) << "no picture yet";
    rect.viewId = 2;
    EXPECT_EQ(picturePart(rect, view, held), PicturePart::None) << "a view left behind";
    rect.viewId = 3;
    rect.rect = {60, 40, 8, 8};
    EXPECT_EQ(picturePart(rect, view, held), PicturePart::None) << "outside the picture";
    rect.rect = {0, 0, 64, 48};
    rect.pixels = Dbi(64, 48);
    EXPECT_EQ(picturePart(rect, view, held), PicturePart::Rect)
        << "a change as large as the view is still a change of the picture held";
}

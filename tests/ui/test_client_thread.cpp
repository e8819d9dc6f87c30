// ClientThread against an in-process session server over loopback: snapshots, applied
// rectangles, and a failed connection that retries instead of crashing. No GL.
#include "net/client_thread.h"

#include "libsim/skull.h"
#include "libsim/tool.h"
#include "net/session_server.h"
#include "net/view.h"

#include "loopback.h"
#include <glm/gtx/quaternion.hpp>

#include <gtest/gtest.h>

#include <chrono>
#include <memory>
#include <thread>

using namespace trephine;
using namespace trephine::net;

namespace {

using trephine::testing::loopbackServerConfig;
template <class F>
bool waitFor(F pred, double seconds) {
    auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds);
    while (std::chrono::steady_clock::now() < end) {
        if (pred())
            return true;
        std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
    return pred();
}
} // namespace

TEST(ClientThread, PublishesSnapshotsAndDrilledRectangles) {
    Volume skull = makeSkull(64);
    SurfaceSite site = defaultBurrSite(skull);
    ServerConfig sc = loopbackServerConfig("skull:64");
    SessionServer server(skull, sc);
    server.start();

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
    for (int i = 0; i < 50; ++i) {
        ToolState t;
        t.toolKind = uint8_t(ToolKind::Burr);
        t.diameterMm = 5.0f;
        t.position = site.position - site.normal * (-1.0f + 0.08f * float(i));
        t.orientation = glm::rotation(glm::vec3(0, 0, 1), site.normal);
        t.speed = 1.0f;
        t.drilling = true;
        EXPECT_TRUE(client.sendToolState(t));
        std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    ASSERT_TRUE(waitFor([&] { return client.rectsPublished() > 1 && server.idle(); }, 20.0));
    std::this_thread::sleep_for(std::chrono::milliseconds(300));
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
    server.start();
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

TEST(ClientThread, ReconnectsToANewServerOnTheSamePort) {
    Volume skull = makeSkull(64);
    ServerConfig sc = loopbackServerConfig("skull:64");
    auto server = std::make_unique<SessionServer>(skull, sc);
    const uint16_t port = server->port();
    server->start();

    ClientThreadConfig cc;
    cc.address = "127.0.0.1:" + std::to_string(port);
    cc.client.view = toViewSpec(cameraPreset("top", skull, {64, 64}));
    cc.retryS = 0.2;
    cc.connectTimeoutS = 1.0;
    ClientThread client(cc);
    client.start();
    ASSERT_TRUE(waitFor([&] { return client.snapshot()->hasFullImage; }, 20.0));
    const int attemptsBefore = client.snapshot()->attempts;
    EXPECT_GE(client.snapshot()->packetLoss, 0.0) << "ENet's loss estimate, once connected";
    client.drainRects();

    // The server goes away: the thread says why and retries.
    server->stop();
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
    ASSERT_TRUE(waitFor([&] { return client.snapshot()->attempts > attemptsBefore; }, 10.0));
    EXPECT_NE(client.snapshot()->state, LinkState::Connected);

    // A new server on the same port: the thread reconnects and gets a whole image again.
    sc.port = port;
    server = std::make_unique<SessionServer>(skull, sc);
    server->start();
    ASSERT_TRUE(waitFor(
        [&] {
            auto s = client.snapshot();
            return s->state == LinkState::Connected && s->hasFullImage;
        },
        20.0));
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

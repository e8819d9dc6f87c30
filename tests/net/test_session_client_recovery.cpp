// How a client recovers, over loopback with the server in this process: a resync during a view
// change keeps the view asked for and asks only once; (ClientThread) each applied rectangle
// carries its own update's latency, and the statistics tick restarts after a stall instead of
// catching up; a view larger than the server serves is refused without breaking a later switch or
// connection; a reconnected client's tool sequence carries on. Deadlines only guard against
// hangs; nothing asserts wall time.
#include "net/client_thread.h"
#include "net/session_client.h"
#include "net/session_server.h"

#include "libsim/dirty_rect.h"
#include "libsim/skull.h"
#include "libsim/tool.h"
#include "net/codec.h"
#include "net/view.h"

#include "loopback.h"

#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <memory>
#include <mutex>
#include <thread>
#include <vector>

using namespace trephine;
using namespace trephine::net;
using trephine::testing::drillThrough;
using trephine::testing::loopback;
using trephine::testing::loopbackServerConfig;
using trephine::testing::Pumped;
using trephine::testing::pumpUntil;
using trephine::testing::quantised;
using trephine::testing::waitFor;

namespace {

// Pumps the server (without polling the client) until it has sent everything it had.
bool waitServerIdle(SessionServer& server) {
    return waitFor([&] { return server.idle(); });
}

// The predicted-coding session, and a second view to ask for.
struct PredictedSession : trephine::testing::PaperZstdSession {
    ViewSpec& paper = view;
    ViewSpec top = toViewSpec(cameraPreset("top", volume, {160, 160}));

    // Damages the client's copy where a cut of `box` will be redrawn, so the predicted update of
    // the cut fails its base check.
    void damageWhereCutShows(const Box3i& box) {
        const PixelRect rect = dirtyScreenRect(toCamera(paper), volume, box);
        ASSERT_FALSE(rect.empty());
        client->damagePixelForTest(rect.x + rect.w / 2, rect.y + rect.h / 2);
    }
    // Pumps until the full image of the newest request has come, then until the client holds
    // exactly the server's picture of the view it shows.
    bool settled() {
        return pumpUntil({client.get()},
                         [&] { return server->idle() && client->hasFullImage(); }) &&
               pumpUntil({client.get()}, [&] {
                   return server->idle() &&
                          client->dbi() ==
                              quantised(server->renderView(client->view()), client->view());
               });
    }
};

} // namespace

// A predicted update of the view shown fails its base check while a view change is pending: the
// resync waits for the pending view's full image (it asks for nothing: not the shown view, which
// would bring the old view back, nor the pending one again), so the view asked for is shown.
TEST(SessionClientRecovery, AResyncDuringAViewChangeEndsOnTheViewAskedFor) {
    PredictedSession s;
    ASSERT_FALSE(s.paper == s.top);
    const Box3i box = surfaceBox(s.volume, 6);
    s.damageWhereCutShows(box);
    s.server->submitBoxCut(box);
    // The cut's predicted update leaves before the view request below reaches the server, so it
    // comes before the new view's full image on the (ordered) image channel.
    ASSERT_TRUE(waitServerIdle(*s.server));
    s.client->requestView(s.top);
    const uint64_t requestsAfterViewChange = s.client->stats().totalMessagesOut(Channel::Control);
    ASSERT_TRUE(pumpUntil({s.client.get()}, [&] { return s.client->resyncs() > 0; }));
    ASSERT_TRUE(s.settled());
    EXPECT_TRUE(s.client->view() == s.top)
        << "showing the " << (s.client->view() == s.paper ? "old view" : "other view");
    EXPECT_EQ(s.client->updatesRejected(), 0u);
    // The pending view's full image was on its way: the resync asked for nothing more.
    EXPECT_EQ(s.client->stats().totalMessagesOut(Channel::Control), requestsAfterViewChange);
}

// Every predicted update coded against the same stale copy fails its check until the full image
// comes; only the first asks for one.
TEST(SessionClientRecovery, AResyncAsksOnceUntilItsFullImageArrives) {
    PredictedSession s;
    s.damageWhereCutShows(surfaceBox(s.volume, 6));
    const uint64_t requestsBefore = s.client->stats().totalMessagesOut(Channel::Control);
    // Three growing cuts on one spot, each sent on its own before the client reads any: each
    // update's rectangle covers the damaged pixel and the previous update's.
    for (int n : {6, 10, 14}) {
        s.server->submitBoxCut(surfaceBox(s.volume, n));
        ASSERT_TRUE(waitServerIdle(*s.server));
    }
    ASSERT_TRUE(s.settled());
    EXPECT_TRUE(s.client->view() == s.paper);
    // Only the first is predicted: the next carry it unacknowledged, unpredicted (protocol 13).
    ASSERT_GE(s.client->resyncs(), 1u) << "the first update met the stale copy";
    EXPECT_EQ(s.client->stats().totalMessagesOut(Channel::Control) - requestsBefore, 1u)
        << "view requests for " << s.client->resyncs() << " mismatching updates";
    EXPECT_EQ(s.client->updatesRejected(), 0u);
}

// Volume updates add their latencies to the client's latency window too: the full image that ends
// a volume period must not carry their mean (it was caused by the switch, not by drilling), and
// each drilled rectangle carries a latency of its own.
TEST(SessionClientRecovery, TheFullImageAfterVolumeModeCarriesNoLatency) {
    Volume skull = makeSkull(64);
    const SurfaceSite site = defaultBurrSite(skull);
    SessionServer server(skull, loopbackServerConfig("skull:64"));
    Pumped pumped(server);
    ClientThreadConfig cc;
    cc.address = "127.0.0.1:" + std::to_string(server.port());
    cc.client.view =
        toViewSpec(cameraLookingAt(site.position, site.normal, 150.0f, 45.0f, {96, 96}, skull));
    cc.client.renderLocally = false; // a window's client: no local render to wait for
    ClientThread client(cc);
    client.start();
    ASSERT_TRUE(waitFor([&] { return client.snapshot()->hasFullImage; }));

    ASSERT_TRUE(client.requestSync(Sync::Volume));
    ASSERT_TRUE(waitFor([&] { return client.snapshot()->sync == Sync::Volume; }));
    drillThrough(client, site, 25);
    ASSERT_TRUE(waitFor([&] {
        return server.idle() && client.snapshot()->modes[size_t(Sync::Volume)].latencyP50Us > 0;
    })) << "volume updates with a latency";
    client.drainRects();

    ASSERT_TRUE(client.requestSync(Sync::Dbi));
    ASSERT_TRUE(waitFor([&] {
        auto s = client.snapshot();
        return s->sync == Sync::Dbi && s->hasFullImage;
    }));
    int fulls = 0;
    for (const AppliedRect& r : client.drainRects())
        if (r.full) {
            ++fulls;
            EXPECT_LT(r.latencyUs, 0) << "the switch's full image, sequence " << r.sequence;
        }
    ASSERT_EQ(fulls, 1);

    SurfaceSite beside = site; // fresh bone next to the first hole
    beside.position += glm::normalize(glm::cross(site.normal, glm::vec3(1, 0, 0))) * 8.0f;
    const uint64_t published = client.rectsPublished();
    drillThrough(client, beside, 25);
    ASSERT_TRUE(waitFor([&] { return client.rectsPublished() > published && server.idle(); }));
    int drilled = 0;
    for (const AppliedRect& r : client.drainRects())
        if (!r.full) {
            ++drilled;
            EXPECT_GE(r.latencyUs, 0) << "drilled rectangle, sequence " << r.sequence;
        }
    EXPECT_GT(drilled, 0);
    client.stop();
    server.stop();
}

// The network thread stalls for 2.5 s (here in the force-model hook; in a window, a large full
// volume applied): its 1 s statistics tick must start afresh, not catch up one tick a poll with
// ~1 ms intervals. The client pings every 0.25 s, so every tick of at least a second has sent
// some control messages, and none a thousand a second.
TEST(SessionClientRecovery, TheStatisticsTickRestartsAfterAStall) {
    Volume sphere = makeSphere(32);
    SessionServer server(sphere, loopbackServerConfig("sphere:32"));
    Pumped pumped(server);
    std::atomic<bool> stallArmed{false};
    std::atomic<uint64_t> stallEndUs{0};
    ClientThreadConfig cc;
    cc.address = "127.0.0.1:" + std::to_string(server.port());
    cc.client.view = toViewSpec(cameraPreset("top", sphere, {32, 32}));
    cc.onHapticModel = [&](const HapticModel&) {
        if (stallArmed.exchange(false)) {
            std::this_thread::sleep_for(std::chrono::milliseconds(2500));
            stallEndUs = steadyNowUs();
        }
    };
    ClientThread client(cc);
    client.start();
    ASSERT_TRUE(waitFor([&] { return client.snapshot()->hasFullImage; }));
    // Ticks from the second after this one on cover only welcomed time (pings every 0.25 s).
    const size_t first = client.snapshot()->rateHistory.size() + 1;
    ASSERT_TRUE(waitFor([&] { return client.snapshot()->rateHistory.size() > first; }));

    stallArmed = true;
    ToolState t;
    t.toolKind = uint8_t(ToolKind::Burr);
    t.diameterMm = 4.0f;
    t.position = {0.0f, 0.0f, sphereRadiusMm(32) + 5.0f}; // in the air: a model, no cut
    ASSERT_TRUE(client.sendToolState(t));
    ASSERT_TRUE(waitFor([&] { return stallEndUs.load() != 0; }));
    // The tick a second after the stall has been published.
    ASSERT_TRUE(
        waitFor([&] { return client.snapshot()->publishedUs > stallEndUs.load() + 1300000; }));
    auto s = client.snapshot();
    ASSERT_GT(s->rateHistory.size(), first + 2);
    for (size_t i = first; i < s->rateHistory.size(); ++i) {
        const double perS = s->rateHistory[i][size_t(Channel::Control)].messagesOutPerS;
        EXPECT_GT(perS, 0.0) << "tick " << i << " of " << s->rateHistory.size();
        EXPECT_LT(perS, 50.0) << "tick " << i << " of " << s->rateHistory.size();
    }
    client.stop();
    server.stop();
}

// A view larger than the server serves (the welcome says how large) is refused by the client
// itself, so a volume client never adopts locally a view the server dropped, and a later switch
// to DBI completes (its full image names the view the client shows).
TEST(SessionClientRecovery, AViewLargerThanTheServerServesIsRefusedAndASwitchToDbiStillCompletes) {
    Volume sphere = makeSphere(32);
    ServerConfig sc = loopbackServerConfig("sphere:32");
    sc.maxViewPixels = 64 * 64;
    SessionServer server(sphere, sc);
    Pumped pumped(server);
    ClientConfig cc;
    cc.view = toViewSpec(cameraPreset("top", sphere, {64, 64}));
    cc.sync = Sync::Volume;
    cc.renderThreads = 1;
    SessionClient client(cc);
    client.connect(loopback(server.port()));
    ASSERT_TRUE(pumpUntil({&client}, [&] { return client.localVolume() != nullptr; }));
    EXPECT_EQ(client.welcome().maxViewPixels, 64u * 64u);
    const ViewSpec shown = client.view();
    EXPECT_EQ(client.requestView(toViewSpec(cameraPreset("top", sphere, {96, 96}))), 0u);
    EXPECT_EQ(client.viewsRefused(), 1u);
    ViewSpec farAway = shown; // a view the wire refuses: never answered, so never asked
    farAway.eye.z = 2.0f * kMaxViewDistanceMm;
    EXPECT_EQ(client.requestView(farAway), 0u);
    EXPECT_EQ(client.viewsRefused(), 2u);
    EXPECT_EQ(client.view(), shown) << "the volume client kept its view";
    client.requestSync(Sync::Dbi);
    ASSERT_TRUE(pumpUntil({&client}, [&] { return client.sync() == Sync::Dbi; }))
        << "the switch to DBI completes";
    EXPECT_TRUE(client.hasFullImage());
    EXPECT_EQ(server.viewsRefused(), 0u) << "nothing the server had to drop";
    // A view it serves still goes through.
    const ViewSpec left = toViewSpec(cameraPreset("left", sphere, {64, 64}));
    const uint32_t id = client.requestView(left);
    EXPECT_NE(id, 0u);
    ASSERT_TRUE(pumpUntil({&client}, [&] { return client.viewId() == id; }));
    EXPECT_EQ(client.view(), left);
    server.stop();
}

// A view asked for before the welcome cannot be checked against the server's limit then: once
// the welcome says the limit, the client drops it (the server drops it too) instead of waiting
// for its image for good, and the hello's view is the picture.
TEST(SessionClientRecovery, ATooLargeViewAskedBeforeTheWelcomeIsDroppedThen) {
    Volume sphere = makeSphere(32);
    ServerConfig sc = loopbackServerConfig("sphere:32");
    sc.maxViewPixels = 100 * 100;
    SessionServer server(sphere, sc);
    Pumped pumped(server);
    ClientConfig cc;
    cc.view = toViewSpec(cameraPreset("top", sphere, {64, 64}));
    SessionClient client(cc);
    EXPECT_NE(client.requestView(toViewSpec(cameraPreset("left", sphere, {200, 200}))), 0u)
        << "no limit known yet";
    client.connect(loopback(server.port()));
    ASSERT_TRUE(pumpUntil({&client}, [&] { return client.hasFullImage(); }))
        << "waited for the dropped view's image";
    EXPECT_EQ(client.viewsRefused(), 1u);
    EXPECT_EQ(client.view(), cc.view);
    // Later views still go through.
    const ViewSpec left = toViewSpec(cameraPreset("left", sphere, {64, 64}));
    const uint32_t id = client.requestView(left);
    ASSERT_NE(id, 0u);
    ASSERT_TRUE(
        pumpUntil({&client}, [&] { return client.viewId() == id && client.hasFullImage(); }));
    server.stop();
}

// A view the client refused (larger than the server serves) is not the one the next connection's
// hello asks for, which the server would refuse as a bad hello on every reconnect.
TEST(SessionClientRecovery, ARefusedViewDoesNotBreakTheNextConnection) {
    Volume sphere = makeSphere(32);
    ServerConfig sc = loopbackServerConfig("sphere:32");
    sc.maxViewPixels = 100 * 100;
    auto server = std::make_unique<SessionServer>(sphere, sc);
    const uint16_t port = server->port();
    auto pumped = std::make_unique<Pumped>(*server);
    ClientThreadConfig cc;
    cc.address = "127.0.0.1:" + std::to_string(port);
    cc.client.view = toViewSpec(cameraPreset("top", sphere, {64, 64}));
    cc.retryS = 0.1;
    ClientThread client(cc);
    client.start();
    ASSERT_TRUE(waitFor([&] { return client.snapshot()->hasFullImage; }));
    client.requestView(toViewSpec(cameraPreset("left", sphere, {200, 200})));
    ASSERT_TRUE(waitFor([&] { return client.snapshot()->viewsRefused == 1; }));
    server->stop();
    pumped.reset();
    server.reset();
    ASSERT_TRUE(waitFor([&] { return client.snapshot()->state != LinkState::Connected; }));
    sc.port = port;
    server = std::make_unique<SessionServer>(sphere, sc);
    pumped = std::make_unique<Pumped>(*server);
    EXPECT_TRUE(waitFor([&] {
        auto s = client.snapshot();
        return s->state == LinkState::Connected && s->hasFullImage;
    })) << "closed: "
        << client.snapshot()->closeReason;
    EXPECT_EQ(client.snapshot()->view, cc.client.view);
    client.stop();
    server->stop();
}

// The server goes away and comes back on the same port: the client reconnects and its tool
// sequence carries on from the first connection's, so whatever keeps the newest force model by
// tool sequence (HapticLoop, the window's force source) takes the new connection's answers as
// new, not as older than the first connection's.
TEST(SessionClientRecovery, AReconnectedClientCarriesItsToolSequenceOn) {
    Volume sphere = makeSphere(32);
    auto server = std::make_unique<SessionServer>(sphere, loopbackServerConfig("sphere:32"));
    const uint16_t port = server->port();
    auto pumped = std::make_unique<Pumped>(*server);
    std::mutex mutex;
    std::vector<uint32_t> answered;
    ClientThreadConfig cc;
    cc.address = "127.0.0.1:" + std::to_string(port);
    cc.client.view = toViewSpec(cameraPreset("top", sphere, {32, 32}));
    cc.retryS = 0.1;
    cc.onHapticModel = [&](const HapticModel& m) {
        std::lock_guard lock(mutex);
        answered.push_back(m.toolSequence);
    };
    ClientThread client(cc);
    client.start();
    ASSERT_TRUE(waitFor([&] { return client.snapshot()->hasFullImage; }));
    ToolState t;
    t.toolKind = uint8_t(ToolKind::Burr);
    t.diameterMm = 4.0f;
    t.position = {0.0f, 0.0f, sphereRadiusMm(32) + 5.0f}; // in the air: a model, no cut
    auto count = [&] {
        std::lock_guard lock(mutex);
        return answered.size();
    };
    for (int i = 0; i < 5; ++i) {
        ASSERT_TRUE(client.sendToolState(t));
        ASSERT_TRUE(waitFor([&] { return count() == size_t(i + 1); }));
    }
    const uint32_t lastBefore = answered.back();

    server->stop();
    pumped.reset();
    server.reset();
    ASSERT_TRUE(waitFor([&] { return client.snapshot()->state != LinkState::Connected; }));
    ServerConfig again = loopbackServerConfig("sphere:32");
    again.port = port;
    server = std::make_unique<SessionServer>(sphere, again);
    pumped = std::make_unique<Pumped>(*server);
    ASSERT_TRUE(waitFor([&] {
        return client.snapshot()->state == LinkState::Connected && client.snapshot()->hasFullImage;
    }));
    ASSERT_TRUE(client.sendToolState(t));
    ASSERT_TRUE(waitFor([&] { return count() == 6; }));
    EXPECT_GT(int32_t(answered.back() - lastBefore), 0)
        << "after reconnecting: " << answered.back() << ", before: " << lastBefore;
    client.stop();
    server->stop();
}

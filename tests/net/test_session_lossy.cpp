// A session over a slow, lossy link (the in-process link emulator, 100 ms each way, 10 ms jitter,
// 20 % loss in both directions): a DBI client and a replicated-volume client join through it while
// a third participant drills over plain loopback. Reliable updates (images, voxels, rosters) get
// through in the end, resent by ENet, so both converge bit for bit on the server's volume and every
// roster lists everyone. (Voxels that overtake the welcome are tested with a fake server in
// test_session_volume.cpp; here that race is possible but rare.) Deadlines only guard hangs.
#include "net/link_emulator.h"
#include "net/session_client.h"
#include "net/session_server.h"

#include "libsim/skull.h"

#include "loopback.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>

using namespace trephine;
using namespace trephine::net;

using trephine::testing::burrState;
using trephine::testing::loopback;
using trephine::testing::loopbackServerConfig;
using trephine::testing::namedClientConfig;
using trephine::testing::Pumped;
using trephine::testing::pumpUntil;
using trephine::testing::sphereTop;

TEST(SessionLossy, ClientsOfBothDesignsConvergeOverASlowLossyLink) {
    Volume sphere = makeSphere(32);
    SessionServer server(sphere, loopbackServerConfig("sphere:32"));
    // Its own threads: over a lossy 100 ms link, ENet's resends keep the network thread's pace.
    server.start();
    const ENetAddress target = loopback(server.port());
    const LinkConditions link = LinkConditions::parse("latency=100,jitter=10,loss=20");
    LinkEmulator dbiLink(0, target, link), volumeLink(0, target, link);

    ClientConfig dc = namedClientConfig(sphere, "dbi", Role::Trainee, 32);
    dc.codec = Codec::Raw; // bit for bit
    ClientConfig vc = namedClientConfig(sphere, "volume", Role::Trainee, 32);
    vc.sync = Sync::Volume;
    vc.renderThreads = 1;
    SessionClient dbi(dc), vol(vc);
    SessionClient driller(namedClientConfig(sphere, "driller", Role::Trainee, 32));
    dbi.connect(loopback(dbiLink.port()));
    vol.connect(loopback(volumeLink.port()));
    driller.connect(target);
    const std::vector<SessionClient*> all = {&dbi, &vol, &driller};
    ASSERT_TRUE(pumpUntil(all,
                          [&] {
                              return dbi.hasFullImage() && vol.sync() == Sync::Volume &&
                                     vol.localVolume() != nullptr && driller.hasFullImage();
                          }))
        << "joined over the lossy link: " << dbi.closeReason() << vol.closeReason();

    // A burr stroke over loopback, one state at a time (unsequenced: a late one would be dropped).
    for (uint64_t i = 0; i < 20; ++i) {
        driller.sendToolState(burrState(sphereTop(32), int(i), 20, 1000000));
        ASSERT_TRUE(pumpUntil(all, [&] { return server.toolStatesApplied() == i + 1; }));
    }
    const Volume drilled = server.volumeSnapshot();
    ASSERT_FALSE(drilled == sphere) << "the stroke cut bone";
    ASSERT_TRUE(pumpUntil(all, [&] {
        return server.idle() && *vol.localVolume() == drilled &&
               compare(dbi.dbi(), server.renderView(dbi.view())).identical();
    })) << "both designs converge on the drilled volume";
    ASSERT_TRUE(pumpUntil(all, [&] {
        for (SessionClient* c : all)
            if (c->participants().size() != 3)
                return false;
        return true;
    }));
    EXPECT_GT(dbiLink.dropped() + volumeLink.dropped(), 0u) << "the link did lose packets";
    EXPECT_EQ(dbi.stats().malformed(), 0u);
    EXPECT_EQ(vol.stats().malformed(), 0u);
    server.stop();
}

// A client on a slow link while the bone changes fast: the server hands ENet no more of its
// updates while more than ServerConfig::maxInFlightBytes are still unacknowledged, and merges
// what comes meanwhile into one pending update, so the backlog stays bounded (it grew by every
// update before) and the client still converges on the final volume, with fewer, larger updates.
TEST(SessionLossy, ASlowClientsBacklogStaysBoundedAndItCatchesUp) {
    Volume skull = makeSkull(64);
    ServerConfig sc = loopbackServerConfig("skull:64");
    sc.maxInFlightBytes = 16 * 1024;
    SessionServer server(skull, sc);
    Pumped pumped(server);
    const ENetAddress target = loopback(server.port());
    LinkEmulator slow(0, target, LinkConditions::parse("rate=1")); // 1 Mbit/s: ~125 kB/s
    ClientConfig cc = namedClientConfig(skull, "slow", Role::Trainee, 128);
    cc.codec = Codec::Raw; // large updates, bit for bit
    SessionClient client(cc);
    client.connect(loopback(slow.port()));
    ASSERT_TRUE(pumpUntil(
        {&client}, [&] { return client.hasFullImage(); }, 60.0))
        << client.closeReason();
    const uint64_t before = client.updatesApplied();
    // 120 cuts, one every 2 ms: updates of tens of kB each, megabytes in all, far more than the
    // link carries meanwhile (without the bound ENet would hold them all).
    constexpr int kCuts = 120;
    for (int i = 0; i < kCuts; ++i) {
        const Box3i box = surfaceBox(skull, 10 + (i % 8) * 2);
        server.submitBoxCut(Box3i{box.lo + glm::ivec3(i % 5), box.hi + glm::ivec3(i % 5)});
        trephine::testing::pollAll({&client});
    }
    ASSERT_TRUE(pumpUntil(
        {&client},
        [&] {
            return server.idle() &&
                   compare(client.dbi(), server.renderView(client.view())).identical();
        },
        120.0))
        << "the slow client converges";
    // The largest update is the whole window uncompressed (the join's full image): RGBA and a
    // float depth, 8 bytes a pixel, and the message's fields.
    const int64_t largestUpdate = 128 * 128 * 8 + 1024;
    EXPECT_LE(server.peakInFlightBytes(), sc.maxInFlightBytes + largestUpdate);
    EXPECT_LT(client.updatesApplied() - before, uint64_t(kCuts) / 4)
        << "updates merged while the link was busy";
    EXPECT_EQ(client.stats().malformed(), 0u);
    server.stop();
}

// The transport over a long link (docs/session.md, "Transport"): 200 ms round
// trip, 5 % loss each way, 20 Mbit/s. The server sizes its reliable window by delay (BulkWindow),
// so the raw 256 x 256 view (512 kB, eight of ENet's 64 KiB windows) is not held to one window a
// round trip; both designs still converge bit for bit while a third participant drills.
TEST(SessionLossy, ClientsOfBothDesignsConvergeThrough200MsAnd5PercentLoss) {
    Volume skull = makeSkull(64);
    SessionServer server(skull, loopbackServerConfig("skull:64"));
    Pumped pumped(server);
    const ENetAddress target = loopback(server.port());
    const LinkConditions link = LinkConditions::parse("latency=100,loss=5,rate=20");
    LinkEmulator dbiLink(0, target, link), volumeLink(0, target, link);
    ClientConfig dc = namedClientConfig(skull, "dbi", Role::Trainee, 256);
    dc.codec = Codec::Raw; // bit for bit
    ClientConfig vc = namedClientConfig(skull, "volume", Role::Trainee, 64);
    vc.sync = Sync::Volume;
    vc.renderThreads = 1;
    SessionClient dbi(dc), vol(vc), driller(namedClientConfig(skull, "driller", Role::Trainee, 64));
    dbi.connect(loopback(dbiLink.port()));
    vol.connect(loopback(volumeLink.port()));
    driller.connect(target);
    const std::vector<SessionClient*> all = {&dbi, &vol, &driller};
    ASSERT_TRUE(pumpUntil(
        all,
        [&] {
            return dbi.hasFullImage() && vol.sync() == Sync::Volume && vol.localVolume() &&
                   driller.hasFullImage();
        },
        120.0))
        << "joined over the lossy link: " << dbi.closeReason() << vol.closeReason();
    // Cuts of growing boxes while the first updates are still on their way.
    for (int i = 0; i < 12; ++i) {
        const Box3i box = surfaceBox(skull, 6 + i, i % 3);
        server.submitBoxCut(box);
        for (int k = 0; k < 20; ++k)
            trephine::testing::pollAll(all);
    }
    const Volume drilled = server.volumeSnapshot();
    ASSERT_FALSE(drilled == skull) << "the cuts removed bone";
    ASSERT_TRUE(pumpUntil(
        all,
        [&] {
            return server.idle() && *vol.localVolume() == drilled &&
                   compare(dbi.dbi(), server.renderView(dbi.view())).identical();
        },
        120.0))
        << "both designs converge on the cut volume";
    EXPECT_GT(dbiLink.dropped() + volumeLink.dropped(), 0u) << "the link did lose packets";
    EXPECT_EQ(dbi.stats().malformed(), 0u);
    EXPECT_EQ(vol.stats().malformed(), 0u);
    server.stop();
}

// Lossy rectangles (protocol 13) to a zstd client through 200 ms and 5 % loss: planar while any
// is unacknowledged, predicted against its picture once it has acknowledged all (quiet cuts),
// repaired after the last cut. It converges on the server's picture with no base mismatch.
TEST(SessionLossy, AZstdClientConvergesOnLossyRectanglesPredictedOrNot) {
    Volume skull = makeSkull(64);
    SessionServer server(skull, loopbackServerConfig("skull:64"));
    Pumped pumped(server);
    LinkEmulator link(0, loopback(server.port()),
                      LinkConditions::parse("latency=100,loss=5,rate=20,seed=7"));
    ClientConfig cc = namedClientConfig(skull, "zstd", Role::Trainee, 160);
    cc.codec = Codec::Zstd;
    SessionClient client(cc);
    client.connect(loopback(link.port()));
    ASSERT_TRUE(pumpUntil(
        {&client}, [&] { return client.hasFullImage(); }, 60.0))
        << client.closeReason();
    for (int i = 0; i < 12; ++i) {
        server.submitBoxCut(surfaceBox(skull, 6 + i % 4, i % 3));
        // The first six in a burst; the rest each once everything before it is acknowledged
        // (a round trip and some: no later acknowledgement is awaited).
        const uint64_t until = steadyNowUs() + (i < 6 ? 20'000 : 700'000);
        pumpUntil({&client}, [&] { return steadyNowUs() > until; });
    }
    ASSERT_TRUE(pumpUntil(
        {&client},
        [&] {
            return server.idle() &&
                   compare(client.dbi(), trephine::testing::quantised(
                                             server.renderView(client.view()), client.view()))
                       .identical();
        },
        60.0))
        << "the client converges";
    EXPECT_EQ(client.resyncs(), 0u) << "every predicted rectangle met the pixels it was coded on";
    EXPECT_GT(client.predictedApplied(), 0u);
    EXPECT_GT(client.imageAcksSent(), 1u);
    EXPECT_GT(link.dropped(), 0u);
    EXPECT_EQ(client.stats().malformed(), 0u);
}

// A tool state's force answer does not wait behind a bulk image on the same link: tool states
// go every 10 ms while a 2 MB raw full image crosses a 20 Mbit/s, 50 ms link (0.8 s of
// serialisation), and their HapticModels come back within a round trip and the window's queue
// target. Measured here with real time: the link's delays are real (the margin is wide).
TEST(SessionLossy, AToolStateIsNotDelayedByAFullImageInFlight) {
    Volume skull = makeSkull(64);
    SessionServer server(skull, loopbackServerConfig("skull:64"));
    Pumped pumped(server);
    LinkEmulator link(0, loopback(server.port()), LinkConditions::parse("latency=25,rate=20"));
    ClientConfig cc = namedClientConfig(skull, "watcher", Role::Trainee, 500);
    cc.codec = Codec::Raw; // 8 bytes a pixel: 2 MB a full image
    SessionClient client(cc);
    std::vector<double> answersMs;
    client.setHapticCallback([&](const HapticModel& m, uint64_t arrivalUs) {
        if (!client.hasFullImage())
            answersMs.push_back(double(arrivalUs - m.clientTimeUs) * 1e-3);
    });
    client.connect(loopback(link.port()));
    ASSERT_TRUE(pumpUntil(
        {&client}, [&] { return client.hasFullImage(); }, 60.0))
        << client.closeReason();
    answersMs.clear();
    ViewSpec turned = client.view();
    turned.eye.x += 20.0f;
    const uint32_t id = client.requestView(turned);
    uint64_t nextToolUs = 0;
    ASSERT_TRUE(pumpUntil(
        {&client},
        [&] {
            const uint64_t now = steadyNowUs();
            if (!client.hasFullImage() && now >= nextToolUs) {
                ToolState t;
                t.position = glm::vec3(0, 0, 200); // above the skull: answered, nothing cut
                client.sendToolState(t);
                nextToolUs = now + 10000;
            }
            return client.hasFullImage() && client.viewId() == id;
        },
        60.0));
    ASSERT_GE(answersMs.size(), 10u) << "tool states answered while the image was in flight";
    std::sort(answersMs.begin(), answersMs.end());
    const double rttMs = 50.0, median = answersMs[answersMs.size() / 2];
    EXPECT_LE(median, rttMs + 40.0)
        << "slowest " << answersMs.back() << " ms of " << answersMs.size();
    EXPECT_LE(answersMs[answersMs.size() * 9 / 10], rttMs + 80.0);
    server.stop();
}

// The server's host gives a peer more than ENet's 64 KiB window where the path carries it (a
// 100 ms, 20 Mbit/s link holds 250 kB), and a reliable 2 MB message still arrives whole.
TEST(SessionLossy, TheServersWindowGrowsPastEnetsOnALongFatLink) {
    Host server = Host::listen(0, 1);
    server.setBulkWindow(BulkWindow{.adaptive = true});
    LinkEmulator link(0, loopback(server.port()), LinkConditions::parse("latency=50,rate=20"));
    Host client = Host::client();
    ASSERT_NE(client.connect(loopback(link.port()), kProtocolVersion), nullptr);
    ENetPeer* peer = nullptr;
    std::vector<uint8_t> received;
    const std::vector<uint8_t> big(2 << 20, 7);
    uint32_t largest = 0;
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(60);
    while (received.empty() && std::chrono::steady_clock::now() < deadline) {
        server.service(1, [&](const ENetEvent& e) {
            if (e.type == ENET_EVENT_TYPE_CONNECT) {
                peer = e.peer;
                disableThrottle(peer);
                server.send(peer, Channel::Image, big);
            }
        });
        client.service(1, [&](const ENetEvent& e) {
            if (e.type == ENET_EVENT_TYPE_RECEIVE)
                received.assign(e.packet->data, e.packet->data + e.packet->dataLength);
        });
        if (peer)
            largest = std::max(largest, server.windowBytes(peer));
    }
    EXPECT_EQ(received, big);
    EXPECT_GT(largest, uint32_t(ENET_PROTOCOL_MAXIMUM_WINDOW_SIZE));
}

// What Host::send says it queued is what the link carries, so the figures count it: a lossy
// message's fragments with their headers, more with parity; the client gets it whole either way.
TEST(SessionLossy, TheLossyChannelCountsItsFragmentsAndTheirParity) {
    Host server = Host::listen(0, 1);
    Host client = Host::client();
    ASSERT_NE(client.connect(loopback(server.port()), kProtocolVersion), nullptr);
    std::vector<uint8_t> message(20000);
    for (size_t i = 0; i < message.size(); ++i)
        message[i] = uint8_t(i * 7);
    ENetPeer* peer = nullptr;
    size_t plain = 0, withParity = 0, reliable = 0;
    int received = 0;
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(10);
    while (received < 2 && std::chrono::steady_clock::now() < deadline) {
        server.service(1, [&](const ENetEvent& e) {
            if (e.type != ENET_EVENT_TYPE_CONNECT)
                return;
            peer = e.peer;
            plain = server.send(peer, Channel::ImageLossy, message);
            withParity = server.send(peer, Channel::ImageLossy, message, {}, 100);
            reliable = server.send(peer, Channel::Image, message);
        });
        client.service(1, [&](const ENetEvent& e) {
            if (e.type == ENET_EVENT_TYPE_RECEIVE && e.channelID == uint8_t(Channel::ImageLossy)) {
                EXPECT_EQ(
                    std::vector<uint8_t>(e.packet->data, e.packet->data + e.packet->dataLength),
                    message);
                ++received;
            }
        });
    }
    EXPECT_EQ(received, 2);
    EXPECT_GT(plain, message.size()) << "each fragment's header";
    EXPECT_LT(plain, message.size() * 11 / 10);
    EXPECT_GT(withParity, plain + message.size() / 20) << "parity for 10 % loss";
    EXPECT_EQ(reliable, message.size()) << "a reliable message goes as it is";
}

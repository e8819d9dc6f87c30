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

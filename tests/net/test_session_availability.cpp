// Availability over loopback: a trainee joins and is served while hostile peers flood the server
// with half-open connections (raw CONNECT datagrams) or reconnect as soon as they are dropped;
// every refusal shows in the report. Tests assert what happens, never how fast (the benchmark
// bench_availability prints the times beside their targets).
#include "flood.h"
#include "loopback.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

using namespace trephine;
using namespace trephine::net;
using trephine::testing::HalfOpenFlood;
using trephine::testing::loopback;
using trephine::testing::loopbackServerConfig;
using trephine::testing::Pumped;
using trephine::testing::pumpUntil;
using trephine::testing::Reconnectors;
using trephine::testing::waitFor;

namespace {

nlohmann::json availabilityOf(const SessionServer& server) {
    return nlohmann::json::parse(server.reportJson()).at("availability");
}

// A trainee joins a server of `sc` while 8 addresses x 4 sockets send half-open CONNECTs (200 a
// second each); the server's availability figures once the trainee has its first image.
nlohmann::json joinUnderHalfOpenFlood(const ServerConfig& sc) {
    const Volume sphere = makeSphere(24);
    SessionServer server(sphere, sc);
    Pumped pumped(server);
    HalfOpenFlood flood(server.port(), 8, 4, 5000);
    EXPECT_EQ(flood.sockets(), 32u);
    EXPECT_TRUE(waitFor([&] { return flood.sent() >= 2000; }, 20.0));
    SessionClient trainee(trephine::testing::namedClientConfig(sphere, "ada", Role::Trainee, 32));
    trainee.connect(loopback(server.port()));
    EXPECT_TRUE(pumpUntil(
        {&trainee}, [&] { return trainee.hasFullImage(); }, 20.0))
        << trainee.closeReason();
    nlohmann::json a = availabilityOf(server);
    a["refused_server_full"] = server.refusedFull();
    return a;
}

} // namespace

// Without admission, a few dozen CONNECTs filled ENet's maxClients + 4 slots for ~30 s.
TEST(SessionAvailability, AHalfOpenFloodDoesNotLockATraineeOut) {
    ServerConfig sc = loopbackServerConfig("sphere:24");
    sc.maxClients = 2;
    sc.admission.handshakeTimeoutUs = 300000;
    const nlohmann::json a = joinUnderHalfOpenFlood(sc);
    EXPECT_GT(a.at("connects_rate_limited").get<uint64_t>() +
                  a.at("connects_address_busy").get<uint64_t>() +
                  a.at("connects_cookieless").get<uint64_t>(),
              0u)
        << a.dump();
    EXPECT_GT(a.at("handshakes_reset").get<uint64_t>(), 0u) << "half-open slots reclaimed";
    EXPECT_EQ(a.at("refused_server_full").get<uint64_t>(), 0u);
}

// Peers that complete ENet's handshake but never say hello, reconnecting whenever dropped, hold
// no place: the places are for admitted peers.
TEST(SessionAvailability, ReconnectingSilentPeersDoNotKeepTheServerFull) {
    const Volume sphere = makeSphere(24);
    ServerConfig sc = loopbackServerConfig("sphere:24");
    sc.maxClients = 2;
    sc.helloTimeoutS = 0.2f;
    SessionServer server(sphere, sc);
    // Its own threads: the reconnectors race the two joins as separate peers would, which one
    // pumping thread turns into batches the test's counts do not allow for.
    server.start();
    Reconnectors silent(server.port(), 6, 3, kProtocolVersion);
    ASSERT_TRUE(trephine::testing::waitFor([&] { return silent.connects() >= 6; }));
    SessionClient a(trephine::testing::namedClientConfig(sphere, "ada", Role::Trainee, 32));
    SessionClient b(trephine::testing::namedClientConfig(sphere, "ada", Role::Trainee, 32));
    a.connect(loopback(server.port()));
    b.connect(loopback(server.port()));
    ASSERT_TRUE(pumpUntil(
        {&a, &b}, [&] { return a.hasFullImage() && b.hasFullImage(); }, 20.0))
        << a.closeReason() << " / " << b.closeReason();
    // Give the silent peers time to be dropped for saying no hello, and to come back.
    const uint64_t before = server.helloTimeouts();
    ASSERT_TRUE(pumpUntil(
        {&a, &b}, [&] { return server.helloTimeouts() >= before + 6; }, 20.0));
    EXPECT_FALSE(a.closed());
    EXPECT_FALSE(b.closed());
    EXPECT_EQ(server.refusedFull(), 0u);
    // Two "ada"s: the second is listed as "ada (2)".
    ASSERT_TRUE(pumpUntil(
        {&a, &b}, [&] { return a.participants().size() == 2; }, 20.0));
    std::vector<std::string> names;
    for (const auto& [id, p] : a.participants())
        names.push_back(p.name);
    EXPECT_NE(std::find(names.begin(), names.end(), "ada (2)"), names.end());
}

// Silent peers from a few addresses hold every waiting slot; a newcomer from another address
// takes the oldest slot of the address holding the most instead of waiting for one to free.
TEST(SessionAvailability, AFewAddressesHoldingEveryWaitingSlotDoNotKeepANewcomerOut) {
    const Volume sphere = makeSphere(24);
    ServerConfig sc = loopbackServerConfig("sphere:24");
    sc.maxClients = 2;
    sc.helloTimeoutS = 60.0f; // silent peers stay for the whole test
    sc.admission.waitingSlots = 12;
    sc.admission.waitingPerAddress = 6;
    SessionServer server(sphere, sc);
    Pumped pumped(server);
    std::vector<std::unique_ptr<Reconnectors>> silent;
    for (uint8_t a = 2; a < 5; ++a) // 3 addresses x 6 peers: 18 for 12 slots
        silent.push_back(std::make_unique<Reconnectors>(server.port(), 6, a, kProtocolVersion));
    ASSERT_TRUE(waitFor(
        [&] { return availabilityOf(server).at("connects_pool_full").get<uint64_t>() > 0; }, 20.0))
        << "the pool fills";
    SessionClient trainee(trephine::testing::namedClientConfig(sphere, "ada", Role::Trainee, 32));
    trainee.connect(loopback(server.port()));
    ASSERT_TRUE(pumpUntil(
        {&trainee}, [&] { return trainee.hasFullImage(); }, 20.0))
        << trainee.closeReason();
    EXPECT_GT(availabilityOf(server).at("connects_displaced").get<uint64_t>(), 0u);
}

// A CONNECT the gate refuses is answered: the client hears at once that the server is busy,
// not "no answer" after ENet's timeout, and tries again by itself until it is in.
TEST(SessionAvailability, ARefusedConnectionHearsTheServerIsBusyAndJoinsOnceThereIsRoom) {
    const Volume sphere = makeSphere(24);
    ServerConfig sc = loopbackServerConfig("sphere:24");
    sc.helloTimeoutS = 1.0f;
    sc.admission.waitingPerAddress = 2;
    SessionServer server(sphere, sc);
    Pumped pumped(server);
    auto silent = std::make_unique<Reconnectors>(server.port(), 2, 1, kProtocolVersion);
    ASSERT_TRUE(waitFor([&] { return silent->connects() >= 2; }, 20.0));
    ClientConfig cc = trephine::testing::namedClientConfig(sphere, "ada", Role::Trainee, 32);
    cc.clock = [&] { return pumped.now(); }; // the server's time: skipping moves both
    SessionClient trainee(cc);
    trainee.connect(loopback(server.port())); // from 127.0.0.1, whose two places are taken
    ASSERT_TRUE(pumpUntil(
        {&trainee}, [&] { return trainee.busyRefusals() > 0; }, 20.0));
    EXPECT_FALSE(trainee.closed());
    EXPECT_EQ(trainee.closeReason(), refuseReasonText(uint32_t(RefuseReason::Busy)));
    // The report counts it by the end of the network thread's pass that refused it.
    EXPECT_TRUE(waitFor(
        [&] {
            const nlohmann::json a = availabilityOf(server);
            return a.at("connects_address_busy").get<uint64_t>() +
                       a.at("connects_rate_limited").get<uint64_t>() >
                   0;
        },
        5.0))
        << availabilityOf(server).dump();
    silent.reset();   // their places free at the hello timeout (1 s), and the trainee's retry
    pumped.skip(2.5); // waits at most 2 s: time skipped, not slept
    ASSERT_TRUE(pumpUntil(
        {&trainee}, [&] { return trainee.hasFullImage(); }, 20.0))
        << trainee.closeReason();
}

// With cookies asked for from the first connection, a client returns the server's cookie and
// joins; spoofed CONNECTs (a flood that never reads its answers) take no slot at all.
TEST(SessionAvailability, AFloodThatCannotReceiveSpendsNoSlotWhenCookiesAreAskedFor) {
    ServerConfig sc = loopbackServerConfig("sphere:24");
    sc.admission.cookiesFrom = 0;
    const nlohmann::json a = joinUnderHalfOpenFlood(sc);
    EXPECT_GE(a.at("connects_cookieless").get<uint64_t>(), 2000u) << a.dump();
    EXPECT_EQ(a.at("handshakes_reset").get<uint64_t>(), 0u) << "no half-open slot was spent";
    EXPECT_EQ(a.at("connects_pool_full").get<uint64_t>(), 0u);
}

// A threaded server lets a trainee's rectangle go out before the chunked work of a larger view
// that sees the same drilling (StepConfig::letSend): the report counts the waits, and with the
// network thread running each ends with its pass, not the bound.
TEST(SessionAvailability, ALargerViewsWorkWaitsUntilTheTraineesRectangleIsTaken) {
    const Volume sphere = makeSphere(32);
    SessionServer server(sphere, loopbackServerConfig("sphere:32"));
    server.start();
    SessionClient trainee(trephine::testing::namedClientConfig(sphere, "ada", Role::Trainee, 64));
    ClientConfig wc = trephine::testing::namedClientConfig(sphere, "watcher", Role::Trainee, 64);
    wc.view = toViewSpec(cameraPreset("top", sphere, {640, 480})); // more than a slice
    wc.codec = Codec::Raw;                                         // bit for bit
    SessionClient watcher(wc);
    trainee.connect(loopback(server.port()));
    watcher.connect(loopback(server.port()));
    const std::vector<SessionClient*> all = {&trainee, &watcher};
    ASSERT_TRUE(pumpUntil(all, [&] { return trainee.hasFullImage() && watcher.hasFullImage(); }));
    for (uint64_t i = 0; i < 20; ++i) {
        trainee.sendToolState(
            trephine::testing::burrState(trephine::testing::sphereTop(32), int(i), 20, 1000000));
        ASSERT_TRUE(pumpUntil(all, [&] { return server.toolStatesApplied() == i + 1; }));
    }
    ASSERT_TRUE(pumpUntil(all, [&] {
        return server.idle() &&
               compare(watcher.dbi(), server.renderView(watcher.view())).identical();
    }));
    const nlohmann::json report = nlohmann::json::parse(server.reportJson());
    const uint64_t waits = report.at("send_waits"), bounded = report.at("send_waits_bounded");
    EXPECT_GT(waits, 0u) << report.dump();
    EXPECT_LT(bounded, waits) << "the network thread's passes end the waits";
    server.stop();
}

// The report's peaks of what ENet held for one peer, taken as messages are handed to it: a
// joiner's welcome and scene on the control channel, its first full image as an update.
TEST(SessionAvailability, TheReportHoldsThePeaksOfWhatENetHeldForAPeer) {
    const Volume sphere = makeSphere(24);
    SessionServer server(sphere, loopbackServerConfig("sphere:24"));
    Pumped pumped(server);
    SessionClient trainee(trephine::testing::namedClientConfig(sphere, "ada", Role::Trainee, 32));
    trainee.connect(loopback(server.port()));
    ASSERT_TRUE(pumpUntil({&trainee}, [&] { return trainee.hasFullImage(); }))
        << trainee.closeReason();
    ASSERT_TRUE(pumpUntil({&trainee}, [&] {
        return availabilityOf(server).at("peak_control_bytes").get<int64_t>() > 0 &&
               server.peakInFlightBytes() > 0;
    })) << availabilityOf(server).dump();
}

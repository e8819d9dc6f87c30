#include "net/link_emulator.h"

#include "libsim/error.h"
#include "net/enet_host.h"

#include <gtest/gtest.h>

#include <chrono>

using namespace trephine;
using namespace trephine::net;
using Clock = std::chrono::steady_clock;

TEST(LinkEmulator, ParsesConditions) {
    LinkConditions c = LinkConditions::parse("latency=25,jitter=5,loss=1.5,rate=100");
    EXPECT_DOUBLE_EQ(c.latencyMs, 25);
    EXPECT_DOUBLE_EQ(c.jitterMs, 5);
    EXPECT_DOUBLE_EQ(c.lossPercent, 1.5);
    EXPECT_DOUBLE_EQ(c.rateMbps, 100);
    EXPECT_EQ(c.describe(), "latency 25 ms, jitter 5 ms, loss 1.5 %, rate 100 Mbit/s");
    EXPECT_EQ(LinkConditions{}.describe(), "latency 0 ms, jitter 0 ms, loss 0 %, rate unlimited");
    EXPECT_THROW(LinkConditions::parse("latency=fast"), Error);
    EXPECT_THROW(LinkConditions::parse("lag=3"), Error);
    EXPECT_THROW(LinkConditions::parse("loss=-1"), Error);
    // Not finite, or large enough to overflow the relay's clock arithmetic.
    for (const char* bad : {"latency=nan", "jitter=inf", "rate=1e300", "seed=1e20"})
        EXPECT_THROW(LinkConditions::parse(bad), Error) << bad;
}

// ENet through the relay: the connection works, and its round trip grows by the added latency.
TEST(LinkEmulator, EnetConnectsThroughTheRelayWithAddedLatency) {
    Host server = Host::listen(0, 2);
    ENetAddress target = parseAddress("127.0.0.1:" + std::to_string(server.port()));
    LinkEmulator relay(0, target, LinkConditions::parse("latency=20"));
    Host client = Host::client();
    ENetPeer* peer = client.connect(parseAddress("127.0.0.1:" + std::to_string(relay.port())), 7);

    bool connected = false;
    Clock::time_point connectStart = Clock::now(), connectedAt{};
    auto deadline = Clock::now() + std::chrono::seconds(5);
    while (Clock::now() < deadline && !connected) {
        server.service(1, [](const ENetEvent&) {});
        client.service(1, [&](const ENetEvent& e) {
            if (e.type == ENET_EVENT_TYPE_CONNECT) {
                connected = true;
                connectedAt = Clock::now();
            }
        });
    }
    ASSERT_TRUE(connected) << "no connection through the relay";
    ASSERT_NE(peer, nullptr);
    // Connecting takes at least one round trip: 2 x 20 ms one-way.
    double ms = std::chrono::duration<double, std::milli>(connectedAt - connectStart).count();
    EXPECT_GE(ms, 40.0);
    EXPECT_GT(relay.forwarded(), 0u);
    EXPECT_EQ(relay.dropped(), 0u);
}

TEST(LinkEmulator, TotalLossDropsEverything) {
    Host server = Host::listen(0, 2);
    ENetAddress target = parseAddress("127.0.0.1:" + std::to_string(server.port()));
    LinkEmulator relay(0, target, LinkConditions::parse("loss=100"));
    Host client = Host::client();
    client.connect(parseAddress("127.0.0.1:" + std::to_string(relay.port())), 7);
    bool serverSawConnect = false;
    auto deadline = Clock::now() + std::chrono::milliseconds(300);
    while (Clock::now() < deadline) {
        server.service(1, [&](const ENetEvent& e) {
            serverSawConnect = serverSawConnect || e.type == ENET_EVENT_TYPE_CONNECT;
        });
        client.service(1, [](const ENetEvent&) {});
    }
    EXPECT_FALSE(serverSawConnect);
    EXPECT_GT(relay.dropped(), 0u);
    EXPECT_EQ(relay.forwarded(), 0u);
}

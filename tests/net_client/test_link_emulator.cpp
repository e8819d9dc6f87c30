#include "net/link_emulator.h"

#include "libsim/error.h"
#include "net/enet_host.h"

#include <gtest/gtest.h>

#include <chrono>
#include <span>
#include <vector>

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
    EXPECT_TRUE(LinkConditions::parse("rate=100,shared=1").shared);
    EXPECT_EQ(LinkConditions::parse("rate=100,shared=1").describe(),
              "latency 0 ms, jitter 0 ms, loss 0 %, rate 100 Mbit/s shared by all clients");
    EXPECT_THROW(LinkConditions::parse("shared=2"), Error);
}

// --link's spec in every mode: one line naming the text; nothing that emulates nothing, and
// nothing that lets nothing through.
TEST(LinkEmulator, LinkSpecsAreRefusedWithTheirText) {
    EXPECT_DOUBLE_EQ(linkSpecConditions("latency=50,loss=1,rate=20").latencyMs, 50);
    for (const char* bad : {"", ",", "latency=fast", "loss=100", "lag=3"}) {
        try {
            linkSpecConditions(bad);
            ADD_FAILURE() << "accepted '" << bad << "'";
        } catch (const Error& e) {
            const std::string what = e.what();
            EXPECT_NE(what.find(std::string("'") + bad), std::string::npos) << what;
            EXPECT_EQ(what.find('\n'), std::string::npos) << what;
        }
    }
    EXPECT_EQ(startLinkEnd("", LinkEnd::Client, parseAddress("127.0.0.1:7777")), nullptr);
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

// The rate counts each datagram as it occupies an Ethernet link: 100 datagrams of 4 bytes at
// 1 Mbit/s take 56 ms with their 66 bytes of framing each, 3.2 ms as bare payload.
namespace {

// The next datagram at `target` within 50 ms into `into` (its size, or -1), and its sender.
int receiveWithin50Ms(ENetSocket target, std::span<uint8_t> into, ENetAddress& sender) {
    enet_uint32 wait = ENET_SOCKET_WAIT_RECEIVE;
    if (enet_socket_wait(target, &wait, 50) != 0 || !(wait & ENET_SOCKET_WAIT_RECEIVE))
        return -1;
    ENetBuffer b{into.data(), into.size()};
    return enet_socket_receive(target, &sender, &b, 1);
}

// Sends `perSender` 4-byte datagrams from each of `senders` sockets through a relay with
// `conditions` and returns the milliseconds until the last one reached the target (-1: not all).
double sendThrough(const char* conditions, int senders, int perSender) {
    ENetSocket target = enet_socket_create(ENET_SOCKET_TYPE_DATAGRAM);
    ENetAddress any = parseAddress("127.0.0.1:0");
    enet_socket_bind(target, &any);
    ENetAddress targetAddress{};
    enet_socket_get_address(target, &targetAddress);
    targetAddress.host = any.host;
    LinkEmulator relay(0, targetAddress, LinkConditions::parse(conditions));
    const ENetAddress relayAddress = parseAddress("127.0.0.1:" + std::to_string(relay.port()));
    std::vector<ENetSocket> from(static_cast<size_t>(senders), ENET_SOCKET_NULL);
    uint8_t payload[4] = {1, 2, 3, 4};
    const auto start = Clock::now();
    for (ENetSocket& s : from) {
        s = enet_socket_create(ENET_SOCKET_TYPE_DATAGRAM);
        for (int i = 0; i < perSender; ++i) {
            ENetBuffer b{payload, sizeof payload};
            enet_socket_send(s, &relayAddress, &b, 1);
        }
    }
    int received = 0;
    Clock::time_point last{};
    while (received < senders * perSender && Clock::now() - start < std::chrono::seconds(5)) {
        uint8_t buffer[64];
        ENetAddress sender{};
        if (receiveWithin50Ms(target, buffer, sender) == int(sizeof payload)) {
            ++received;
            last = Clock::now();
        }
    }
    for (ENetSocket s : from)
        enet_socket_destroy(s);
    enet_socket_destroy(target);
    return received == senders * perSender
               ? std::chrono::duration<double, std::milli>(last - start).count()
               : -1.0;
}

} // namespace

// A shared rate is one link for every client: two clients' 100 datagrams each take the wire time
// of 200 (112 ms at 1 Mbit/s), where each client's own link would carry them side by side.
TEST(LinkEmulator, ASharedRateSerialisesEveryClientOnOneLink) {
    const double wireMs = 200 * (4.0 + LinkConditions::kWireOverheadBytes) * 8.0 / 1e6 * 1e3;
    const double shared = sendThrough("rate=1,shared=1", 2, 100);
    ASSERT_GT(shared, 0) << "not every datagram came through";
    EXPECT_GE(shared, 0.95 * wireMs);
}

TEST(LinkEmulator, RateCountsEachDatagramsFraming) {
    ENetSocket target = enet_socket_create(ENET_SOCKET_TYPE_DATAGRAM);
    ASSERT_NE(target, ENET_SOCKET_NULL);
    ENetAddress any = parseAddress("127.0.0.1:0");
    ASSERT_EQ(enet_socket_bind(target, &any), 0);
    ENetAddress targetAddress{};
    ASSERT_EQ(enet_socket_get_address(target, &targetAddress), 0);
    targetAddress.host = any.host;
    LinkEmulator relay(0, targetAddress, LinkConditions::parse("rate=1"));
    ENetSocket sender = enet_socket_create(ENET_SOCKET_TYPE_DATAGRAM);
    ASSERT_NE(sender, ENET_SOCKET_NULL);
    const ENetAddress relayAddress = parseAddress("127.0.0.1:" + std::to_string(relay.port()));

    constexpr int kDatagrams = 100;
    uint8_t payload[4] = {1, 2, 3, 4};
    const auto start = Clock::now();
    for (int i = 0; i < kDatagrams; ++i) {
        ENetBuffer b{payload, sizeof payload};
        ASSERT_EQ(enet_socket_send(sender, &relayAddress, &b, 1), int(sizeof payload));
    }
    int received = 0;
    Clock::time_point last{};
    while (received < kDatagrams && Clock::now() - start < std::chrono::seconds(5)) {
        enet_uint32 wait = ENET_SOCKET_WAIT_RECEIVE;
        if (enet_socket_wait(target, &wait, 50) != 0 || !(wait & ENET_SOCKET_WAIT_RECEIVE))
            continue;
        uint8_t buffer[64];
        ENetBuffer b{buffer, sizeof buffer};
        ENetAddress from{};
        if (enet_socket_receive(target, &from, &b, 1) == int(sizeof payload)) {
            ++received;
            last = Clock::now();
        }
    }
    ASSERT_EQ(received, kDatagrams);
    const double ms = std::chrono::duration<double, std::milli>(last - start).count();
    const double wireMs =
        kDatagrams * (4.0 + LinkConditions::kWireOverheadBytes) * 8.0 / 1e6 * 1e3; // 56 ms
    EXPECT_GE(ms, 0.95 * wireMs);
    EXPECT_LT(ms, 10.0 * wireMs) << "the relay should not hold datagrams far longer";
    enet_socket_destroy(sender);
    enet_socket_destroy(target);
}

// A relay in front of a server on this machine passes on each client host as an address of its
// own, one for all of a host's ports, so the server's per-address rules (admission, a removal)
// see hosts, not the relay.
TEST(LinkEmulator, EachClientHostReachesALocalTargetFromItsOwnAddress) {
    ENetSocket target = enet_socket_create(ENET_SOCKET_TYPE_DATAGRAM);
    ENetAddress bound = parseAddress("127.0.0.1:0");
    ASSERT_EQ(enet_socket_bind(target, &bound), 0);
    ENetAddress targetAddress{};
    enet_socket_get_address(target, &targetAddress);
    targetAddress.host = bound.host;
    LinkEmulator relay(0, targetAddress, LinkConditions{});
    const ENetAddress relayAddress = parseAddress("127.0.0.1:" + std::to_string(relay.port()));
    // Two sockets of host 127.0.0.2 and one of host 127.0.0.3.
    std::vector<ENetSocket> from;
    for (const char* host : {"127.0.0.2:0", "127.0.0.2:0", "127.0.0.3:0"}) {
        ENetSocket s = enet_socket_create(ENET_SOCKET_TYPE_DATAGRAM);
        ENetAddress a = parseAddress(host);
        ASSERT_EQ(enet_socket_bind(s, &a), 0) << host;
        from.push_back(s);
    }
    std::vector<uint32_t> seen(from.size(), 0);
    for (size_t i = 0; i < from.size(); ++i) {
        uint8_t payload[1] = {uint8_t(i)};
        ENetBuffer b{payload, 1};
        enet_socket_send(from[i], &relayAddress, &b, 1);
        const auto deadline = Clock::now() + std::chrono::seconds(5);
        while (!seen[i] && Clock::now() < deadline) {
            uint8_t got[8];
            ENetAddress sender{};
            if (receiveWithin50Ms(target, got, sender) == 1 && got[0] == i)
                seen[i] = sender.host;
        }
        ASSERT_NE(seen[i], 0u) << "datagram " << i << " did not arrive";
        EXPECT_EQ(ENET_NET_TO_HOST_32(seen[i]) >> 24, 127u) << "a loopback address";
    }
    EXPECT_EQ(seen[0], seen[1]) << "one host, one address";
    EXPECT_NE(seen[0], seen[2]) << "two hosts, two addresses";
    EXPECT_NE(seen[0], bound.host) << "not the relay's own 127.0.0.1";
    for (ENetSocket s : from)
        enet_socket_destroy(s);
    enet_socket_destroy(target);
}

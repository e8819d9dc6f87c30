#include "net/enet_host.h"

#include "libsim/error.h"
#include "net/link_emulator.h"
#include "net/protocol.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <string>
#include <vector>

using namespace trephine;
using namespace trephine::net;

TEST(EnetHost, ParsesAddresses) {
    ENetAddress a = parseAddress("127.0.0.1:9000");
    EXPECT_EQ(a.port, 9000);
    EXPECT_EQ(formatAddress(a), "127.0.0.1:9000");
    EXPECT_EQ(parseAddress("localhost").port, 7777);
    EXPECT_EQ(parseAddress(":1234").port, 1234);
    EXPECT_EQ(parseAddress("4321").port, 4321);
    EXPECT_THROW(parseAddress("127.0.0.1:http"), Error);
    EXPECT_THROW(parseAddress("127.0.0.1:70000"), Error);
}

TEST(EnetHost, LoopbackConnectDeliversConnectDataAndMessagesPerChannel) {
    Host server = Host::listen(0, 4);
    ASSERT_NE(server.port(), 0);
    Host client = Host::client();
    ENetAddress addr = parseAddress("127.0.0.1:" + std::to_string(server.port()));
    ENetPeer* toServer = client.connect(addr, 1234);
    ASSERT_NE(toServer, nullptr);

    uint32_t connectData = 0;
    bool clientConnected = false;
    std::vector<std::pair<int, std::string>> received;
    auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(5);
    bool sent = false;
    while (std::chrono::steady_clock::now() < deadline && received.size() < 2) {
        server.service(1, [&](const ENetEvent& e) {
            if (e.type == ENET_EVENT_TYPE_CONNECT)
                connectData = e.data;
            if (e.type == ENET_EVENT_TYPE_RECEIVE)
                received.emplace_back(
                    e.channelID,
                    std::string(reinterpret_cast<char*>(e.packet->data), e.packet->dataLength));
        });
        client.service(1, [&](const ENetEvent& e) {
            if (e.type == ENET_EVENT_TYPE_CONNECT)
                clientConnected = true;
        });
        if (clientConnected && !sent) {
            std::string a = "hello", b = "pose";
            client.send(toServer, Channel::Control,
                        std::span(reinterpret_cast<const uint8_t*>(a.data()), a.size()));
            client.send(toServer, Channel::ToolState,
                        std::span(reinterpret_cast<const uint8_t*>(b.data()), b.size()));
            sent = true;
        }
    }
    EXPECT_EQ(connectData, 1234u);
    ASSERT_EQ(received.size(), 2u);
    for (auto& [ch, text] : received) {
        if (ch == int(Channel::Control)) {
            EXPECT_EQ(text, "hello");
        } else {
            EXPECT_EQ(ch, int(Channel::ToolState));
            EXPECT_EQ(text, "pose");
        }
    }
}

// Admission cookies travel as the connect ID (net/admission.h): this ENet must carry the one
// asked for.
TEST(EnetHost, AConnectionCarriesTheConnectIdAskedFor) {
    Host client = Host::client();
    const ENetAddress to = parseAddress("127.0.0.1:9");
    ENetPeer* peer = client.connect(to, kProtocolVersion, 0xabcdefu);
    ASSERT_NE(peer, nullptr);
    EXPECT_EQ(peer->connectID, 0xabcdefu);
}

// Channel::ImageLossy's messages through 5 % loss: in datagrams of their own with parity for it,
// all but about one in a thousand arrive whole; without, a 30 KiB one (23 datagrams) arrives
// about a third of the time. The receiving host's loss figure reads the link's.
TEST(EnetHost, ParityCarriesLossyMessagesThroughLoss) {
    Host server = Host::listen(0, 2);
    LinkEmulator relay(0, parseAddress("127.0.0.1:" + std::to_string(server.port())),
                       LinkConditions::parse("loss=5"));
    Host client = Host::client();
    client.connect(parseAddress("127.0.0.1:" + std::to_string(relay.port())), 7);
    ENetPeer* toClient = nullptr;
    std::vector<uint8_t> m(30 * 1024);
    for (size_t i = 0; i < m.size(); ++i)
        m[i] = uint8_t(i * 7 + i / 251);
    int whole = 0;
    const auto pump = [&](int ms) {
        auto until = std::chrono::steady_clock::now() + std::chrono::milliseconds(ms);
        while (std::chrono::steady_clock::now() < until) {
            server.service(1, [&](const ENetEvent& e) {
                if (e.type == ENET_EVENT_TYPE_CONNECT)
                    toClient = e.peer;
            });
            client.service(1, [&](const ENetEvent& e) {
                if (e.type == ENET_EVENT_TYPE_RECEIVE &&
                    e.channelID == uint8_t(Channel::ImageLossy))
                    whole += std::equal(m.begin(), m.end(), e.packet->data,
                                        e.packet->data + e.packet->dataLength) &&
                             e.packet->dataLength == m.size();
            });
        }
    };
    for (int i = 0; i < 500 && !toClient; ++i)
        pump(10);
    ASSERT_NE(toClient, nullptr);
    const auto sendAll = [&](uint32_t lossPermille) {
        whole = 0;
        for (int i = 0; i < 50; ++i) {
            ASSERT_TRUE(server.send(toClient, Channel::ImageLossy, m, {}, lossPermille));
            pump(5);
        }
        pump(200);
    };
    sendAll(0);
    const int without = whole;
    sendAll(50);
    EXPECT_LE(without, 30);
    EXPECT_GE(whole, 48) << "without parity " << without;
    EXPECT_GE(client.lossPermille(client.get()->peers), 20u);
    EXPECT_LE(client.lossPermille(client.get()->peers), 100u);
    // Datagrams on the channel that are not fragments reach the handler as they came, for the
    // session to refuse as malformed.
    for (int i = 0; i < 20; ++i)
        enet_peer_send(client.get()->peers, uint8_t(Channel::ImageLossy),
                       enet_packet_create("bad", 3, ENET_PACKET_FLAG_UNSEQUENCED));
    int refused = 0;
    auto until = std::chrono::steady_clock::now() + std::chrono::milliseconds(300);
    while (std::chrono::steady_clock::now() < until) {
        server.service(1, [&](const ENetEvent& e) {
            refused += e.type == ENET_EVENT_TYPE_RECEIVE && e.packet->dataLength == 3;
        });
        client.service(1, [](const ENetEvent&) {});
    }
    EXPECT_GE(refused, 10);
    EXPECT_LE(refused, 20);
}

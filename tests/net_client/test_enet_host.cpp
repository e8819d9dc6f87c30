#include "net/enet_host.h"

#include "libsim/error.h"
#include "net/protocol.h"

#include <gtest/gtest.h>

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

// Hostile peers for availability tests and benchmarks, over loopback: raw UDP sockets sending
// ENet CONNECT datagrams and never finishing the handshake (half-open connections), and ENet
// clients that connect, never say hello and reconnect as soon as they are dropped. Each binds a
// loopback address of its own (127.0.0.2 and up: Linux answers for all of 127/8), so the server
// tells them from the trainee at 127.0.0.1.
#pragma once

#include "net/protocol.h"

#include <arpa/inet.h>
#include <enet/enet.h>
#include <enet/protocol.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <atomic>
#include <cstring>
#include <random>
#include <thread>
#include <vector>

namespace trephine::testing {

// `sockets` UDP sockets on each of `addresses` loopback addresses (127.0.0.2 on), each sending a
// CONNECT with a fresh connect ID every `intervalUs`, until destroyed.
class HalfOpenFlood {
public:
    HalfOpenFlood(uint16_t port, int addresses, int sockets, int intervalUs) {
        for (int a = 0; a < addresses; ++a)
            for (int s = 0; s < sockets; ++s) {
                const int fd = ::socket(AF_INET, SOCK_DGRAM | SOCK_NONBLOCK, 0);
                sockaddr_in local{};
                local.sin_family = AF_INET;
                local.sin_addr.s_addr = htonl(0x7f000002u + uint32_t(a));
                if (fd >= 0 && ::bind(fd, reinterpret_cast<sockaddr*>(&local), sizeof local) == 0)
                    m_fds.push_back(fd);
                else if (fd >= 0)
                    ::close(fd);
            }
        m_thread = std::thread([this, port, intervalUs] { run(port, intervalUs); });
    }
    ~HalfOpenFlood() {
        m_stop = true;
        m_thread.join();
        for (int fd : m_fds)
            ::close(fd);
    }
    size_t sockets() const { return m_fds.size(); }
    uint64_t sent() const { return m_sent.load(); }

private:
    void run(uint16_t port, int intervalUs) {
        sockaddr_in server{};
        server.sin_family = AF_INET;
        server.sin_addr.s_addr = htonl(0x7f000001u);
        server.sin_port = htons(port);
        std::mt19937 rng(11);
        std::vector<uint8_t> d(4 + sizeof(ENetProtocolConnect), 0);
        uint8_t sink[2048];
        while (!m_stop) {
            for (int fd : m_fds) {
                const uint16_t peer = uint16_t(ENET_PROTOCOL_MAXIMUM_PEER_ID) |
                                      uint16_t(ENET_PROTOCOL_HEADER_FLAG_SENT_TIME);
                d[0] = uint8_t(peer >> 8);
                d[1] = uint8_t(peer);
                ENetProtocolConnect c{};
                c.header.command = uint8_t(ENET_PROTOCOL_COMMAND_CONNECT) |
                                   uint8_t(ENET_PROTOCOL_COMMAND_FLAG_ACKNOWLEDGE);
                c.header.reliableSequenceNumber = ENET_HOST_TO_NET_16(1);
                c.outgoingPeerID = ENET_HOST_TO_NET_16(0);
                c.mtu = ENET_HOST_TO_NET_32(1400);
                c.windowSize = ENET_HOST_TO_NET_32(32768);
                c.channelCount = ENET_HOST_TO_NET_32(5);
                c.connectID = rng();
                std::memcpy(d.data() + 4, &c, sizeof c);
                if (::sendto(fd, d.data(), d.size(), 0, reinterpret_cast<sockaddr*>(&server),
                             sizeof server) > 0)
                    ++m_sent;
                while (::recv(fd, sink, sizeof sink, 0) > 0) {
                } // the server's VERIFY_CONNECT, never acknowledged
            }
            std::this_thread::sleep_for(std::chrono::microseconds(intervalUs));
        }
    }

    std::vector<int> m_fds;
    std::atomic<bool> m_stop{false};
    std::atomic<uint64_t> m_sent{0};
    std::thread m_thread;
};

// `count` ENet clients on 127.0.0.<address> that connect, never say hello, and reconnect at once
// whenever they are dropped, until destroyed. They know the protocol: asked for an admission
// cookie (RefuseReason::Retry), they connect again with it, as a client does.
class Reconnectors {
public:
    Reconnectors(uint16_t port, int count, uint8_t address, uint32_t connectData)
        : m_connectData(connectData) {
        m_thread = std::thread([=, this] { run(port, count, address); });
    }
    ~Reconnectors() {
        m_stop = true;
        m_thread.join();
    }
    uint64_t connects() const { return m_connects.load(); }

private:
    void run(uint16_t port, int count, uint8_t address) {
        ENetAddress bindTo{};
        bindTo.host = htonl(0x7f000000u | address);
        ENetAddress server{};
        enet_address_set_host(&server, "127.0.0.1");
        server.port = port;
        std::vector<ENetHost*> hosts;
        for (int i = 0; i < count; ++i)
            if (ENetHost* h = enet_host_create(&bindTo, 1, 5, 0, 0)) {
                hosts.push_back(h);
                enet_host_connect(h, &server, 5, m_connectData);
            }
        while (!m_stop) {
            for (ENetHost* h : hosts) {
                ENetEvent ev;
                while (enet_host_service(h, &ev, 0) > 0) {
                    if (ev.type == ENET_EVENT_TYPE_CONNECT)
                        ++m_connects;
                    else if (ev.type == ENET_EVENT_TYPE_RECEIVE)
                        enet_packet_destroy(ev.packet);
                    else if (ev.type == ENET_EVENT_TYPE_DISCONNECT &&
                             (ev.data & 0xff) == uint32_t(net::RefuseReason::Retry)) {
                        h->randomSeed = (ev.data >> 8) - 1; // ENet's connect ID: ++randomSeed
                        enet_host_connect(h, &server, 5, m_connectData);
                    }
                }
                // Dropped (or refused): straight back.
                if (h->peers[0].state == ENET_PEER_STATE_DISCONNECTED)
                    enet_host_connect(h, &server, 5, m_connectData);
            }
            std::this_thread::sleep_for(std::chrono::milliseconds(1));
        }
        for (ENetHost* h : hosts)
            enet_host_destroy(h);
    }

    uint32_t m_connectData; // the protocol version (ENet's connect data)
    std::atomic<bool> m_stop{false};
    std::atomic<uint64_t> m_connects{0};
    std::thread m_thread;
};

} // namespace trephine::testing

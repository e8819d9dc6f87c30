// An in-process UDP relay that emulates a network link between ENet peers on this machine:
// latency, jitter, random loss and a rate limit, in each direction. `tc netem` is not available
// on these kernels, so tests and the update study (`trephine study updates --link`) put this
// between client and server.
// Clients send to the relay's port; it forwards to the target through one socket per client, so
// any number of clients can share one relay.
#pragma once

#include <enet/enet.h>

#include <atomic>
#include <cstdint>
#include <mutex>
#include <string>
#include <thread>

namespace trephine::net {

struct LinkConditions {
    double latencyMs = 0.0; // one-way delay added in each direction
    double jitterMs = 0.0;  // uniform extra delay in [0, jitter]; order is kept
    double lossPercent = 0.0;
    // 0 = unlimited; otherwise each direction serialises at this rate, each datagram counted as
    // it occupies an Ethernet link: its UDP payload plus kWireOverheadBytes.
    double rateMbps = 0.0;
    // UDP 8 + IPv4 20 + Ethernet header and FCS 18 + preamble 8 + inter-frame gap 12 bytes.
    static constexpr size_t kWireOverheadBytes = 66;
    uint32_t seed = 1;

    // Parses "latency=25,jitter=5,loss=1,rate=100" (any subset, any order); throws
    // trephine::Error naming the text when malformed.
    static LinkConditions parse(const std::string& text);
    std::string describe() const; // "latency 0 ms, jitter 0 ms, loss 0 %, rate 100 Mbit/s"
};

class LinkEmulator {
public:
    // Relays datagrams arriving at 127.0.0.1:listenPort (0 = any free port) to target.
    LinkEmulator(uint16_t listenPort, const ENetAddress& target, LinkConditions conditions);
    ~LinkEmulator();
    LinkEmulator(const LinkEmulator&) = delete;
    LinkEmulator& operator=(const LinkEmulator&) = delete;

    uint16_t port() const { return m_port; }
    void setConditions(const LinkConditions& c);

    uint64_t forwarded() const { return m_forwarded.load(); }
    uint64_t dropped() const { return m_dropped.load(); }

private:
    void run();

    uint16_t m_port = 0;
    ENetAddress m_target{};
    ENetSocket m_front = ENET_SOCKET_NULL;
    std::mutex m_mutex;
    LinkConditions m_conditions;
    std::atomic<bool> m_stop{false};
    std::atomic<uint64_t> m_forwarded{0}, m_dropped{0};
    std::thread m_thread;
};

} // namespace trephine::net

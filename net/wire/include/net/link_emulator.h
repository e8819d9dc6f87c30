// An in-process UDP relay that emulates a network link between ENet peers on this machine:
// latency, jitter, random loss and a rate limit, in each direction. `tc netem` is not available
// on these kernels, so tests and the update study (`trephine study updates --link`) put this
// between client and server.
// Clients send to the relay's port; it forwards to the target through one socket per client, so
// any number of clients can share one relay. Towards a target on this machine each client host's
// sockets are bound to a loopback address of that host's own, so the target tells hosts apart. `--link` in every mode starts one with startLinkEnd.
#pragma once

#include <enet/enet.h>

#include <atomic>
#include <cstdint>
#include <memory>
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
    // The rate is one link that all clients share (a classroom behind one uplink), not one per
    // client: all downstream datagrams queue for one serialiser, all upstream ones for another.
    bool shared = false;
    uint32_t seed = 1;

    // Parses "latency=25,jitter=5,loss=1,rate=100,shared=1" (any subset, any order); throws
    // trephine::Error naming the text when malformed.
    static LinkConditions parse(const std::string& text);
    std::string describe() const; // "latency 0 ms, jitter 0 ms, loss 0 %, rate 100 Mbit/s"
};

class LinkEmulator {
public:
    // Relays datagrams arriving at 127.0.0.1:listenPort (0 = any free port) to target; with
    // `anyHost`, at listenPort on every interface (a server's public port).
    LinkEmulator(uint16_t listenPort, const ENetAddress& target, LinkConditions conditions,
                 bool anyHost = false);
    ~LinkEmulator();
    LinkEmulator(const LinkEmulator&) = delete;
    LinkEmulator& operator=(const LinkEmulator&) = delete;

    uint16_t port() const { return m_port; }
    void setConditions(const LinkConditions& c);
    LinkConditions conditions() const;

    uint64_t forwarded() const { return m_forwarded.load(); }
    uint64_t dropped() const { return m_dropped.load(); }
    // UDP payload bytes the target sent towards the clients (its egress, before loss) and the
    // clients sent towards the target.
    uint64_t bytesDown() const { return m_bytesDown.load(); }
    uint64_t bytesUp() const { return m_bytesUp.load(); }

private:
    void run();

    uint16_t m_port = 0;
    ENetAddress m_target{};
    ENetSocket m_front = ENET_SOCKET_NULL;
    mutable std::mutex m_mutex;
    LinkConditions m_conditions;
    std::atomic<bool> m_stop{false};
    std::atomic<uint64_t> m_forwarded{0}, m_dropped{0}, m_bytesDown{0}, m_bytesUp{0};
    std::thread m_thread;
};

// Which end of a session `--link` runs on: a server puts the relay on its public port in front
// of a private one; a client connects through a relay on a free loopback port.
enum class LinkEnd { Server, Client };

// --link's SPEC checked: LinkConditions::parse's, refusing an empty one and a loss of 100 %
// (nothing would get through) with one line naming it.
LinkConditions linkSpecConditions(const std::string& spec);
// `--link SPEC` of every mode (server, trainee, instructor, demo), so the flag means the same
// everywhere: SPEC as linkSpecConditions reads it. Relays `publicPort` (Server: on every interface;
// Client: 0, a loopback port) to `target`. An empty SPEC is no link: null.
std::unique_ptr<LinkEmulator> startLinkEnd(const std::string& spec, LinkEnd end,
                                           const ENetAddress& target, uint16_t publicPort = 0);
// "127.0.0.1:PORT": where a client on this machine reaches the relay.
std::string relayAddress(const LinkEmulator& link);

} // namespace trephine::net

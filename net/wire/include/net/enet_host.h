// A thin RAII layer over ENet: library initialisation, one host (server or client), channel
// purposes, HOST:PORT parsing, and draining every pending event per service call (ENet returns one
// event per enet_host_service; the rest wait in enet_host_check_events).
#pragma once

#include "net/fragments.h"

#include <enet/enet.h>

#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <utility>
#include <vector>

namespace trephine::net {

// One purpose per channel, so small latency-critical messages never queue behind bulk data.
enum class Channel : uint8_t {
    Control = 0,   // reliable: hello, welcome, view requests, pings
    ToolState = 1, // unsequenced, newest wins: the client's tool pose
    Haptic = 2,    // unsequenced, newest wins: force and gradient from the server
    Image = 3,     // reliable: DBI rectangle updates
    Volume = 4,    // reliable: voxel updates for the replicated-volume baseline
    // Unreliable, newest wins (a message older than one delivered is dropped), in fragments of
    // our own with parity (net/fragments.h): drilling rectangles, state the server repairs from
    // acknowledgements (net/outbox.h).
    ImageLossy = 5,
    Count = 6
};
const char* channelName(Channel c);

// ENet packet flags for a channel's purpose.
uint32_t channelPacketFlags(Channel c);

// Initialises ENet once per process for as long as any instance lives.
class EnetLibrary {
public:
    EnetLibrary();
    ~EnetLibrary();
    EnetLibrary(const EnetLibrary&) = delete;
    EnetLibrary& operator=(const EnetLibrary&) = delete;
};

// Parses "HOST:PORT" (or ":PORT" / "PORT" for the loopback host); throws trephine::Error with one
// line naming the text when it is not an address.
ENetAddress parseAddress(const std::string& text, uint16_t defaultPort = 7777);
std::string formatAddress(const ENetAddress& a);

// ENet drops unreliable and unsequenced packets at the sender when round-trip times vary (its
// packet throttle), which on a busy machine loses tool states that the simulation integrates.
// Ours are small and newest-wins: keep the throttle fully open on both ends of a session.
inline void disableThrottle(ENetPeer* peer) {
    enet_peer_throttle_configure(peer, ENET_PEER_PACKET_THROTTLE_INTERVAL,
                                 ENET_PEER_PACKET_THROTTLE_ACCELERATION, 0);
    peer->packetThrottle = ENET_PEER_PACKET_THROTTLE_SCALE;
}

// How a server host sizes each peer's reliable window. ENet sends reliable data only while less
// than peer->windowSize is unacknowledged, and negotiates at most 64 KiB: ~5 Mbit/s at 100 ms
// RTT, so a full 500^2 view took 8 round trips. The host sizes the window itself instead, by
// delay: it grows while the smoothed RTT stays within queueTargetMs of the lowest seen, shrinks
// when bulk data queues up on the path, and releases new data at window / lowest RTT, so the
// path's queue (where tool states and force models wait too) stays about queueTargetMs long.
struct BulkWindow {
    // Off by default: on a 1 Mbit/s link with no delay it stalled a client's updates for good
    // (SessionLossy.ASlowClientsBacklogStaysBoundedAndItCatchesUp fails with it on); ENet's
    // negotiated 64 KiB window then.
    bool adaptive = false;
    uint32_t minBytes = 64 * 1024;
    uint32_t maxBytes = 16u << 20;
    double queueTargetMs = 10;
    uint32_t burstBytes = 16 * 1024; // the most released at once beyond the pace
};

class Host {
public:
    using EventHandler = std::function<void(const ENetEvent&)>;

    // A server host bound to port (0 = any free port; see port()). Throws trephine::Error.
    static Host listen(uint16_t port, size_t maxPeers, BulkWindow window = {});
    // A client host with one outgoing peer slot.
    static Host client();

    Host(Host&& o) noexcept;
    Host& operator=(Host&& o) noexcept;
    Host(const Host&) = delete;
    ~Host();

    ENetHost* get() const { return m_host; }
    uint16_t port() const { return m_host ? m_host->address.port : 0; }

    // Starts connecting; the protocol version travels in the connect data. With `connectId`
    // (an admission cookie, net/admission.h) the connection carries that connect ID: null when
    // this ENet cannot be made to.
    ENetPeer* connect(const ENetAddress& address, uint32_t connectData,
                      std::optional<uint32_t> connectId = std::nullopt);

    // Waits up to timeoutMs for the first event, then drains every event already pending and
    // flushes queued sends. Packets in receive events are destroyed after the handler returns.
    // Returns the number of events handled.
    int service(uint32_t timeoutMs, const EventHandler& handler);
    // Sends what is queued, then waits up to timeoutMs for a datagram on the socket (a runner's
    // wait; service(0) then handles what came).
    void wait(uint32_t timeoutMs);

    // Bytes of packets sent with it that ENet still holds (queued, or sent and not acknowledged):
    // each packet keeps the counter alive until ENet releases it, so it outlives its peer.
    using InFlight = std::shared_ptr<std::atomic<int64_t>>;

    // Queues a packet on the channel with that channel's flags; sent on the next service/flush.
    // With `inFlight`, its size counts there until ENet releases the packet. On
    // Channel::ImageLossy it goes as datagram-sized fragments with the parity for a loss of
    // `lossPermille` per thousand (0: none; net/fragments.h); the receiving host delivers it whole.
    // Returns the bytes queued (on ImageLossy its fragments', headers and parity included: what
    // the link carries), 0 when it could not be queued.
    size_t send(ENetPeer* peer, Channel channel, std::span<const uint8_t> bytes,
                const InFlight& inFlight = {}, uint32_t lossPermille = 0);
    void flush();

    // The largest Channel::ImageLossy message a host puts back together: a client's (a server's
    // images), and a server's (a client's acknowledgements).
    static constexpr size_t kClientLossyMessageBytes = 16u << 20, kServerLossyMessageBytes = 4096;
    // Of the Channel::ImageLossy datagrams from `peer`: lost per thousand, smoothed. One that is
    // not a fragment reaches the handler as it came, for the session to refuse as malformed.
    uint32_t lossPermille(const ENetPeer* peer) const;

    void setBulkWindow(const BulkWindow& w) { m_window = w; }
    // The window the host gives peer now (ENet's own when not adaptive).
    uint32_t windowBytes(const ENetPeer* peer) const { return peer->windowSize; }

private:
    Host(ENetHost* h, size_t lossyMessageBytes)
        : m_host(h), m_lossyMessageBytes(lossyMessageBytes) {}
    // One peer slot's window as the host sizes it.
    struct PeerWindow {
        uint32_t connectId = 0; // the connection it belongs to: a new one starts afresh
        double window = 0, tokens = 0, minRttMs = 0, periodMinRttMs = 0;
        uint32_t lastMs = 0, periodStartMs = 0, inTransit = 0;
    };
    // One peer slot's lossy messages: the count of those sent, and those coming back together.
    struct PeerFragments {
        uint32_t connectId = 0;
        uint32_t sent = 0;
        std::optional<FragmentAssembler> assembler;
    };
    // Before ENet sends: every connected peer's window for this pass. After: what it sent.
    void paceBefore();
    void paceAfter();
    PeerFragments& fragments(const ENetPeer* peer);
    bool sendPacket(ENetPeer* peer, Channel channel, std::span<const uint8_t> bytes,
                    const InFlight& inFlight);
    // A Channel::ImageLossy datagram received: the handler gets the message it completes.
    void reassemble(const ENetEvent& ev, const EventHandler& handler);
    EnetLibrary m_lib;
    ENetHost* m_host = nullptr;
    size_t m_lossyMessageBytes = kClientLossyMessageBytes;
    BulkWindow m_window{false};
    std::vector<PeerWindow> m_peers;
    std::vector<PeerFragments> m_fragments;
};

} // namespace trephine::net

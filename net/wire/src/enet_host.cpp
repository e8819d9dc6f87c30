#include "net/enet_host.h"

#include "libsim/error.h"

#include <algorithm>
#include <atomic>
#include <charconv>
#include <mutex>

namespace trephine::net {

const char* channelName(Channel c) {
    switch (c) {
    case Channel::Control:
        return "control";
    case Channel::ToolState:
        return "tool";
    case Channel::Haptic:
        return "haptic";
    case Channel::Image:
        return "image";
    case Channel::Volume:
        return "volume";
    case Channel::ImageLossy:
        return "image-lossy";
    default:
        return "?";
    }
}

uint32_t channelPacketFlags(Channel c) {
    switch (c) {
    case Channel::ToolState:
    case Channel::Haptic:
        return ENET_PACKET_FLAG_UNSEQUENCED;
    case Channel::ImageLossy:
        // Our fragments, each under the MTU; their order is ours to keep (net/fragments.h).
        return ENET_PACKET_FLAG_UNSEQUENCED;
    default:
        return ENET_PACKET_FLAG_RELIABLE;
    }
}

namespace {
std::mutex g_libMutex;
int g_libUsers = 0;
} // namespace

EnetLibrary::EnetLibrary() {
    std::lock_guard lock(g_libMutex);
    if (g_libUsers++ == 0 && enet_initialize() != 0)
        throw Error("could not initialise ENet");
}

EnetLibrary::~EnetLibrary() {
    std::lock_guard lock(g_libMutex);
    if (--g_libUsers == 0)
        enet_deinitialize();
}

ENetAddress parseAddress(const std::string& text, uint16_t defaultPort) {
    std::string host = "127.0.0.1";
    std::string portText;
    size_t colon = text.rfind(':');
    if (colon == std::string::npos) {
        bool digits = !text.empty() && text.find_first_not_of("0123456789") == std::string::npos;
        if (digits)
            portText = text;
        else
            host = text;
    } else {
        if (colon > 0)
            host = text.substr(0, colon);
        portText = text.substr(colon + 1);
    }
    uint16_t port = defaultPort;
    if (!portText.empty()) {
        unsigned value = 0;
        auto [end, ec] = std::from_chars(portText.data(), portText.data() + portText.size(), value);
        if (ec != std::errc() || end != portText.data() + portText.size() || value > 65535)
            throw Error("'" + text + "' is not HOST:PORT (the port must be a number 0-65535)");
        port = uint16_t(value);
    }
    if (host == "localhost")
        host = "127.0.0.1";
    ENetAddress a{};
    if (enet_address_set_host(&a, host.c_str()) != 0)
        throw Error("'" + text + "': cannot resolve host '" + host + "'");
    a.port = port;
    return a;
}

std::string formatAddress(const ENetAddress& a) {
    char ip[64] = "?";
    enet_address_get_host_ip(&a, ip, sizeof ip);
    return std::string(ip) + ":" + std::to_string(a.port);
}

Host Host::listen(uint16_t port, size_t maxPeers, BulkWindow window) {
    EnetLibrary lib; // keeps ENet initialised while the host is created
    ENetAddress a{};
    a.host = ENET_HOST_ANY;
    a.port = port;
    ENetHost* h = enet_host_create(&a, maxPeers, size_t(Channel::Count), 0, 0);
    if (!h)
        throw Error("cannot listen on UDP port " + std::to_string(port) +
                    " (in use? try another --port)");
    Host host(h, kServerLossyMessageBytes);
    host.m_window = window;
    return host;
}

Host Host::client() {
    EnetLibrary lib;
    ENetHost* h = enet_host_create(nullptr, 1, size_t(Channel::Count), 0, 0);
    if (!h)
        throw Error("cannot create an ENet client host");
    return Host(h, kClientLossyMessageBytes);
}

Host::Host(Host&& o) noexcept
    : m_host(o.m_host), m_lossyMessageBytes(o.m_lossyMessageBytes), m_window(o.m_window),
      m_peers(std::move(o.m_peers)), m_fragments(std::move(o.m_fragments)) {
    o.m_host = nullptr;
}

Host& Host::operator=(Host&& o) noexcept {
    if (this != &o) {
        if (m_host)
            enet_host_destroy(m_host);
        m_host = o.m_host;
        m_lossyMessageBytes = o.m_lossyMessageBytes;
        m_window = o.m_window;
        m_peers = std::move(o.m_peers);
        m_fragments = std::move(o.m_fragments);
        o.m_host = nullptr;
    }
    return *this;
}

Host::~Host() {
    if (m_host)
        enet_host_destroy(m_host);
}

ENetPeer* Host::connect(const ENetAddress& address, uint32_t connectData,
                        std::optional<uint32_t> connectId) {
    // ENet 1.3.17 draws a connection's ID as ++randomSeed; a build that draws it otherwise
    // cannot return a cookie, which the check below catches (test_enet_host guards it too).
    if (connectId)
        m_host->randomSeed = *connectId - 1;
    ENetPeer* peer = enet_host_connect(m_host, &address, size_t(Channel::Count), connectData);
    if (peer && connectId && peer->connectID != *connectId) {
        enet_peer_reset(peer);
        return nullptr;
    }
    return peer;
}

int Host::service(uint32_t timeoutMs, const EventHandler& handler) {
    int handled = 0;
    ENetEvent ev;
    paceBefore();
    int r = enet_host_service(m_host, &ev, timeoutMs);
    paceAfter();
    while (r > 0) {
        if (ev.type == ENET_EVENT_TYPE_RECEIVE && ev.channelID == uint8_t(Channel::ImageLossy))
            reassemble(ev, handler);
        else
            handler(ev);
        if (ev.type == ENET_EVENT_TYPE_RECEIVE)
            enet_packet_destroy(ev.packet);
        ++handled;
        r = enet_host_check_events(m_host, &ev);
    }
    flush();
    return handled;
}

void Host::flush() {
    paceBefore();
    enet_host_flush(m_host);
    paceAfter();
}

// [SECTION] the bulk window

// Delay-based, as LEDBAT: the smoothed RTT above the lowest of the last 10-20 s is the queue our
// data built on the path. Below the target the window grows (up to 1.5x a round trip while it
// is in use), above it shrinks (down to half a round trip), so the path holds about the target
// of queue and the window about a bandwidth-delay product. Random loss does not shrink it.
void Host::paceBefore() {
    if (!m_window.adaptive || !m_host)
        return;
    const uint32_t now = enet_time_get();
    m_peers.resize(m_host->peerCount);
    for (size_t i = 0; i < m_host->peerCount; ++i) {
        ENetPeer* p = &m_host->peers[i];
        if (p->state != ENET_PEER_STATE_CONNECTED)
            continue;
        PeerWindow& w = m_peers[i];
        if (w.connectId != p->connectID || w.window <= 0) {
            w = PeerWindow{};
            w.connectId = p->connectID;
            w.window = m_window.minBytes;
            w.lastMs = w.periodStartMs = now;
        }
        const double dt = std::min<double>(now - w.lastMs, 100.0);
        w.lastMs = now;
        const double rtt = std::max<double>(p->roundTripTime, 1.0);
        if (now - w.periodStartMs >= 10000) {
            w.minRttMs = w.periodMinRttMs;
            w.periodMinRttMs = 0;
            w.periodStartMs = now;
        }
        w.periodMinRttMs = w.periodMinRttMs > 0 ? std::min(w.periodMinRttMs, rtt) : rtt;
        const double base =
            w.minRttMs > 0 ? std::min(w.minRttMs, w.periodMinRttMs) : w.periodMinRttMs;
        const double queue = rtt - base, target = m_window.queueTargetMs;
        const double rounds = std::min(1.0, dt / base);
        // Grown only while in use: an idle peer's window says nothing about the path.
        const bool used = double(p->reliableDataInTransit) + p->mtu > w.window * 0.5;
        if (queue <= target) {
            if (used)
                w.window *= 1.0 + 0.5 * rounds * (1.0 - queue / target);
        } else {
            w.window *= 1.0 - 0.5 * rounds * std::min(1.0, (queue - target) / target);
        }
        // ENet multiplies the window by its packet throttle (<= 32) in 32 bits.
        const double most = std::min(double(m_window.maxBytes),
                                     double(UINT32_MAX / ENET_PEER_PACKET_THROTTLE_SCALE));
        w.window = std::clamp(w.window, double(m_window.minBytes), most);
        // Paced: a window spread over the lowest round trip, so an idle peer's first image does
        // not enter the path at once.
        const double pace = w.window / base; // bytes a millisecond
        w.tokens = std::min(w.tokens + pace * dt, std::max(double(m_window.burstBytes), pace * dt));
        w.inTransit = p->reliableDataInTransit;
        p->windowSize = uint32_t(std::min(w.window, double(w.inTransit) + std::max(w.tokens, 0.0)));
    }
}

// What ENet sent in the pass (in-transit bytes grew by it, less acknowledgements it took in:
// those freed the path, so sending in their place is the ack clock) comes off the tokens.
void Host::paceAfter() {
    if (!m_window.adaptive || !m_host)
        return;
    for (size_t i = 0; i < m_host->peerCount && i < m_peers.size(); ++i) {
        ENetPeer* p = &m_host->peers[i];
        PeerWindow& w = m_peers[i];
        if (p->state != ENET_PEER_STATE_CONNECTED || w.connectId != p->connectID)
            continue;
        if (p->reliableDataInTransit > w.inTransit)
            w.tokens -= double(p->reliableDataInTransit - w.inTransit);
        w.inTransit = p->reliableDataInTransit;
        p->windowSize = uint32_t(std::min(w.window, double(w.inTransit) + std::max(w.tokens, 0.0)));
    }
}

void Host::wait(uint32_t timeoutMs) {
    flush();
    enet_uint32 condition = ENET_SOCKET_WAIT_RECEIVE | ENET_SOCKET_WAIT_INTERRUPT;
    enet_socket_wait(m_host->socket, &condition, timeoutMs);
}

namespace {
// ENet destroys a packet once it is sent (unreliable) or acknowledged (reliable), or with its
// peer: the bytes leave the counter then, and the packet's share of the counter goes.
void releaseInFlight(ENetPacket* packet) {
    auto* counter = static_cast<Host::InFlight*>(packet->userData);
    (*counter)->fetch_sub(int64_t(packet->dataLength), std::memory_order_relaxed);
    delete counter;
}
} // namespace

Host::PeerFragments& Host::fragments(const ENetPeer* peer) {
    const size_t slot = size_t(peer - m_host->peers);
    if (m_fragments.size() < m_host->peerCount)
        m_fragments.resize(m_host->peerCount);
    PeerFragments& f = m_fragments[slot];
    if (!f.assembler || f.connectId != peer->connectID) {
        f = PeerFragments{};
        f.connectId = peer->connectID;
        f.assembler.emplace(m_lossyMessageBytes);
    }
    return f;
}

uint32_t Host::lossPermille(const ENetPeer* peer) const {
    const size_t slot = size_t(peer - m_host->peers);
    if (slot >= m_fragments.size() || !m_fragments[slot].assembler ||
        m_fragments[slot].connectId != peer->connectID)
        return 0;
    return m_fragments[slot].assembler->lossPermille();
}

void Host::reassemble(const ENetEvent& ev, const EventHandler& handler) {
    std::vector<uint8_t> message;
    const auto result = fragments(ev.peer).assembler->add(
        std::span<const uint8_t>(ev.packet->data, ev.packet->dataLength), message);
    if (result == FragmentAssembler::Result::Refused)
        handler(ev); // not ours: the session finds it malformed, and whose it is
    if (result != FragmentAssembler::Result::Complete)
        return;
    ENetEvent whole = ev;
    whole.packet = enet_packet_create(message.data(), message.size(), ev.packet->flags);
    if (!whole.packet)
        return;
    handler(whole);
    enet_packet_destroy(whole.packet);
}

size_t Host::send(ENetPeer* peer, Channel channel, std::span<const uint8_t> bytes,
                  const InFlight& inFlight, uint32_t lossPermille) {
    if (channel == Channel::ImageLossy) {
        // Each fragment fits one ENet datagram unfragmented: the MTU less ENet's headers.
        const size_t room = peer->mtu - sizeof(ENetProtocolHeader) - sizeof(uint32_t) -
                            sizeof(ENetProtocolSendFragment);
        const auto pieces = splitMessage(bytes, fragments(peer).sent++, room, lossPermille);
        bool sent = !pieces.empty();
        size_t queued = 0;
        for (const auto& piece : pieces) {
            sent = sendPacket(peer, channel, piece, inFlight) && sent;
            queued += piece.size();
        }
        return sent ? queued : 0;
    }
    return sendPacket(peer, channel, bytes, inFlight) ? bytes.size() : 0;
}

bool Host::sendPacket(ENetPeer* peer, Channel channel, std::span<const uint8_t> bytes,
                      const InFlight& inFlight) {
    ENetPacket* p = enet_packet_create(bytes.data(), bytes.size(), channelPacketFlags(channel));
    if (!p)
        return false;
    if (inFlight) {
        inFlight->fetch_add(int64_t(p->dataLength), std::memory_order_relaxed);
        p->userData = new InFlight(inFlight);
        p->freeCallback = releaseInFlight;
    }
    if (enet_peer_send(peer, uint8_t(channel), p) != 0) {
        enet_packet_destroy(p);
        return false;
    }
    return true;
}

} // namespace trephine::net

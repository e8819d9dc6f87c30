#include "net/admission.h"

#include "net/protocol.h"
#include "net/secure_channel.h"

#include <sodium.h>

#include <enet/protocol.h>

#include <algorithm>
#include <cstddef>
#include <cstring>
#include <optional>

namespace trephine::net {

namespace {

uint16_t readBig16(const uint8_t* p) {
    return uint16_t((p[0] << 8) | p[1]);
}

// The offset of the first command in an uncompressed ENet datagram, or 0 when there is none.
size_t firstCommand(std::span<const uint8_t> d) {
    if (d.size() < 2)
        return 0;
    const uint16_t peerId = readBig16(d.data());
    if (peerId & ENET_PROTOCOL_HEADER_FLAG_COMPRESSED)
        return 0;
    const size_t header = (peerId & ENET_PROTOCOL_HEADER_FLAG_SENT_TIME) ? 4 : 2;
    return d.size() > header ? header : 0;
}

// The connect ID of a CONNECT datagram (isEnetConnect), in ENet's byte order.
uint32_t connectIdOf(std::span<const uint8_t> d) {
    const size_t at = firstCommand(d) + offsetof(ENetProtocolConnect, connectID);
    uint32_t id = 0;
    if (at + sizeof id <= d.size())
        std::memcpy(&id, d.data() + at, sizeof id);
    return id;
}

// Whether ENet would take the CONNECT (isEnetConnect): its channel count in ENet's range.
bool acceptableChannels(std::span<const uint8_t> d) {
    ENetProtocolConnect c;
    std::memcpy(&c, d.data() + firstCommand(d), sizeof c);
    const uint32_t channels = ENET_NET_TO_HOST_32(c.channelCount);
    return channels >= ENET_PROTOCOL_MINIMUM_CHANNEL_COUNT &&
           channels <= ENET_PROTOCOL_MAXIMUM_CHANNEL_COUNT;
}

// ENet states a server-side slot passes through on its way in or out; a peer that stops
// answering leaves it in one for ENet's full timeout (~30 s).
bool transient(ENetPeerState s) {
    switch (s) {
    case ENET_PEER_STATE_ACKNOWLEDGING_CONNECT:
    case ENET_PEER_STATE_CONNECTION_PENDING:
    case ENET_PEER_STATE_DISCONNECT_LATER:
    case ENET_PEER_STATE_DISCONNECTING:
    case ENET_PEER_STATE_ACKNOWLEDGING_DISCONNECT:
        return true;
    default:
        return false;
    }
}

} // namespace

bool isEnetConnect(std::span<const uint8_t> d) {
    const size_t at = firstCommand(d);
    if (at == 0 || d.size() < at + sizeof(ENetProtocolConnect))
        return false;
    const uint16_t peerId = readBig16(d.data()) & ENET_PROTOCOL_MAXIMUM_PEER_ID;
    return peerId == ENET_PROTOCOL_MAXIMUM_PEER_ID &&
           (d[at] & ENET_PROTOCOL_COMMAND_MASK) == ENET_PROTOCOL_COMMAND_CONNECT;
}

std::vector<uint8_t> refusalDatagram(std::span<const uint8_t> d, uint32_t data) {
    if (!isEnetConnect(d))
        return {};
    ENetProtocolConnect c;
    std::memcpy(&c, d.data() + firstCommand(d), sizeof c);
    // The header names the client's own peer (its outgoing id in the CONNECT); a connecting
    // peer checks no session id yet. No ACKNOWLEDGE flag: nothing comes back.
    std::vector<uint8_t> out(2 + sizeof(ENetProtocolDisconnect));
    const uint16_t peer = ENET_NET_TO_HOST_16(c.outgoingPeerID) & ENET_PROTOCOL_MAXIMUM_PEER_ID;
    out[0] = uint8_t(peer >> 8);
    out[1] = uint8_t(peer);
    ENetProtocolDisconnect cmd{};
    cmd.header.command =
        uint8_t(ENET_PROTOCOL_COMMAND_DISCONNECT) | uint8_t(ENET_PROTOCOL_COMMAND_FLAG_UNSEQUENCED);
    cmd.header.channelID = 0xFF;
    cmd.data = ENET_HOST_TO_NET_32(data);
    std::memcpy(out.data() + 2, &cmd, sizeof cmd);
    return out;
}

// [SECTION] rules

ConnectCookies::ConnectCookies() {
    initSodium();
    randombytes_buf(m_key.data(), m_key.size());
}

uint32_t ConnectCookies::at(const ENetAddress& from, uint64_t epoch) const {
    uint8_t in[14];
    std::memcpy(in, &from.host, 4);
    std::memcpy(in + 4, &from.port, 2);
    std::memcpy(in + 6, &epoch, 8);
    uint8_t out[crypto_shorthash_BYTES];
    crypto_shorthash(out, in, sizeof in, m_key.data());
    return uint32_t(out[0]) | uint32_t(out[1]) << 8 | uint32_t(out[2]) << 16;
}

uint32_t ConnectCookies::cookie(const ENetAddress& from, uint64_t nowUs) const {
    return at(from, nowUs / kEpochUs);
}

bool ConnectCookies::valid(uint32_t connectId, const ENetAddress& from, uint64_t nowUs) const {
    const uint64_t epoch = nowUs / kEpochUs;
    return connectId == at(from, epoch) || (epoch > 0 && connectId == at(from, epoch - 1));
}

ConnectBuckets::ConnectBuckets(double perS, double burst, uint64_t salt)
    : m_perS(perS), m_burst(burst), m_salt(salt) {}

ConnectBuckets::Bucket& ConnectBuckets::slot(uint32_t address) {
    uint64_t h = (uint64_t(address) ^ m_salt) * 0xff51afd7ed558ccdull;
    h ^= h >> 33;
    return m_table[h % kBuckets];
}

bool ConnectBuckets::take(uint32_t address, uint64_t nowUs) {
    Bucket& b = slot(address);
    if (!b.used || b.address != address) {
        // A new address in this bucket starts from whatever the last one left (never more than
        // a full bucket): an attacker cycling addresses gains nothing by colliding.
        if (!b.used)
            b.tokens = m_burst;
        b.used = true;
        b.address = address;
    }
    if (nowUs > b.lastUs)
        b.tokens = std::min(m_burst, b.tokens + double(nowUs - b.lastUs) * 1e-6 * m_perS);
    b.lastUs = std::max(b.lastUs, nowUs);
    if (b.tokens < 1.0)
        return false;
    b.tokens -= 1.0;
    return true;
}

bool ConnectBuckets::has(uint32_t address, uint64_t nowUs) {
    const Bucket saved = slot(address);
    const bool token = take(address, nowUs);
    slot(address) = saved;
    return token;
}

ConnectDecision judgeConnect(const AdmissionLimits& limits, ConnectBuckets& buckets,
                             uint32_t address, std::span<const WaitingPeer> waiting,
                             uint64_t nowUs) {
    ConnectDecision d;
    // Waiting peers per address, counted once: the pool is full at every CONNECT of a flood.
    std::vector<uint32_t> addresses(waiting.size());
    std::transform(waiting.begin(), waiting.end(), addresses.begin(),
                   [](const WaitingPeer& w) { return w.address; });
    std::sort(addresses.begin(), addresses.end());
    const auto held = [&](uint32_t a) {
        const auto [lo, hi] = std::equal_range(addresses.begin(), addresses.end(), a);
        return size_t(hi - lo);
    };
    const size_t mine = held(address);
    // Refusals that spend no token come first, so a client that retries once the slots free
    // finds its bucket as it left it.
    if (mine >= limits.waitingPerAddress) {
        d.verdict = ConnectVerdict::AddressBusy;
        return d;
    }
    if (waiting.size() >= limits.waitingSlots) {
        // The address holding the most (ties: the one whose candidate ranks first), and its
        // candidate: silent before under way, then the oldest.
        const auto before = [](const WaitingPeer& a, const WaitingPeer& b) {
            return a.progressing != b.progressing ? !a.progressing : a.sinceUs < b.sinceUs;
        };
        size_t most = 0;
        std::optional<size_t> victim;
        for (size_t i = 0; i < waiting.size(); ++i) {
            const size_t n = held(waiting[i].address);
            if (n > most || (n == most && victim && before(waiting[i], waiting[*victim]))) {
                most = n;
                victim = i;
            }
        }
        // Only a share that is larger by two gives one up: addresses one apart would take
        // slots from each other for ever.
        if (!victim || most <= mine + 1) {
            d.verdict = ConnectVerdict::PoolFull;
            return d;
        }
        d.verdict = ConnectVerdict::Displace;
        d.displace = *victim;
    }
    if (!buckets.take(address, nowUs))
        d.verdict = ConnectVerdict::RateLimited;
    return d;
}

bool SlotTimer::expired(size_t index, bool transientNow, uint64_t nowUs, uint64_t timeoutUs) {
    uint64_t& since = m_since.at(index);
    if (!transientNow) {
        since = 0;
        return false;
    }
    if (since == 0)
        since = std::max<uint64_t>(nowUs, 1);
    return nowUs - since > timeoutUs;
}

// [SECTION] the gate on an ENet host

AdmissionGate::AdmissionGate(ENetHost* host, const AdmissionLimits& limits, Admitted admitted,
                             OnReset onReset)
    : m_host(host), m_limits(limits), m_admitted(std::move(admitted)),
      m_onReset(std::move(onReset)), m_buckets(limits.connectsPerS, limits.connectBurst),
      m_refusals(2.0, 2.0), m_cookieReplies(16.0, 32.0), m_timer(host->peerCount),
      m_occupant(host->peerCount, {0, 0}) {}

uint64_t AdmissionGate::occupiedSince(size_t index) {
    auto& [connectId, since] = m_occupant.at(index);
    const ENetPeer& p = m_host->peers[index];
    if (since == 0 || connectId != p.connectID) {
        connectId = p.connectID;
        since = std::max<uint64_t>(m_nowUs, 1);
    }
    return since;
}

void AdmissionGate::reset(ENetPeer* p, bool tell) {
    m_timer.forget(size_t(p - m_host->peers));
    m_occupant.at(size_t(p - m_host->peers)) = {0, 0};
    if (m_onReset)
        m_onReset(p);
    if (tell) // a displaced peer learns why, and that the server is there
        enet_peer_disconnect_now(p, uint32_t(RefuseReason::Busy));
    else
        enet_peer_reset(p);
}

int AdmissionGate::judge() {
    const std::span<const uint8_t> d(m_host->receivedData, m_host->receivedDataLength);
    if (!isEnetConnect(d))
        return 0;
    const ENetAddress& from = m_host->receivedAddress;
    const uint32_t connectId = connectIdOf(d);
    for (size_t i = 0; i < m_host->peerCount; ++i) {
        const ENetPeer& p = m_host->peers[i];
        // ENet answers a repeated CONNECT of a handshake under way itself: not a new connection.
        if (p.state != ENET_PEER_STATE_DISCONNECTED && p.address.host == from.host &&
            p.address.port == from.port && p.connectID == connectId)
            return 0;
    }
    // One ENet refuses (no channel, or too many) takes no one's slot: ENet drops it.
    if (!acceptableChannels(d))
        return 0;
    // ENet copies the connect ID as it is (the client's byte order, x86's on both ends).
    const bool cookie = m_cookies.valid(connectId, from, m_nowUs);
    // Under pressure a CONNECT without its cookie, or from an address over its rate, is answered
    // before any look at the slots: a flood of them costs a hash each (the count of waiting
    // peers is the last CONNECT's or reap's).
    if (!cookie && m_lastWaiting >= m_limits.cookiesFrom)
        return askForCookie();
    if (!m_buckets.has(from.host, m_nowUs)) {
        ++m_counts.rateLimited;
        answer(m_refusals, uint32_t(RefuseReason::Busy));
        return 1;
    }
    m_waiting.clear();
    m_waitingPeers.clear();
    for (size_t i = 0; i < m_host->peerCount; ++i) {
        ENetPeer& p = m_host->peers[i];
        if (p.state == ENET_PEER_STATE_DISCONNECTED)
            continue;
        const Standing standing = m_admitted(&p);
        if (standing == Standing::Admitted)
            continue;
        m_waiting.push_back({p.address.host, occupiedSince(i), standing == Standing::Progressing});
        m_waitingPeers.push_back(&p);
    }
    m_lastWaiting = m_waiting.size();
    if (!cookie && m_waiting.size() >= m_limits.cookiesFrom)
        return askForCookie();
    const ConnectDecision decision =
        judgeConnect(m_limits, m_buckets, from.host, m_waiting, m_nowUs);
    switch (decision.verdict) {
    case ConnectVerdict::Accept:
        return 0;
    case ConnectVerdict::Displace:
        ++m_counts.displaced;
        reset(m_waitingPeers.at(decision.displace), true);
        return 0;
    case ConnectVerdict::RateLimited:
        ++m_counts.rateLimited;
        break;
    case ConnectVerdict::AddressBusy:
        ++m_counts.addressBusy;
        break;
    case ConnectVerdict::PoolFull:
        ++m_counts.poolFull;
        break;
    }
    answer(m_refusals, uint32_t(RefuseReason::Busy));
    return 1;
}

int AdmissionGate::askForCookie() {
    ++m_counts.cookieless;
    const ENetAddress& from = m_host->receivedAddress;
    answer(m_cookieReplies, uint32_t(RefuseReason::Retry) | m_cookies.cookie(from, m_nowUs) << 8);
    return 1;
}

void AdmissionGate::answer(ConnectBuckets& budget, uint32_t data) {
    const ENetAddress& from = m_host->receivedAddress;
    if (!budget.take(from.host, m_nowUs))
        return;
    const std::vector<uint8_t> refusal =
        refusalDatagram({m_host->receivedData, m_host->receivedDataLength}, data);
    ENetBuffer b{const_cast<uint8_t*>(refusal.data()), refusal.size()};
    enet_socket_send(m_host->socket, &from, &b, 1);
}

void AdmissionGate::reap(uint64_t nowUs) {
    m_lastWaiting = 0;
    for (size_t i = 0; i < m_host->peerCount; ++i) {
        ENetPeer* p = &m_host->peers[i];
        m_lastWaiting +=
            p->state != ENET_PEER_STATE_DISCONNECTED && m_admitted(p) != Standing::Admitted;
        if (!m_timer.expired(i, transient(ENetPeerState(p->state)), nowUs,
                             m_limits.handshakeTimeoutUs))
            continue;
        ++m_counts.handshakesReset;
        reset(p, false);
    }
}

} // namespace trephine::net

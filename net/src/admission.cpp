#include "net/admission.h"

#include <enet/protocol.h>

#include <algorithm>
#include <cstddef>
#include <cstring>

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

// [SECTION] rules

ConnectBuckets::ConnectBuckets(double perS, double burst, uint64_t salt)
    : m_perS(perS), m_burst(burst), m_salt(salt) {}

bool ConnectBuckets::take(uint32_t address, uint64_t nowUs) {
    uint64_t h = (uint64_t(address) ^ m_salt) * 0xff51afd7ed558ccdull;
    h ^= h >> 33;
    Bucket& b = m_table[h % kBuckets];
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

ConnectVerdict judgeConnect(const AdmissionLimits& limits, ConnectBuckets& buckets,
                            uint32_t address, size_t waitingFromAddress, size_t waiting,
                            uint64_t nowUs) {
    // Slots first: a refused datagram spends no token, so a client that retries once the slots
    // free finds its bucket as it left it.
    if (waiting >= limits.waitingSlots)
        return ConnectVerdict::PoolFull;
    if (waitingFromAddress >= limits.waitingPerAddress)
        return ConnectVerdict::AddressBusy;
    if (!buckets.take(address, nowUs))
        return ConnectVerdict::RateLimited;
    return ConnectVerdict::Accept;
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

AdmissionGate::AdmissionGate(ENetHost* host, const AdmissionLimits& limits, Admitted admitted)
    : m_host(host), m_limits(limits), m_admitted(std::move(admitted)),
      m_buckets(limits.connectsPerS, limits.connectBurst), m_timer(host->peerCount) {}

int AdmissionGate::judge() {
    const std::span<const uint8_t> d(m_host->receivedData, m_host->receivedDataLength);
    if (!isEnetConnect(d))
        return 0;
    const ENetAddress& from = m_host->receivedAddress;
    const uint32_t connectId = connectIdOf(d);
    size_t waiting = 0, fromAddress = 0;
    for (size_t i = 0; i < m_host->peerCount; ++i) {
        const ENetPeer& p = m_host->peers[i];
        if (p.state == ENET_PEER_STATE_DISCONNECTED || m_admitted(&p))
            continue;
        // ENet answers a repeated CONNECT of a handshake under way itself: not a new connection.
        if (p.address.host == from.host && p.address.port == from.port && p.connectID == connectId)
            return 0;
        ++waiting;
        fromAddress += p.address.host == from.host;
    }
    switch (judgeConnect(m_limits, m_buckets, from.host, fromAddress, waiting, m_nowUs)) {
    case ConnectVerdict::Accept:
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
    return 1;
}

void AdmissionGate::reap(uint64_t nowUs, const OnReset& onReset) {
    for (size_t i = 0; i < m_host->peerCount; ++i) {
        ENetPeer* p = &m_host->peers[i];
        if (!m_timer.expired(i, transient(ENetPeerState(p->state)), nowUs,
                             m_limits.handshakeTimeoutUs))
            continue;
        m_timer.forget(i);
        ++m_counts.handshakesReset;
        if (onReset)
            onReset(p);
        enet_peer_reset(p);
    }
}

} // namespace trephine::net

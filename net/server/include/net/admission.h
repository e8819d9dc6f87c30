// Connection admission: peers not yet admitted (no accepted hello) must not hold the session's
// scarce places. ENet spends a peer slot on every CONNECT datagram before the application hears
// of it, so the gate sits in ENet's intercept (it sees raw datagrams first): a token bucket per
// source address for new connections, a cap on connections from one address still waiting to be
// admitted, and, when every waiting slot is taken, a newcomer displaces the oldest waiting peer
// of the address that holds the most, so a few addresses cannot keep everyone else out. A reaper
// frees slots whose ENet handshake (or goodbye) never finishes. The rules are plain functions
// with time passed in; AdmissionGate binds them to one ENet host. docs/session.md
// ("Availability") gives the figures.
#pragma once

#include <enet/enet.h>

#include <array>
#include <cstdint>
#include <functional>
#include <span>
#include <vector>

namespace trephine::net {

// True when `datagram` is an ENet datagram that asks for a new connection (a CONNECT command to
// no peer yet). Anything else (or a datagram too short to tell) is ENet's to judge.
bool isEnetConnect(std::span<const uint8_t> datagram);

// The ENet datagram that refuses the connection `connect` (an isEnetConnect datagram) with
// `data` as its disconnect data: a DISCONNECT command to the connecting peer, which ENet on
// the client reports as a disconnect event. It lets a refused client know the server is there
// without the server keeping any state for it. Empty when `connect` is not a CONNECT.
std::vector<uint8_t> refusalDatagram(std::span<const uint8_t> connect, uint32_t data);

// Return-routability under pressure: a cookie is a keyed hash (SipHash, a random key per server
// run) of a CONNECT's source address and port and the time in 10 s epochs, 24 bits. While the
// waiting slots are filling, a CONNECT must carry its cookie as its connect ID; one without is
// answered statelessly with a Retry refusal carrying the cookie (refusalDatagram), and the client
// connects again with it. A source that cannot receive, a spoofed one, then spends no slot.
class ConnectCookies {
public:
    ConnectCookies();
    uint32_t cookie(const ENetAddress& from, uint64_t nowUs) const;
    // The cookie of this epoch or the last (a client's retries keep working across a boundary).
    bool valid(uint32_t connectId, const ENetAddress& from, uint64_t nowUs) const;
    static constexpr uint64_t kEpochUs = 10'000'000;

private:
    uint32_t at(const ENetAddress& from, uint64_t epoch) const;
    std::array<uint8_t, 16> m_key{};
};

// New connections per source address: a bucket of `burst` tokens refilled at `perS` a second.
// Addresses hash into a fixed table, so spoofed sources cannot grow it: two addresses that share
// a bucket share its tokens (a stricter limit for both, never a looser one).
class ConnectBuckets {
public:
    ConnectBuckets(double perS, double burst, uint64_t salt = 0x9e3779b97f4a7c15ull);
    // Takes a token for a connection from `address` at `nowUs`; false when none is left.
    bool take(uint32_t address, uint64_t nowUs);
    // Whether `address` has a token at `nowUs`, taking none.
    bool has(uint32_t address, uint64_t nowUs);

private:
    struct Bucket {
        uint32_t address = 0;
        double tokens = 0;
        uint64_t lastUs = 0;
        bool used = false;
    };
    Bucket& slot(uint32_t address);
    static constexpr size_t kBuckets = 4096;
    double m_perS, m_burst;
    uint64_t m_salt;
    std::array<Bucket, kBuckets> m_table{};
};

// What the gate answers to a CONNECT datagram.
enum class ConnectVerdict {
    Accept,
    Displace,    // accepted in place of another address's oldest waiting peer
    RateLimited, // the address opened connections faster than its bucket allows
    AddressBusy, // the address already has as many connections waiting as one may
    PoolFull,    // every slot for waiting connections is taken by addresses holding no more
};

struct AdmissionLimits {
    size_t waitingSlots = 256;     // ENet slots beyond maxClients for connections not admitted
    size_t waitingPerAddress = 16; // of which one source address may hold at once
    double connectsPerS = 8.0;     // new connections a second per address, after...
    double connectBurst = 24.0;    // ...a burst of this many
    uint64_t handshakeTimeoutUs = 3000000; // ENet handshake or goodbye unfinished: slot reset
    // Cookies are asked for once this many connections wait (0: always; ConnectCookies).
    size_t cookiesFrom = 64;
};

// A connection not yet admitted: its source address, since when it has held its slot, and
// whether it is under way (it has made its code offer) rather than silent or half-open.
struct WaitingPeer {
    uint32_t address = 0;
    uint64_t sinceUs = 0;
    bool progressing = false;
};

struct ConnectDecision {
    ConnectVerdict verdict = ConnectVerdict::Accept;
    size_t displace = 0; // with Displace: the index in `waiting` of the peer to reset
};

// The decision for one CONNECT from `address`, given every peer still waiting. With the pool
// full, the slots are shared max-min fairly: a newcomer whose address holds at least two fewer
// waiting peers than the address holding the most takes one of that address's slots: a silent
// one before one under way, the oldest first. A lone joiner, whose address holds one, is so
// never displaced while any address holds fewer than three.
ConnectDecision judgeConnect(const AdmissionLimits& limits, ConnectBuckets& buckets,
                             uint32_t address, std::span<const WaitingPeer> waiting,
                             uint64_t nowUs);

// How long each slot has been in a state it must leave soon (an ENet handshake or goodbye): a
// slot that stays longer than the timeout is due to be reset.
class SlotTimer {
public:
    explicit SlotTimer(size_t slots) : m_since(slots, 0) {}
    // Slot `index` is (`transient`) or is not in such a state at `nowUs`: true when it has been
    // for longer than `timeoutUs`.
    bool expired(size_t index, bool transient, uint64_t nowUs, uint64_t timeoutUs);
    void forget(size_t index) { m_since.at(index) = 0; }

private:
    std::vector<uint64_t> m_since; // 0: not in a transient state
};

// Figures of refused and reclaimed connections (read into the server's report).
struct AdmissionCounts {
    uint64_t rateLimited = 0, addressBusy = 0, poolFull = 0, handshakesReset = 0, displaced = 0;
    uint64_t cookieless = 0; // CONNECTs without a valid cookie while cookies were asked for
    bool operator==(const AdmissionCounts&) const = default;
};

// The gate on one ENet host (network thread only). `admitted` says whether an ENet peer has been
// admitted into the session (its slot is then the session's, not the gate's).
class AdmissionGate {
public:
    // Where a peer's connection stands in the session: admitted (its slot is the session's), or
    // waiting, under way (Progressing) or not.
    enum class Standing { Waiting, Progressing, Admitted };
    using Admitted = std::function<Standing(const ENetPeer*)>;
    // Called before a slot is reset with the peer it held (the server forgets it: ENet reports no
    // disconnect for a reset peer).
    using OnReset = std::function<void(ENetPeer*)>;

    // `onReset` is also called for a peer displaced by a newcomer, from within ENet's service.
    AdmissionGate(ENetHost* host, const AdmissionLimits& limits, Admitted admitted,
                  OnReset onReset = {});
    AdmissionGate(const AdmissionGate&) = delete;
    AdmissionGate& operator=(const AdmissionGate&) = delete;

    // The datagram the host received last (ENet's receivedData and receivedAddress), judged from
    // ENet's intercept, which the server owns: 1 drops it, 0 lets ENet handle it.
    int judge();

    // Sets the time the intercept judges by (the network thread's `now` of this pass).
    void setNow(uint64_t nowUs) { m_nowUs = nowUs; }
    int askForCookie(); // drops the CONNECT just received, answering with its cookie
    // Answers the CONNECT just received with a refusal carrying `data`, if `budget` allows.
    void answer(ConnectBuckets& budget, uint32_t data);
    // Resets every slot whose handshake or goodbye has outlasted the limit.
    void reap(uint64_t nowUs);
    const AdmissionCounts& counts() const { return m_counts; }

private:
    void reset(ENetPeer* peer, bool tell);
    // When each slot's present occupant (told apart by its connect ID) was first seen.
    uint64_t occupiedSince(size_t index);

    ENetHost* m_host;
    AdmissionLimits m_limits;
    Admitted m_admitted;
    OnReset m_onReset;
    ConnectBuckets m_buckets;
    ConnectBuckets m_refusals;      // refusals answered per address: no flood is reflected 1:1
    ConnectBuckets m_cookieReplies; // cookies sent per address (a class behind a NAT needs many)
    ConnectCookies m_cookies;
    SlotTimer m_timer;
    std::vector<std::pair<uint32_t, uint64_t>> m_occupant; // per slot: connect ID, since
    std::vector<WaitingPeer> m_waiting;                    // judge()'s scratch
    std::vector<ENetPeer*> m_waitingPeers;
    size_t m_lastWaiting = 0; // connections waiting, as last counted
    AdmissionCounts m_counts;
    uint64_t m_nowUs = 0;
};

} // namespace trephine::net

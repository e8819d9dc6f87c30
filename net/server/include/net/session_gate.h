// The server's gate (docs/security.md): what stands between a connection and the session
// policy. It runs the role-code handshake (SPAKE2, net/secure_channel.h), limits wrong codes per
// address, keeps the instructors' removals, and after the handshake opens every message a peer
// sends and seals every one it is sent. In an open session (no codes) it passes messages as they
// are. No ENet, no clock: the network thread feeds it with the time, and tests do the same.
#pragma once

#include "net/enet_host.h"
#include "net/protocol.h"
#include "net/secure_channel.h"
#include "net/server_config.h"
#include "net/server_report.h"

#include <cstdint>
#include <map>
#include <optional>
#include <set>
#include <span>
#include <string>
#include <utility>
#include <vector>

namespace trephine::net {

// Attempts from one address: a burst of kBurst answered at once, then one more every kRefillS
// seconds; a code proven gives its attempt back. Past them an offer waits, never refused: the
// address's waiting offers are answered in arrival order, one every kExcessS, and each code
// proven lets the next one through at once. So participants behind one address (a classroom's
// NAT) join while a guesser there waits its turn. Every answer is one guess tested, so in t
// seconds an address tests at most kBurst + t / kRefillS + t / kExcessS guesses (3,730 in the
// first hour), plus one per code proven there; the slow lanes of all addresses together answer
// at most kExcessInAllPerS a second, so A addresses test at most A (kBurst + t / kRefillS) +
// kExcessInAllPerS t (docs/security.md).
struct AttemptLimit {
    static constexpr double kBurst = 10.0;
    static constexpr double kRefillS = 30.0;
    static constexpr double kExcessS = 1.0;
    static constexpr double kExcessInAllPerS = 8.0;
};

class SessionGate {
public:
    // Hashes the config's codes (throws trephine::Error on a malformed one, on only one of the
    // two, or on both the same).
    SessionGate(const ServerConfig& config, ReportBook& book);

    bool open() const { return !m_codes; }

    // A new connection `id` from `address`: the Challenge to send it.
    std::vector<uint8_t> connect(uint16_t id, const ENetAddress& address);

    struct Result {
        enum class Kind {
            Deliver, // a message for the session policy: `message`
            Reply,   // a handshake step to send back: `message`
            Proven,  // the handshake ended: the peer holds `role` from now on
            Refuse,  // send the peer away with `refuse` (the disconnect data)
            Held,    // an offer waits for its turn: release() answers it
            Bad,     // malformed, forged or replayed: dropped, counted as malformed
        } kind = Kind::Bad;
        std::span<const uint8_t> message;
        uint32_t refuse = 0;
        Role role = Role::Trainee;
    };
    // A message from `id` on `channel`; the result's message lives until the next call.
    Result receive(uint16_t id, Channel channel, std::span<const uint8_t> data, uint64_t now);

    // What `id` is sent on `channel`: sealed once it proved a code, else as it is.
    bool sealing(uint16_t id) const;
    std::vector<uint8_t> seal(uint16_t id, Channel channel, std::span<const uint8_t> plain);

    // The peer is gone; a handshake it left after an answer counted as a wrong code.
    void leave(uint16_t id);
    // An instructor removed `id`: its address may not join with its role's code until
    // allowRejoin().
    void remove(uint16_t id);
    void allowRejoin();
    // [Codes] A new code for `role` (generateCode), hashed with the session's salt: the old one
    // proves nothing from now on, handshakes under way with it included, and the removals from
    // that role's code are lifted. Peers already in stay. Returns the code as printed.
    // Defined in session_codes.cpp, with install().
    std::string issue(Role role);
    // [Codes] As issue(), with a code hashed elsewhere (CodeMint): false, and nothing changed,
    // for the other role's code or an open session.
    bool install(Role role, const Bytes32& w);
    // The salt codes are hashed with (none in an open session).
    std::optional<Salt> salt() const;
    size_t removedCount() const { return m_removed.size(); }
    // The answers due at `now` to offers that waited (AttemptLimit), for the peers named.
    std::vector<std::pair<uint16_t, std::vector<uint8_t>>> release(uint64_t now);
    // The peers whose offers wait for their turn now.
    std::vector<uint16_t> held() const;
    // `id` has made an offer (waiting, answered or proven): a joiner under way, not a silent
    // connection (the admission gate displaces silent ones first).
    bool progressing(uint16_t id) const;

private:
    struct Codes {
        Salt salt;
        Bytes32 trainee, instructor;
    };
    struct Peer {
        uint32_t host = 0;
        enum class Stage { Connected, Waiting, Answered, Secure, Refused } stage = Stage::Connected;
        Role wanted = Role::Trainee; // Offer's role; in an open session, the hello's
        Bytes32 share{};             // a waiting Offer's
        uint64_t turn = 0;           // a waiting Offer's place in the queue
        std::vector<std::pair<Role, SessionKeys>> answers;
        std::optional<SecureChannel> channel;
    };
    struct Bucket {
        double tokens = AttemptLimit::kBurst;
        uint64_t atUs = 0;
        uint64_t nextExcessUs = 0; // when the slow lane answers its next waiting offer
    };

    Result refuse(Peer& p, RefuseReason why, uint32_t detail, uint64_t SecurityCounters::*counter);
    Result handshake(Peer& p, std::span<const uint8_t> data, uint64_t now);
    // No earlier offer from `p`'s address waits (offers are answered in arrival order).
    bool firstInLine(const Peer& p) const;
    // Whether `p`'s address may have an offer answered at `now` (a token, or the slow lane's
    // turn); spends what answering it costs.
    bool mayAnswer(const Peer& p, uint64_t now);
    bool answer(Peer& p); // answers the waiting offer into m_reply; false: not a group point
    Result openSealed(Peer& p, Channel channel, std::span<const uint8_t> data);
    Bucket& bucket(uint32_t host, uint64_t now);
    void count(uint64_t SecurityCounters::*counter);

    ReportBook& m_book;
    std::optional<Codes> m_codes;
    std::map<uint16_t, Peer> m_peers;
    std::map<uint32_t, Bucket> m_buckets;          // by IPv4 address
    std::set<std::pair<uint32_t, Role>> m_removed; // address and role code of removed peers
    std::vector<uint8_t> m_plain;                  // the last message opened
    std::vector<uint8_t> m_reply;
    uint64_t m_nextTurn = 1;
    // The slow lanes' shared budget (AttemptLimit::kExcessInAllPerS).
    double m_excessTokens = AttemptLimit::kExcessInAllPerS;
    uint64_t m_excessAtUs = 0;
};

} // namespace trephine::net

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

// Wrong codes from one address: a burst of kBurst, then one more every kRefillS seconds, so at
// most kBurst + 3600 / kRefillS (130) guesses in the first hour and 120 an hour after it.
struct AttemptLimit {
    static constexpr double kBurst = 10.0;
    static constexpr double kRefillS = 30.0;
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
    // Defined in session_codes.cpp.
    std::string issue(Role role);
    size_t removedCount() const { return m_removed.size(); }
    // Seconds until `address` may try a code again (0: now).
    uint32_t waitS(const ENetAddress& address, uint64_t now);

private:
    struct Codes {
        Salt salt;
        Bytes32 trainee, instructor;
    };
    struct Peer {
        uint32_t host = 0;
        enum class Stage { Connected, Answered, Secure, Refused } stage = Stage::Connected;
        Role wanted = Role::Trainee; // Offer's role; in an open session, the hello's
        std::vector<std::pair<Role, SessionKeys>> answers;
        std::optional<SecureChannel> channel;
    };
    struct Bucket {
        double tokens = AttemptLimit::kBurst;
        uint64_t atUs = 0;
    };

    Result refuse(Peer& p, RefuseReason why, uint32_t detail, uint64_t SecurityCounters::*counter);
    Result handshake(Peer& p, std::span<const uint8_t> data, uint64_t now);
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
};

} // namespace trephine::net

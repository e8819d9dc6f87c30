// What the server's gate (net/session_gate.h) counts: handshakes, refusals, sealed messages
// dropped. Kept in the server's report (ServerReport::security) and written as its "security".
#pragma once

#include <nlohmann/json.hpp>

#include <cstdint>

namespace trephine::net {

struct SecurityCounters {
    uint64_t handshakes = 0;      // codes proven
    uint64_t codesRefused = 0;    // wrong code, no code, the trainee code in instructor mode
    uint64_t attemptsLimited = 0; // refused: too many wrong codes from the address
    uint64_t removedRefused = 0;  // a removed participant trying to join again
    uint64_t removed = 0;         // participants an instructor removed
    uint64_t removalsRefused = 0; // Remove messages not applied (from trainees, of nobody)
    uint64_t forged = 0;          // sealed messages that failed to authenticate
    uint64_t replayed = 0;        // sealed messages whose counter was seen or too old
    uint64_t spoofed = 0;         // datagrams naming a peer from another address (ENet drops them)
    uint64_t unauthenticated = 0; // messages before the handshake ended (dropped)
    uint64_t codesIssued = 0;     // new codes an instructor issued while the server ran
    uint64_t newCodesRefused = 0; // requests for one from trainees, or in an open session

    bool operator==(const SecurityCounters&) const = default;
};

nlohmann::ordered_json securityJson(const SecurityCounters& c);

} // namespace trephine::net

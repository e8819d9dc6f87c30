// The session's cryptography, all of it libsodium's (docs/security.md): role codes people can read
// out, the SPAKE2 handshake over ristretto255 that proves a code without revealing it, and the
// sealed channel (ChaCha20-Poly1305 with per-channel counters and a replay window) that every
// message travels in after it. No ENet and no clock: the server's gate and the client use it.
#pragma once

#include "net/enet_host.h"
#include "net/protocol.h"

#include <array>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace trephine::net {

using Bytes32 = std::array<uint8_t, 32>;
using Salt = std::array<uint8_t, 16>;

// Initialises libsodium once (throws trephine::Error when it cannot).
void initSodium();

// [SECTION] codes

// A fresh code of 8 symbols from Crockford's base32 (no I, L, O, U), 40 random bits, shown as
// "ABCD-EFGH" so it can be read out over the phone.
std::string generateCode();
// The code as both ends hash it: upper case, without dashes and spaces, O read as 0 and I, L as
// 1. Throws trephine::Error (one line naming `what`) unless 6 to 64 letters and digits remain.
std::string normaliseCode(std::string_view code, std::string_view what = "the code");

// [SECTION] the handshake (SPAKE2, RFC 9382's shape, on ristretto255)

// argon2id limits of the code's hash: the code is never exposed to an offline guess on the wire
// (SPAKE2), so this only slows one who has read the server's memory; kept low so a join stays
// fast (the measured handshake time is in docs/security.md).
inline constexpr unsigned long long kCodeHashOps = 2;
inline constexpr size_t kCodeHashMemBytes = size_t(8) << 20;

// The code's scalar w, from argon2id of the normalised code with the server's salt.
Bytes32 codeScalar(std::string_view normalisedCode, const Salt& salt);

// Keys both ends derive from one successful handshake.
struct SessionKeys {
    Bytes32 clientToServer{}, serverToClient{};
    Bytes32 clientConfirm{}, serverConfirm{}; // the two confirmation MACs
};

// The client's half: X* = x G + w M, then the keys for a server share Y* = y G + w N. `role`
// is the role the client asks for; both roles enter the transcript.
class SpakeClient {
public:
    SpakeClient(const Bytes32& w, const Salt& salt, Role role);
    // With the ephemeral scalar x given, not drawn: for docs/security.md's test vector only.
    SpakeClient(const Bytes32& w, const Salt& salt, Role role, const Bytes32& x);
    const Bytes32& share() const { return m_share; }
    // The keys for the server's share made with the code of `entryRole`, or none when the share
    // is not a valid point.
    std::optional<SessionKeys> keys(const Bytes32& serverShare, Role entryRole) const;

private:
    Bytes32 m_w, m_x, m_share;
    Salt m_salt;
    Role m_role;
};

// The server's half for the code of `entryRole` (scalar w): Y* = y G + w N with a fresh y, and
// the keys for the client's share X*. None when X* is not a valid point or leads to the identity.
struct SpakeServerAnswer {
    Bytes32 share;
    SessionKeys keys;
};
std::optional<SpakeServerAnswer> spakeAnswer(const Bytes32& w, const Salt& salt, Role wanted,
                                             Role entryRole, const Bytes32& clientShare);
// With the ephemeral scalar y given, not drawn: for docs/security.md's test vector only.
std::optional<SpakeServerAnswer> spakeAnswer(const Bytes32& w, const Salt& salt, Role wanted,
                                             Role entryRole, const Bytes32& clientShare,
                                             const Bytes32& y);

// Constant-time comparison of two MACs.
bool sameMac(const Bytes32& a, const Bytes32& b);

// [SECTION] the sealed channel

// A sliding window of the newest 64 counters seen on one channel: a counter older than the
// window, or one already seen, is a replay. Unsequenced channels reorder, reliable ones do not;
// one rule serves both.
class ReplayWindow {
public:
    bool fresh(uint64_t counter) const;
    void accept(uint64_t counter);

private:
    uint64_t m_highest = 0;
    uint64_t m_seen = 0; // bit i: m_highest - i was seen
    bool m_any = false;
};

class SecureChannel {
public:
    // The counter (8 bytes) before the ciphertext, the tag (16) after it.
    static constexpr size_t kOverhead = 24;
    enum class Opened { Ok, Forged, Replayed };

    SecureChannel(const SessionKeys& keys, bool server);
    // The message sealed for `channel`: its counter, then ciphertext and tag.
    std::vector<uint8_t> seal(Channel channel, std::span<const uint8_t> plain);
    // Opens a sealed message received on `channel` into `plain`: Forged when it fails to
    // authenticate (tampered, forged, moved to another channel), Replayed for a counter seen.
    Opened open(Channel channel, std::span<const uint8_t> sealed, std::vector<uint8_t>& plain);

private:
    Bytes32 m_sendKey, m_receiveKey;
    std::array<uint64_t, size_t(Channel::Count)> m_sent{};
    std::array<ReplayWindow, size_t(Channel::Count)> m_received{};
};

} // namespace trephine::net

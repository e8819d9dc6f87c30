#include "net/secure_channel.h"

#include "libsim/error.h"

#include <sodium.h>

#include <cctype>
#include <cstring>
#include <mutex>

namespace trephine::net {

void initSodium() {
    static std::once_flag once;
    static bool ok = false;
    std::call_once(once, [] { ok = sodium_init() >= 0; });
    if (!ok)
        throw Error("could not initialise libsodium");
}

// [SECTION] codes

namespace {
constexpr char kCrockford[] = "0123456789ABCDEFGHJKMNPQRSTVWXYZ";
} // namespace

std::string generateCode() {
    initSodium();
    uint8_t random[5];
    randombytes_buf(random, sizeof random);
    uint64_t bits = 0;
    for (uint8_t b : random)
        bits = bits << 8 | b;
    std::string code;
    for (int i = 7; i >= 0; --i) {
        code += kCrockford[(bits >> (5 * i)) & 31];
        if (i == 4)
            code += '-';
    }
    return code;
}

std::string normaliseCode(std::string_view code, std::string_view what) {
    std::string out;
    for (char c : code) {
        if (c == '-' || c == ' ')
            continue;
        c = char(std::toupper(static_cast<unsigned char>(c)));
        if (c == 'O')
            c = '0';
        else if (c == 'I' || c == 'L')
            c = '1';
        if (!((c >= '0' && c <= '9') || (c >= 'A' && c <= 'Z')))
            throw Error(std::string(what) + ": use letters and digits only (dashes and spaces are "
                                            "ignored)");
        out += c;
    }
    if (out.size() < 6 || out.size() > 64)
        throw Error(std::string(what) + " must be 6 to 64 letters and digits, not " +
                    std::to_string(out.size()));
    return out;
}

// [SECTION] the handshake

namespace {

// The blinding points M (client) and N (server): hashed to the group, so nobody knows their
// discrete logarithms.
struct Blinding {
    Bytes32 m, n;
    Blinding() {
        initSodium();
        auto point = [](const char* label, Bytes32& out) {
            uint8_t h[crypto_hash_sha512_BYTES];
            crypto_hash_sha512(h, reinterpret_cast<const uint8_t*>(label), std::strlen(label));
            crypto_core_ristretto255_from_hash(out.data(), h);
        };
        point("trephine SPAKE2 ristretto255 M", m);
        point("trephine SPAKE2 ristretto255 N", n);
    }
};
const Blinding& blinding() {
    static const Blinding b;
    return b;
}

// The transcript hash over everything both ends saw (RFC 9382: shares, K and w; here also the
// salt and both roles), split into the session keys and the confirmation MACs.
SessionKeys deriveKeys(const Salt& salt, Role wanted, Role entry, const Bytes32& x,
                       const Bytes32& y, const Bytes32& k, const Bytes32& w) {
    uint8_t tt[crypto_generichash_BYTES_MAX];
    crypto_generichash_state st;
    crypto_generichash_init(&st, nullptr, 0, sizeof tt);
    static constexpr char kLabel[] = "trephine SPAKE2 v9";
    crypto_generichash_update(&st, reinterpret_cast<const uint8_t*>(kLabel), sizeof kLabel - 1);
    const uint8_t roles[2] = {uint8_t(wanted), uint8_t(entry)};
    crypto_generichash_update(&st, salt.data(), salt.size());
    crypto_generichash_update(&st, roles, sizeof roles);
    for (const Bytes32* part : {&x, &y, &k, &w})
        crypto_generichash_update(&st, part->data(), part->size());
    crypto_generichash_final(&st, tt, sizeof tt);

    SessionKeys keys;
    Bytes32 confirmClient, confirmServer;
    crypto_kdf_derive_from_key(keys.clientToServer.data(), 32, 1, "trphsess", tt);
    crypto_kdf_derive_from_key(keys.serverToClient.data(), 32, 2, "trphsess", tt);
    crypto_kdf_derive_from_key(confirmClient.data(), 32, 1, "trphconf", tt + 32);
    crypto_kdf_derive_from_key(confirmServer.data(), 32, 2, "trphconf", tt + 32);
    crypto_auth(keys.clientConfirm.data(), tt, sizeof tt, confirmClient.data());
    crypto_auth(keys.serverConfirm.data(), tt, sizeof tt, confirmServer.data());
    sodium_memzero(tt, sizeof tt);
    return keys;
}

// K = s (share - w B): the other side's ephemeral point, unblinded, times our scalar.
bool unblind(const Bytes32& share, const Bytes32& w, const Bytes32& blindPoint, const Bytes32& s,
             Bytes32& k) {
    Bytes32 wb, t;
    // The identity (all zeros) is a valid encoding, but no share a peer with a fresh scalar sends.
    if (sodium_is_zero(share.data(), share.size()) ||
        !crypto_core_ristretto255_is_valid_point(share.data()) ||
        crypto_scalarmult_ristretto255(wb.data(), w.data(), blindPoint.data()) != 0 ||
        crypto_core_ristretto255_sub(t.data(), share.data(), wb.data()) != 0)
        return false;
    return crypto_scalarmult_ristretto255(k.data(), s.data(), t.data()) == 0;
}

// The share s G + w B of an ephemeral scalar s; false when s is zero.
bool shareOf(const Bytes32& w, const Bytes32& blindPoint, const Bytes32& s, Bytes32& share) {
    Bytes32 sg, wb;
    if (crypto_scalarmult_ristretto255_base(sg.data(), s.data()) != 0)
        return false;
    if (crypto_scalarmult_ristretto255(wb.data(), w.data(), blindPoint.data()) != 0 ||
        crypto_core_ristretto255_add(share.data(), sg.data(), wb.data()) != 0)
        throw Error("the code's scalar is zero"); // a 2^-252 chance
    return true;
}

// A fresh ephemeral scalar and its share s G + w B.
void blindedShare(const Bytes32& w, const Bytes32& blindPoint, Bytes32& s, Bytes32& share) {
    do {
        crypto_core_ristretto255_scalar_random(s.data());
    } while (!shareOf(w, blindPoint, s, share));
}

std::optional<SpakeServerAnswer> answerWith(const Bytes32& w, const Salt& salt, Role wanted,
                                            Role entryRole, const Bytes32& clientShare,
                                            const Bytes32* givenY) {
    SpakeServerAnswer a;
    Bytes32 y, k;
    if (sodium_is_zero(clientShare.data(), clientShare.size()) ||
        !crypto_core_ristretto255_is_valid_point(clientShare.data()))
        return std::nullopt;
    if (givenY) {
        y = *givenY;
        if (!shareOf(w, blinding().n, y, a.share))
            return std::nullopt;
    } else {
        blindedShare(w, blinding().n, y, a.share);
    }
    if (!unblind(clientShare, w, blinding().m, y, k))
        return std::nullopt;
    a.keys = deriveKeys(salt, wanted, entryRole, clientShare, a.share, k, w);
    return a;
}

} // namespace

Bytes32 codeScalar(std::string_view normalisedCode, const Salt& salt) {
    initSodium();
    uint8_t wide[64];
    if (crypto_pwhash(wide, sizeof wide, normalisedCode.data(), normalisedCode.size(), salt.data(),
                      kCodeHashOps, kCodeHashMemBytes, crypto_pwhash_ALG_ARGON2ID13) != 0)
        throw Error("cannot hash the session code (out of memory?)");
    Bytes32 w;
    crypto_core_ristretto255_scalar_reduce(w.data(), wide);
    sodium_memzero(wide, sizeof wide);
    return w;
}

SpakeClient::SpakeClient(const Bytes32& w, const Salt& salt, Role role)
    : m_w(w), m_salt(salt), m_role(role) {
    blindedShare(m_w, blinding().m, m_x, m_share);
}

SpakeClient::SpakeClient(const Bytes32& w, const Salt& salt, Role role, const Bytes32& x)
    : m_w(w), m_x(x), m_salt(salt), m_role(role) {
    if (!shareOf(m_w, blinding().m, m_x, m_share))
        throw Error("SpakeClient: the given scalar x is zero");
}

std::optional<SessionKeys> SpakeClient::keys(const Bytes32& serverShare, Role entryRole) const {
    Bytes32 k;
    if (!unblind(serverShare, m_w, blinding().n, m_x, k))
        return std::nullopt;
    return deriveKeys(m_salt, m_role, entryRole, m_share, serverShare, k, m_w);
}

std::optional<SpakeServerAnswer> spakeAnswer(const Bytes32& w, const Salt& salt, Role wanted,
                                             Role entryRole, const Bytes32& clientShare) {
    return answerWith(w, salt, wanted, entryRole, clientShare, nullptr);
}

std::optional<SpakeServerAnswer> spakeAnswer(const Bytes32& w, const Salt& salt, Role wanted,
                                             Role entryRole, const Bytes32& clientShare,
                                             const Bytes32& y) {
    return answerWith(w, salt, wanted, entryRole, clientShare, &y);
}

bool sameMac(const Bytes32& a, const Bytes32& b) {
    return sodium_memcmp(a.data(), b.data(), a.size()) == 0;
}

// [SECTION] the sealed channel

bool ReplayWindow::fresh(uint64_t counter) const {
    if (!m_any || counter > m_highest)
        return true;
    const uint64_t age = m_highest - counter;
    return age < 64 && !((m_seen >> age) & 1u);
}

void ReplayWindow::accept(uint64_t counter) {
    if (!m_any || counter > m_highest) {
        const uint64_t shift = m_any ? counter - m_highest : 64;
        m_seen = (shift >= 64 ? 0 : m_seen << shift) | 1u;
        m_highest = counter;
        m_any = true;
    } else {
        m_seen |= uint64_t(1) << (m_highest - counter);
    }
}

namespace {
// The channel and the counter: a sealed message moved to another channel fails to open.
void nonceOf(Channel channel, uint64_t counter,
             uint8_t (&nonce)[crypto_aead_chacha20poly1305_IETF_NPUBBYTES]) {
    std::memset(nonce, 0, sizeof nonce);
    nonce[0] = uint8_t(channel);
    for (int i = 0; i < 8; ++i)
        nonce[4 + i] = uint8_t(counter >> (8 * i));
}
} // namespace

SecureChannel::SecureChannel(const SessionKeys& keys, bool server)
    : m_sendKey(server ? keys.serverToClient : keys.clientToServer),
      m_receiveKey(server ? keys.clientToServer : keys.serverToClient) {
    static_assert(kOverhead == 8 + crypto_aead_chacha20poly1305_IETF_ABYTES);
}

std::vector<uint8_t> SecureChannel::seal(Channel channel, std::span<const uint8_t> plain) {
    const uint64_t counter = ++m_sent[size_t(channel)];
    std::vector<uint8_t> out(plain.size() + kOverhead);
    for (int i = 0; i < 8; ++i)
        out[size_t(i)] = uint8_t(counter >> (8 * i));
    uint8_t nonce[crypto_aead_chacha20poly1305_IETF_NPUBBYTES];
    nonceOf(channel, counter, nonce);
    unsigned long long written = 0;
    crypto_aead_chacha20poly1305_ietf_encrypt(out.data() + 8, &written, plain.data(), plain.size(),
                                              nullptr, 0, nullptr, nonce, m_sendKey.data());
    return out;
}

SecureChannel::Opened SecureChannel::open(Channel channel, std::span<const uint8_t> sealed,
                                          std::vector<uint8_t>& plain) {
    if (sealed.size() < kOverhead || size_t(channel) >= m_received.size())
        return Opened::Forged;
    uint64_t counter = 0;
    for (int i = 0; i < 8; ++i)
        counter |= uint64_t(sealed[size_t(i)]) << (8 * i);
    ReplayWindow& window = m_received[size_t(channel)];
    if (!window.fresh(counter))
        return Opened::Replayed;
    uint8_t nonce[crypto_aead_chacha20poly1305_IETF_NPUBBYTES];
    nonceOf(channel, counter, nonce);
    plain.resize(sealed.size() - kOverhead);
    unsigned long long length = 0;
    if (crypto_aead_chacha20poly1305_ietf_decrypt(plain.data(), &length, nullptr, sealed.data() + 8,
                                                  sealed.size() - 8, nullptr, 0, nonce,
                                                  m_receiveKey.data()) != 0) {
        plain.clear();
        return Opened::Forged;
    }
    window.accept(counter); // only once authentic: a forgery cannot move the window
    return Opened::Ok;
}

} // namespace trephine::net

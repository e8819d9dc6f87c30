// docs/security.md's test vector ("The handshake, byte by byte"): each step is computed twice,
// by the code and from the document's recipe with bare libsodium calls, and both must give the
// frozen bytes, which must also appear in the document. A change to the code, the recipe or the
// document's table fails here. Also docs/protocol.md's placeholder view of the hello.
#include "net/protocol.h"
#include "net/secure_channel.h"

#include <gtest/gtest.h>
#include <sodium.h>

#include <algorithm>
#include <array>
#include <cstring>
#include <fstream>
#include <span>
#include <sstream>
#include <string>
#include <vector>

using namespace trephine::net;

namespace {

// [SECTION] the vector, as docs/security.md gives it

constexpr char kCodeAsTyped[] = "bur7-h0le";
constexpr char kCodeNormalised[] = "BUR7H01E";
constexpr char kSalt[] = "000102030405060708090a0b0c0d0e0f";
constexpr char kX[] = "e6652eba60c26dec7632d7aefcfdfdd11bc46aa0622cd3637db6d5fe0a47640a";
constexpr char kY[] = "7796fbebad3873e4023f0de9842fa14f983e09f478d75db4eba8d9b9dae55c0a";
constexpr uint64_t kPingTimeUs = 0x0102030405060708;

constexpr char kW[] = "e8d9437445d2c94e2eef02053a7af86833506c63aa492ea044935c0974f1070e";
constexpr char kM[] = "7ae1319660d92d643252ba9d66e893d9b15f2495d0142758760a9d1ae6838127";
constexpr char kN[] = "e8dc72c27ddcc1c28dd8b3a869194c07ed85b8d7093eaf6960fbd745c33f2422";
constexpr char kShareX[] = "84eddd23e00696df2c43200cbf841239f8674b09758529c341de48a64f82b439";
constexpr char kShareY[] = "b4987f5c816c530588b0ba9d4422d4d8b9f5f1333825dcf5548fd4200337c361";
constexpr char kK[] = "aee094cd11fb23b68b883f7da65018f97541b9ee4421830b05ad7aecbe76a971";
constexpr char kTranscript[] = "c4e03c969179017fd794ba2d1cdb7d5696289906bc8060d87ec0b5f06f077cfde4b"
                               "fd6b58f18b520be6cc2a206ce538a1fad5fe5ea6a049b108bfc568e333ba2";
constexpr char kClientToServer[] =
    "71a75a751509700b778ba2b4ede0f368f38025546638612cd6b438634452e530";
constexpr char kServerToClient[] =
    "568c1d9bdeda3c441f39bc7f5b76b29c5d61c97334af3be4c38edbac365a1f77";
constexpr char kConfirmKeyClient[] =
    "bc9dc84d67945aba53752d693cefa055b9525b9d2473e43ba293fceb671e971d";
constexpr char kConfirmKeyServer[] =
    "fce053e014a33c594d31a5a710e1f14d7130be8597158ad6cc326a2894c18c4c";
constexpr char kClientMac[] = "d86fdf50a99580942a12d1f3d3dd7a9c2cba07f9f41461bf76676f81ca918317";
constexpr char kServerMac[] = "ed54f3513c922c6542e21a89ce9521b2935f60735152fd6c02be0b96372d9fc3";
// The server's MAC with asked 1 and entry 0: the role bytes' order.
constexpr char kServerMacInstructorAsked[] =
    "193ffbab8e183fc51979dabbc755a41e95eeb9c86288e50b35fce27fe1fc18e2";
constexpr char kSealedPing[] = "01000000000000005e1885ac56bfe5f9e6e3a3119e356bb38a38659787652ed4ba";

// docs/protocol.md: the hello's view before the scene (ViewSpec's defaults at 1 x 1 pixels).
constexpr char kPlaceholderView[] = "00000000000000000000964300000000000000000000000000000000000080"
                                    "3f00000000000070420000204100007a4401000100";

// [SECTION] helpers

std::vector<uint8_t> unhex(std::string_view hex) {
    std::vector<uint8_t> out(hex.size() / 2);
    size_t n = 0;
    EXPECT_EQ(sodium_hex2bin(out.data(), out.size(), hex.data(), hex.size(), nullptr, &n, nullptr),
              0);
    EXPECT_EQ(n, out.size());
    return out;
}

template <size_t N>
std::array<uint8_t, N> unhexArray(std::string_view hex) {
    std::array<uint8_t, N> a{};
    const std::vector<uint8_t> v = unhex(hex);
    EXPECT_EQ(v.size(), N);
    std::memcpy(a.data(), v.data(), std::min(N, v.size()));
    return a;
}

std::string hex(std::span<const uint8_t> bytes) {
    std::string s(bytes.size() * 2 + 1, '\0');
    sodium_bin2hex(s.data(), s.size(), bytes.data(), bytes.size());
    s.pop_back();
    return s;
}

std::span<const uint8_t> bytesOf(const char* text) {
    return {reinterpret_cast<const uint8_t*>(text), std::strlen(text)};
}

// The document's recipe, step by step, in bare libsodium: what a client written from it does.
struct FromTheDocument {
    Bytes32 w, m, n, shareX, shareY, kClient, kServer;
    std::array<uint8_t, 64> transcript;
    Bytes32 clientToServer, serverToClient, confirmKeyClient, confirmKeyServer;
    Bytes32 clientMac, serverMac;

    static Bytes32 hashToGroup(const char* label) {
        uint8_t h[64];
        crypto_hash_sha512(h, reinterpret_cast<const uint8_t*>(label), std::strlen(label));
        Bytes32 p;
        crypto_core_ristretto255_from_hash(p.data(), h);
        return p;
    }
    static Bytes32 mul(const Bytes32& s, const Bytes32& p) {
        Bytes32 q;
        EXPECT_EQ(crypto_scalarmult_ristretto255(q.data(), s.data(), p.data()), 0);
        return q;
    }
    static Bytes32 blinded(const Bytes32& s, const Bytes32& w, const Bytes32& b) {
        Bytes32 sg, out;
        EXPECT_EQ(crypto_scalarmult_ristretto255_base(sg.data(), s.data()), 0);
        crypto_core_ristretto255_add(out.data(), sg.data(), mul(w, b).data());
        return out;
    }
    static Bytes32 unblinded(const Bytes32& s, const Bytes32& share, const Bytes32& w,
                             const Bytes32& b) {
        Bytes32 t;
        crypto_core_ristretto255_sub(t.data(), share.data(), mul(w, b).data());
        return mul(s, t);
    }
    // crypto_kdf_derive_from_key, spelled out: keyed BLAKE2b-256 of nothing, salt the id.
    static Bytes32 kdf(const uint8_t* key, uint64_t id, const char (&context)[9]) {
        uint8_t salt[16] = {}, personal[16] = {};
        for (int i = 0; i < 8; ++i)
            salt[i] = uint8_t(id >> (8 * i));
        std::memcpy(personal, context, 8);
        Bytes32 out;
        crypto_generichash_blake2b_salt_personal(out.data(), 32, nullptr, 0, key, 32, salt,
                                                 personal);
        return out;
    }
    // crypto_auth, spelled out: HMAC-SHA-512 cut to its first 32 bytes.
    static Bytes32 mac(const Bytes32& key, std::span<const uint8_t> message) {
        uint8_t full[64];
        crypto_auth_hmacsha512_state st;
        crypto_auth_hmacsha512_init(&st, key.data(), key.size());
        crypto_auth_hmacsha512_update(&st, message.data(), message.size());
        crypto_auth_hmacsha512_final(&st, full);
        Bytes32 out;
        std::memcpy(out.data(), full, 32);
        return out;
    }

    FromTheDocument(const Salt& salt, Role asked, Role entry, const Bytes32& x, const Bytes32& y) {
        uint8_t wide[64];
        EXPECT_EQ(crypto_pwhash(wide, 64, kCodeNormalised, std::strlen(kCodeNormalised),
                                salt.data(), 2, 8u << 20, crypto_pwhash_ALG_ARGON2ID13),
                  0);
        crypto_core_ristretto255_scalar_reduce(w.data(), wide);
        m = hashToGroup("trephine SPAKE2 ristretto255 M");
        n = hashToGroup("trephine SPAKE2 ristretto255 N");
        shareX = blinded(x, w, m);
        shareY = blinded(y, w, n);
        kClient = unblinded(x, shareY, w, n);
        kServer = unblinded(y, shareX, w, m);

        std::vector<uint8_t> t;
        for (uint8_t c : bytesOf("trephine SPAKE2 v9"))
            t.push_back(c);
        t.insert(t.end(), salt.begin(), salt.end());
        t.push_back(uint8_t(asked));
        t.push_back(uint8_t(entry));
        for (const Bytes32* part : {&shareX, &shareY, &kClient, &w})
            t.insert(t.end(), part->begin(), part->end());
        EXPECT_EQ(t.size(), 164u);
        crypto_generichash_blake2b(transcript.data(), 64, t.data(), t.size(), nullptr, 0);

        clientToServer = kdf(transcript.data(), 1, "trphsess");
        serverToClient = kdf(transcript.data(), 2, "trphsess");
        confirmKeyClient = kdf(transcript.data() + 32, 1, "trphconf");
        confirmKeyServer = kdf(transcript.data() + 32, 2, "trphconf");
        clientMac = mac(confirmKeyClient, transcript);
        serverMac = mac(confirmKeyServer, transcript);
    }
};

std::string docText(const std::string& name) {
    std::ifstream in(std::string(TREPHINE_SOURCE_DIR) + "/docs/" + name);
    EXPECT_TRUE(in) << "docs/" << name << " not found under " << TREPHINE_SOURCE_DIR;
    std::stringstream text;
    text << in.rdbuf();
    return text.str();
}

Salt salt() {
    return unhexArray<16>(kSalt);
}

} // namespace

TEST(WireVectors, TheDocumentedCodeNormalisesAndHashesToTheDocumentedScalar) {
    initSodium();
    EXPECT_EQ(normaliseCode(kCodeAsTyped), kCodeNormalised);
    const Bytes32 w = codeScalar(kCodeNormalised, salt());
    EXPECT_EQ(hex(w), kW);
    const FromTheDocument doc(salt(), Role::Trainee, Role::Trainee, unhexArray<32>(kX),
                              unhexArray<32>(kY));
    EXPECT_EQ(hex(doc.w), kW);
    EXPECT_EQ(hex(doc.m), kM);
    EXPECT_EQ(hex(doc.n), kN);
}

TEST(WireVectors, TheHandshakeOfTheDocumentedVectorGivesTheDocumentedBytes) {
    initSodium();
    const Bytes32 w = codeScalar(kCodeNormalised, salt());
    const Bytes32 x = unhexArray<32>(kX), y = unhexArray<32>(kY);
    const FromTheDocument doc(salt(), Role::Trainee, Role::Trainee, x, y);

    // The offers.
    const SpakeClient client(w, salt(), Role::Trainee, x);
    EXPECT_EQ(hex(client.share()), kShareX);
    EXPECT_EQ(hex(doc.shareX), kShareX);
    const auto answer = spakeAnswer(w, salt(), Role::Trainee, Role::Trainee, client.share(), y);
    ASSERT_TRUE(answer);
    EXPECT_EQ(hex(answer->share), kShareY);
    EXPECT_EQ(hex(doc.shareY), kShareY);

    // K (the code keeps it to itself: its keys below depend on it), the transcript hash.
    EXPECT_EQ(hex(doc.kClient), kK);
    EXPECT_EQ(hex(doc.kServer), kK);
    EXPECT_EQ(hex(doc.transcript), kTranscript);

    // The keys and MACs, the code's at both ends and the document's.
    const auto keys = client.keys(answer->share, Role::Trainee);
    ASSERT_TRUE(keys);
    for (const SessionKeys* k : {&*keys, &answer->keys}) {
        EXPECT_EQ(hex(k->clientToServer), kClientToServer);
        EXPECT_EQ(hex(k->serverToClient), kServerToClient);
        EXPECT_EQ(hex(k->clientConfirm), kClientMac);
        EXPECT_EQ(hex(k->serverConfirm), kServerMac);
    }
    EXPECT_EQ(hex(doc.clientToServer), kClientToServer);
    EXPECT_EQ(hex(doc.serverToClient), kServerToClient);
    EXPECT_EQ(hex(doc.confirmKeyClient), kConfirmKeyClient);
    EXPECT_EQ(hex(doc.confirmKeyServer), kConfirmKeyServer);
    EXPECT_EQ(hex(doc.clientMac), kClientMac);
    EXPECT_EQ(hex(doc.serverMac), kServerMac);

    // The trainee code's entry answering an instructor's offer: the same shares and K, the role
    // bytes 01 00 in the transcript, so another MAC.
    const auto asked = spakeAnswer(w, salt(), Role::Instructor, Role::Trainee, client.share(), y);
    ASSERT_TRUE(asked);
    EXPECT_EQ(hex(asked->share), kShareY);
    EXPECT_EQ(hex(asked->keys.serverConfirm), kServerMacInstructorAsked);
    const FromTheDocument docAsked(salt(), Role::Instructor, Role::Trainee, x, y);
    EXPECT_EQ(hex(docAsked.serverMac), kServerMacInstructorAsked);
}

TEST(WireVectors, AMessageSealedWithTheDocumentedKeysGivesTheDocumentedBytes) {
    initSodium();
    SessionKeys keys;
    keys.clientToServer = unhexArray<32>(kClientToServer);
    keys.serverToClient = unhexArray<32>(kServerToClient);
    Ping ping;
    ping.clientTimeUs = kPingTimeUs;
    const std::vector<uint8_t> plain = encodeMessage(ping);
    ASSERT_EQ(hex(plain), "090807060504030201");

    SecureChannel client(keys, false);
    const std::vector<uint8_t> sealed = client.seal(Channel::Control, plain);
    EXPECT_EQ(hex(sealed), kSealedPing);

    // From the document: counter 1 (u64 LE), then ChaCha20-Poly1305-IETF under the client's key
    // with nonce channel, 0, 0, 0, counter (u64 LE), and no associated data.
    const uint8_t nonce[12] = {uint8_t(Channel::Control), 0, 0, 0, 1, 0, 0, 0, 0, 0, 0, 0};
    std::vector<uint8_t> doc(8 + plain.size() + 16);
    doc[0] = 1;
    unsigned long long written = 0;
    crypto_aead_chacha20poly1305_ietf_encrypt(doc.data() + 8, &written, plain.data(), plain.size(),
                                              nullptr, 0, nullptr, nonce,
                                              keys.clientToServer.data());
    EXPECT_EQ(hex(doc), kSealedPing);

    SecureChannel server(keys, true);
    std::vector<uint8_t> opened;
    EXPECT_EQ(server.open(Channel::Control, sealed, opened), SecureChannel::Opened::Ok);
    EXPECT_EQ(opened, plain);
}

TEST(WireVectors, TheHellosPlaceholderViewIsTheDocumentedBytes) {
    // What the window and the headless trainee send before the scene names a camera.
    ViewSpec placeholder;
    placeholder.width = placeholder.height = 1;
    std::vector<uint8_t> bytes;
    WriteStream w(bytes);
    ASSERT_TRUE(placeholder.serialize(w));
    EXPECT_EQ(hex(bytes), kPlaceholderView);
    EXPECT_NE(docText("protocol.md").find(std::string("`") + kPlaceholderView + "`"),
              std::string::npos)
        << "docs/protocol.md does not give the placeholder view's bytes";
}

TEST(WireVectors, EveryFrozenValueAppearsInSecurityMd) {
    const std::string doc = docText("security.md");
    for (const char* value : {kCodeAsTyped,
                              kCodeNormalised,
                              kSalt,
                              kX,
                              kY,
                              kW,
                              kM,
                              kN,
                              kShareX,
                              kShareY,
                              kK,
                              kTranscript,
                              kClientToServer,
                              kServerToClient,
                              kConfirmKeyClient,
                              kConfirmKeyServer,
                              kClientMac,
                              kServerMac,
                              kServerMacInstructorAsked,
                              kSealedPing})
        EXPECT_NE(doc.find(std::string("`") + value + "`"), std::string::npos)
            << value << " is not in docs/security.md's vector (in backquotes)";
}

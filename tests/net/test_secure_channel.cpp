// The session's cryptography without sockets (docs/security.md): codes, the SPAKE2 handshake,
// the sealed channel's tamper and replay checks, and the server's gate driven with the time
// passed in: refusals and their reasons, the wrong-code limit per address, removals.
#include "net/secure_channel.h"
#include "net/session_gate.h"

#include "libsim/error.h"

#include "gate_client.h"

#include <fmt/format.h>
#include <gtest/gtest.h>

#include <map>
#include <set>

using namespace trephine;
using namespace trephine::net;
using trephine::testing::GateClient;

namespace {

Salt testSalt(uint8_t fill = 7) {
    Salt s;
    s.fill(fill);
    return s;
}

ServerConfig codedConfig() {
    ServerConfig c;
    c.traineeCode = "TRAIN-EE42";
    c.instructorCode = "teach-3r99";
    return c;
}

ENetAddress address(uint32_t host) {
    ENetAddress a{};
    a.host = host;
    a.port = 5000;
    return a;
}

// Runs one handshake through the gate; the result of the Confirm (or of the step that refused).
SessionGate::Result join(SessionGate& gate, uint16_t id, uint32_t host, GateClient& client,
                         uint64_t now) {
    const std::vector<uint8_t> challenge = gate.connect(id, address(host));
    const SessionGate::Result answer =
        gate.receive(id, Channel::Control, client.offer(challenge), now);
    if (answer.kind != SessionGate::Result::Kind::Reply)
        return answer;
    const std::vector<uint8_t> answerBytes(answer.message.begin(), answer.message.end());
    return gate.receive(id, Channel::Control, client.confirm(answerBytes), now);
}

} // namespace

// [SECTION] codes

TEST(Codes, AGeneratedCodeIsEightReadableSymbolsAndFresh) {
    std::set<std::string> seen;
    for (int i = 0; i < 50; ++i) {
        const std::string code = generateCode();
        ASSERT_EQ(code.size(), 9u) << code;
        EXPECT_EQ(code[4], '-');
        EXPECT_EQ(code.find_first_of("ILOU"), std::string::npos) << code; // none to misread
        EXPECT_EQ(normaliseCode(code).size(), 8u);
        seen.insert(code);
    }
    EXPECT_EQ(seen.size(), 50u);
}

TEST(Codes, TheFormsPeopleTypeNormaliseToOneAndOthersAreRefusedInOneLine) {
    EXPECT_EQ(normaliseCode("abcd-efgh"), "ABCDEFGH");
    EXPECT_EQ(normaliseCode("AB CD EF GH"), "ABCDEFGH");
    EXPECT_EQ(normaliseCode("0OIl-1234"), "00111234"); // read aloud, O is 0 and I, L are 1
    for (const char* bad : {"", "abc", "abcd-ef?h", "läuft-gut"}) {
        try {
            normaliseCode(bad, "--code");
            FAIL() << bad;
        } catch (const Error& e) {
            const std::string what = e.what();
            EXPECT_EQ(what.find('\n'), std::string::npos);
            EXPECT_EQ(what.rfind("--code", 0), 0u) << what;
        }
    }
}

// [SECTION] the handshake

TEST(Spake, TheSameCodeGivesBothEndsTheSameKeysAndAnotherCodeDoesNot) {
    const Salt salt = testSalt();
    const Bytes32 w = codeScalar("ABCDEFGH", salt);
    SpakeClient client(w, salt, Role::Trainee);
    const auto server = spakeAnswer(w, salt, Role::Trainee, Role::Trainee, client.share());
    ASSERT_TRUE(server);
    const auto keys = client.keys(server->share, Role::Trainee);
    ASSERT_TRUE(keys);
    EXPECT_TRUE(sameMac(keys->serverConfirm, server->keys.serverConfirm));
    EXPECT_TRUE(sameMac(keys->clientConfirm, server->keys.clientConfirm));
    EXPECT_EQ(keys->clientToServer, server->keys.clientToServer);
    EXPECT_EQ(keys->serverToClient, server->keys.serverToClient);
    EXPECT_NE(keys->clientToServer, keys->serverToClient);

    const Bytes32 other = codeScalar("ABCDEFGJ", salt);
    SpakeClient wrong(other, salt, Role::Trainee);
    const auto answer = spakeAnswer(w, salt, Role::Trainee, Role::Trainee, wrong.share());
    ASSERT_TRUE(answer);
    const auto wrongKeys = wrong.keys(answer->share, Role::Trainee);
    ASSERT_TRUE(wrongKeys);
    EXPECT_FALSE(sameMac(wrongKeys->serverConfirm, answer->keys.serverConfirm));
    EXPECT_NE(wrongKeys->clientToServer, answer->keys.clientToServer);
}

TEST(Spake, SharesAreFreshAndCarryNothingOfTheCodeAnEavesdropperCouldCompare) {
    // The same code twice: shares differ (fresh ephemeral scalars), so a listener cannot tell
    // two joins with one code from joins with two.
    const Salt salt = testSalt();
    const Bytes32 w = codeScalar("ABCDEFGH", salt);
    SpakeClient a(w, salt, Role::Trainee), b(w, salt, Role::Trainee);
    EXPECT_NE(a.share(), b.share());
    // Another salt gives another scalar for the same code (no table of codes carries over).
    EXPECT_NE(codeScalar("ABCDEFGH", testSalt(8)), w);
}

TEST(Spake, AShareThatIsNoPointOfTheGroupIsRefused) {
    const Salt salt = testSalt();
    const Bytes32 w = codeScalar("ABCDEFGH", salt);
    Bytes32 junk;
    junk.fill(0xff);
    EXPECT_FALSE(spakeAnswer(w, salt, Role::Trainee, Role::Trainee, junk));
    Bytes32 zero{};
    EXPECT_FALSE(spakeAnswer(w, salt, Role::Trainee, Role::Trainee, zero));
    SpakeClient client(w, salt, Role::Trainee);
    EXPECT_FALSE(client.keys(junk, Role::Trainee));
}

// [SECTION] the sealed channel

namespace {
std::pair<SecureChannel, SecureChannel> channelPair() {
    const Salt salt = testSalt();
    const Bytes32 w = codeScalar("ABCDEFGH", salt);
    SpakeClient client(w, salt, Role::Trainee);
    const auto server = spakeAnswer(w, salt, Role::Trainee, Role::Trainee, client.share());
    return {SecureChannel(*client.keys(server->share, Role::Trainee), false),
            SecureChannel(server->keys, true)};
}
} // namespace

TEST(SecureChannel, SealedMessagesOpenOnceAndOnlyOnTheirChannel) {
    auto [client, server] = channelPair();
    const std::vector<uint8_t> msg{1, 2, 3, 4, 5};
    const std::vector<uint8_t> sealed = client.seal(Channel::ToolState, msg);
    EXPECT_EQ(sealed.size(), msg.size() + SecureChannel::kOverhead);
    EXPECT_EQ(std::search(sealed.begin(), sealed.end(), msg.begin(), msg.end()), sealed.end());
    std::vector<uint8_t> plain;
    EXPECT_EQ(server.open(Channel::Haptic, sealed, plain), SecureChannel::Opened::Forged);
    EXPECT_EQ(server.open(Channel::ToolState, sealed, plain), SecureChannel::Opened::Ok);
    EXPECT_EQ(plain, msg);
    EXPECT_EQ(server.open(Channel::ToolState, sealed, plain), SecureChannel::Opened::Replayed);
    // Its own direction only: the client cannot open what it sealed.
    EXPECT_EQ(client.open(Channel::ToolState, client.seal(Channel::ToolState, msg), plain),
              SecureChannel::Opened::Forged);
    // An empty message seals too (the tag alone).
    EXPECT_EQ(server.open(Channel::Control, client.seal(Channel::Control, {}), plain),
              SecureChannel::Opened::Ok);
    EXPECT_TRUE(plain.empty());
}

TEST(SecureChannel, EveryFlippedBitAndEveryTruncationIsForged) {
    auto [client, server] = channelPair();
    const std::vector<uint8_t> msg(40, 0xab);
    const std::vector<uint8_t> sealed = client.seal(Channel::Control, msg);
    std::vector<uint8_t> plain;
    for (size_t bit = 64; bit < sealed.size() * 8; ++bit) { // past the counter: ciphertext, tag
        std::vector<uint8_t> b = sealed;
        b[bit / 8] ^= uint8_t(1u << (bit % 8));
        ASSERT_EQ(server.open(Channel::Control, b, plain), SecureChannel::Opened::Forged) << bit;
    }
    for (size_t len = 0; len < sealed.size(); ++len)
        ASSERT_NE(server.open(Channel::Control, {sealed.data(), len}, plain),
                  SecureChannel::Opened::Ok);
    // A changed counter is a forgery too (the counter is the nonce).
    std::vector<uint8_t> b = sealed;
    b[0] ^= 2;
    EXPECT_EQ(server.open(Channel::Control, b, plain), SecureChannel::Opened::Forged);
    // None of that moved the window: the genuine message still opens.
    EXPECT_EQ(server.open(Channel::Control, sealed, plain), SecureChannel::Opened::Ok);
}

TEST(SecureChannel, ReorderedMessagesOpenWithinTheWindowAndOlderOnesAreReplays) {
    auto [client, server] = channelPair();
    std::vector<std::vector<uint8_t>> sent;
    for (int i = 0; i < 100; ++i)
        sent.push_back(client.seal(Channel::ToolState, std::vector<uint8_t>{uint8_t(i)}));
    std::vector<uint8_t> plain;
    EXPECT_EQ(server.open(Channel::ToolState, sent[90], plain), SecureChannel::Opened::Ok);
    EXPECT_EQ(server.open(Channel::ToolState, sent[60], plain), SecureChannel::Opened::Ok);
    EXPECT_EQ(server.open(Channel::ToolState, sent[89], plain), SecureChannel::Opened::Ok);
    EXPECT_EQ(server.open(Channel::ToolState, sent[99], plain), SecureChannel::Opened::Ok);
    EXPECT_EQ(server.open(Channel::ToolState, sent[60], plain), SecureChannel::Opened::Replayed);
    EXPECT_EQ(server.open(Channel::ToolState, sent[20], plain), SecureChannel::Opened::Replayed);
    EXPECT_EQ(server.open(Channel::ToolState, sent[98], plain), SecureChannel::Opened::Ok);
    // Channels count apart: a reliable channel's first message is fresh whatever the others did.
    EXPECT_EQ(server.open(Channel::Image, client.seal(Channel::Image, sent[0]), plain),
              SecureChannel::Opened::Ok);
}

// [SECTION] the gate

TEST(SessionGate, TheRightCodesJoinInTheirRolesAndSealFromThenOn) {
    ReportBook book;
    SessionGate gate(codedConfig(), book);
    ASSERT_FALSE(gate.open());
    GateClient trainee{"train-ee42"};
    const SessionGate::Result t = join(gate, 1, 0x0100007f, trainee, 0);
    ASSERT_EQ(t.kind, SessionGate::Result::Kind::Proven);
    EXPECT_EQ(t.role, Role::Trainee);
    EXPECT_TRUE(gate.sealing(1));
    GateClient instructor{"TEACH3R99", Role::Instructor};
    const SessionGate::Result i = join(gate, 2, 0x0100007f, instructor, 0);
    ASSERT_EQ(i.kind, SessionGate::Result::Kind::Proven);
    EXPECT_EQ(i.role, Role::Instructor);

    // What the gate seals, the client opens, and the other way round.
    SecureChannel clientSide(*trainee.keys, false);
    std::vector<uint8_t> plain;
    const std::vector<uint8_t> hello{uint8_t(MessageType::Ping), 1, 2, 3, 4, 5, 6, 7, 8};
    EXPECT_EQ(clientSide.open(Channel::Control, gate.seal(1, Channel::Control, hello), plain),
              SecureChannel::Opened::Ok);
    EXPECT_EQ(plain, hello);
    const SessionGate::Result in =
        gate.receive(1, Channel::Control, clientSide.seal(Channel::Control, hello), 0);
    ASSERT_EQ(in.kind, SessionGate::Result::Kind::Deliver);
    EXPECT_EQ(std::vector<uint8_t>(in.message.begin(), in.message.end()), hello);
    // The plain message, now, is no message at all.
    EXPECT_EQ(gate.receive(1, Channel::Control, hello, 0).kind, SessionGate::Result::Kind::Bad);
    EXPECT_EQ(book.read([](const ServerReport& r) { return r.security; }).forged, 1u);
    EXPECT_EQ(book.read([](const ServerReport& r) { return r.security; }).handshakes, 2u);
}

TEST(SessionGate, NoCodeAWrongCodeAndTheTraineeCodeAsInstructorAreEachRefusedWithTheirReason) {
    ReportBook book;
    SessionGate gate(codedConfig(), book);
    // No code: the client says hello in the clear.
    gate.connect(1, address(1));
    Hello h;
    const SessionGate::Result none = gate.receive(1, Channel::Control, encodeMessage(h), 0);
    ASSERT_EQ(none.kind, SessionGate::Result::Kind::Refuse);
    EXPECT_EQ(none.refuse, uint32_t(RefuseReason::WrongCode) | uint32_t(CodeRefusal::None) << 8);
    EXPECT_EQ(refuseReasonText(none.refuse),
              "this session needs a code: give the one the server printed (--code)");

    GateClient wrong{"WRONG-C0DE"};
    const SessionGate::Result w = join(gate, 2, 2, wrong, 0);
    ASSERT_EQ(w.kind, SessionGate::Result::Kind::Refuse);
    EXPECT_EQ(refuseReasonText(w.refuse), "wrong session code");
    EXPECT_FALSE(gate.sealing(2));

    GateClient traineeAsInstructor{"TRAINEE42", Role::Instructor};
    const SessionGate::Result ti = join(gate, 3, 3, traineeAsInstructor, 0);
    ASSERT_EQ(ti.kind, SessionGate::Result::Kind::Refuse);
    EXPECT_EQ(refuseReasonText(ti.refuse),
              "that is the trainee code: the instructor's role needs the instructor code");
    // A trainee offer is answered with the trainee code only: the instructor code cannot join
    // as a trainee, nor be tried through a trainee's offer.
    GateClient instructorAsTrainee{"TEACH3R99", Role::Trainee};
    EXPECT_EQ(join(gate, 4, 4, instructorAsTrainee, 0).kind, SessionGate::Result::Kind::Refuse);
    EXPECT_EQ(book.read([](const ServerReport& r) { return r.security; }).codesRefused, 4u);
    // Refused is refused: nothing more from it reaches anyone.
    EXPECT_EQ(gate.receive(2, Channel::Control, encodeMessage(h), 0).kind,
              SessionGate::Result::Kind::Bad);
}

TEST(SessionGate, MessagesBeforeTheHandshakeEndsAreDroppedAndCounted) {
    ReportBook book;
    SessionGate gate(codedConfig(), book);
    const std::vector<uint8_t> challenge = gate.connect(1, address(1));
    Ping ping{1};
    EXPECT_EQ(gate.receive(1, Channel::Control, encodeMessage(ping), 0).kind,
              SessionGate::Result::Kind::Bad);
    // A Confirm before any Offer, an Answer from a client, garbage: malformed.
    Handshake confirm;
    confirm.step = Handshake::Step::Confirm;
    EXPECT_EQ(gate.receive(1, Channel::Control, encodeMessage(confirm), 0).kind,
              SessionGate::Result::Kind::Bad);
    EXPECT_EQ(gate.receive(1, Channel::Control, std::vector<uint8_t>{24, 9, 9}, 0).kind,
              SessionGate::Result::Kind::Bad);
    EXPECT_EQ(book.read([](const ServerReport& r) { return r.security; }).unauthenticated, 1u);
    // The handshake still works after them.
    GateClient trainee{"TRAINEE42"};
    const auto answer = gate.receive(1, Channel::Control, trainee.offer(challenge), 0);
    ASSERT_EQ(answer.kind, SessionGate::Result::Kind::Reply);
    const std::vector<uint8_t> answerBytes(answer.message.begin(), answer.message.end());
    EXPECT_EQ(gate.receive(1, Channel::Control, trainee.confirm(answerBytes), 0).kind,
              SessionGate::Result::Kind::Proven);
}

// The answer release() gives `id` at `now`, if any.
std::optional<std::vector<uint8_t>> released(SessionGate& gate, uint16_t id, uint64_t now) {
    for (auto& [to, answer] : gate.release(now))
        if (to == id)
            return answer;
    return std::nullopt;
}

TEST(SessionGate, WrongCodesFromOneAddressAreBoundedAndTheRightCodeWaitsItsTurn) {
    ReportBook book;
    SessionGate gate(codedConfig(), book);
    uint16_t id = 1;
    uint64_t now = 1000;
    // The burst: kBurst guesses at once, each answered (one guess per attempt) and refused.
    for (int i = 0; i < int(AttemptLimit::kBurst); ++i) {
        GateClient guess{"GUESS" + std::to_string(100 + i)};
        ASSERT_EQ(refuseReasonText(join(gate, id++, 9, guess, now).refuse), "wrong session code");
    }
    // Then the slow lane: one answer now, the next offer waits its turn.
    GateClient slow{"GUESS998"};
    EXPECT_EQ(join(gate, id++, 9, slow, now).refuse, uint32_t(RefuseReason::WrongCode));
    GateClient guess{"GUESS999"};
    const uint16_t guessId = id++;
    EXPECT_EQ(join(gate, guessId, 9, guess, now).kind, SessionGate::Result::Kind::Held);
    // The right code, behind it at the same address, is never refused: it waits one more turn.
    GateClient right{"TRAINEE42"};
    const uint16_t rightId = id++;
    EXPECT_EQ(join(gate, rightId, 9, right, now + 100000).kind, SessionGate::Result::Kind::Held);
    EXPECT_TRUE(gate.release(now + 999000).empty()) << "one answer a second in the slow lane";
    EXPECT_TRUE(released(gate, guessId, now + 1000000)) << "the earlier offer goes first";
    EXPECT_FALSE(released(gate, rightId, now + 1500000));
    const auto answer = released(gate, rightId, now + 2000000);
    ASSERT_TRUE(answer);
    EXPECT_EQ(gate.receive(rightId, Channel::Control, right.confirm(*answer), now + 2000000).kind,
              SessionGate::Result::Kind::Proven);
    // Another address is not held back.
    GateClient elsewhere{"TRAINEE42"};
    EXPECT_EQ(join(gate, id++, 10, elsewhere, now).kind, SessionGate::Result::Kind::Proven);

    // A guesser trying every 0.5 s for an hour, each try a new connection that leaves once
    // refused or given up after 5 s waiting: its guesses tested stay within the bound.
    now += 10'000'000;
    const uint64_t start = now;
    std::map<uint16_t, uint64_t> held; // connection -> since
    GateClient g{"GUESS5000"};
    int answered = 0;
    for (int step = 0; step < 7200; ++step, now += 500000) {
        const uint16_t cid = id++;
        const SessionGate::Result r = join(gate, cid, 9, g, now);
        answered += r.refuse == uint32_t(RefuseReason::WrongCode);
        if (r.kind == SessionGate::Result::Kind::Held)
            held[cid] = now;
        else
            gate.leave(cid);
        for (auto& [hid, answerBytes] : gate.release(now)) {
            answered += gate.receive(hid, Channel::Control, g.confirm(answerBytes), now).kind ==
                        SessionGate::Result::Kind::Refuse;
            gate.leave(hid);
            held.erase(hid);
        }
        std::erase_if(held, [&](const auto& h) {
            if (now - h.second < 5'000'000)
                return false;
            gate.leave(h.first);
            return true;
        });
    }
    const double hourS = double(now - start) * 1e-6;
    const int bound =
        int(AttemptLimit::kBurst + hourS / AttemptLimit::kRefillS + hourS / AttemptLimit::kExcessS);
    EXPECT_LE(answered, bound);
    EXPECT_GE(answered, int(hourS / AttemptLimit::kExcessS) - 1) << "the slow lane keeps going";
    std::printf("[ wrong codes ] %d guesses answered in one hour from one address (bound: %d)\n",
                answered, bound);
    EXPECT_GT(book.read([](const ServerReport& r) { return r.security; }).attemptsLimited, 3000u);
}

// Many addresses guessing at once share the slow lanes' budget: in all they test no more than
// each address's burst and refill plus kExcessInAllPerS a second.
TEST(SessionGate, ManyAddressesGuessingTogetherStayWithinTheBoundInAll) {
    ReportBook book;
    SessionGate gate(codedConfig(), book);
    constexpr int kAddresses = 40;
    std::vector<GateClient> guessers;
    for (int a = 0; a < kAddresses; ++a)
        guessers.emplace_back(fmt::format("GUESS{}", 7000 + a));
    std::map<uint16_t, int> held; // connection -> its guesser
    uint16_t id = 1;
    int answered = 0;
    const uint64_t start = 1000;
    uint64_t now = start;
    for (; now < start + 60'000'000; now += 100'000) { // every address tries every 0.1 s
        for (int a = 0; a < kAddresses; ++a) {
            const uint16_t cid = id++;
            const SessionGate::Result r =
                join(gate, cid, uint32_t(100 + a), guessers[size_t(a)], now);
            answered += r.refuse == uint32_t(RefuseReason::WrongCode);
            if (r.kind == SessionGate::Result::Kind::Held)
                held[cid] = a;
            else
                gate.leave(cid);
        }
        for (auto& [hid, answer] : gate.release(now)) {
            answered += gate.receive(hid, Channel::Control,
                                     guessers[size_t(held.at(hid))].confirm(answer), now)
                            .kind == SessionGate::Result::Kind::Refuse;
            gate.leave(hid);
            held.erase(hid);
        }
    }
    const double t = double(now - start) * 1e-6;
    const int bound = int(kAddresses * (AttemptLimit::kBurst + t / AttemptLimit::kRefillS) +
                          AttemptLimit::kExcessInAllPerS * t) +
                      1;
    EXPECT_LE(answered, bound);
    EXPECT_GT(answered, int(AttemptLimit::kExcessInAllPerS * t) / 2) << "the slow lanes serve";
    std::printf("[ wrong codes ] %d addresses tested %d guesses in %.0f s (bound in all: %d)\n",
                kAddresses, answered, t, bound);
}

// The probe that kept a classroom out: one address guesses a wrong code every 2 s while 30
// participants with the right codes join from the same address (a NAT), all at once.
TEST(SessionGate, ThirtyParticipantsBehindAGuessersAddressEachJoinWithinFiveSeconds) {
    ReportBook book;
    ServerConfig config = codedConfig();
    SessionGate gate(config, book);
    constexpr uint64_t kStepUs = 10'000;
    struct Joiner {
        GateClient client{"TRAINEE42"};
        uint16_t id = 0;
        uint64_t startUs = 0, joinedUs = 0;
    };
    std::vector<Joiner> joiners(30);
    std::map<uint16_t, uint64_t> guesses; // the guesser's connections waiting, and since when
    GateClient guesser{"GUESS1234"};
    uint16_t nextId = 1;
    int tested = 0, proven = 0;
    const uint64_t start = 1000;
    uint64_t now = start, nextGuess = start;
    const uint64_t classJoins = start + 30'000'000; // once the guesser has spent the burst
    for (; now < start + 90'000'000; now += kStepUs) {
        if (now >= nextGuess) {
            const uint16_t cid = nextId++;
            const SessionGate::Result r = join(gate, cid, 9, guesser, now);
            tested += r.kind == SessionGate::Result::Kind::Refuse;
            if (r.kind == SessionGate::Result::Kind::Held)
                guesses[cid] = now;
            else
                gate.leave(cid);
            nextGuess = now + 2'000'000;
        }
        if (now == classJoins)
            for (Joiner& j : joiners) {
                j.id = nextId++;
                j.startUs = now;
                const std::vector<uint8_t> challenge = gate.connect(j.id, address(9));
                const SessionGate::Result r =
                    gate.receive(j.id, Channel::Control, j.client.offer(challenge), now);
                if (r.kind == SessionGate::Result::Kind::Reply) {
                    const std::vector<uint8_t> a(r.message.begin(), r.message.end());
                    if (gate.receive(j.id, Channel::Control, j.client.confirm(a), now).kind ==
                        SessionGate::Result::Kind::Proven)
                        j.joinedUs = now;
                }
            }
        for (auto& [id, answer] : gate.release(now)) {
            auto joiner = std::find_if(joiners.begin(), joiners.end(),
                                       [&, id = id](const Joiner& j) { return j.id == id; });
            if (joiner == joiners.end()) { // the guesser's: it learns its guess was wrong
                tested += gate.receive(id, Channel::Control, guesser.confirm(answer), now).kind ==
                          SessionGate::Result::Kind::Refuse;
                gate.leave(id);
                guesses.erase(id);
            } else if (gate.receive(id, Channel::Control, joiner->client.confirm(answer), now)
                           .kind == SessionGate::Result::Kind::Proven) {
                joiner->joinedUs = now;
                ++proven;
            }
        }
        // The server times out no offer the gate holds (SessionPolicy::holdHelloClock): held
        // guesses stay queued until answered.
    }
    double worstS = 0;
    for (const Joiner& j : joiners) {
        ASSERT_GT(j.joinedUs, 0u) << "participant " << j.id << " never joined";
        const double s = double(j.joinedUs - j.startUs) * 1e-6;
        EXPECT_LE(s, 5.0) << "participant " << j.id;
        worstS = std::max(worstS, s);
    }
    const double t = double(now - start) * 1e-6;
    const int bound =
        int(AttemptLimit::kBurst + t / AttemptLimit::kRefillS + t / AttemptLimit::kExcessS) +
        proven;
    EXPECT_LE(tested, bound);
    std::printf("[ classroom ] 30 joined behind a guesser, the slowest in %.2f s (target 5 s); "
                "the guesser tested %d guesses in %.0f s (bound %d)\n",
                worstS, tested, t, bound);
}

TEST(SessionGate, ARemovedAddressIsRefusedWithItsRoleCodeUntilAllowedBack) {
    ReportBook book;
    SessionGate gate(codedConfig(), book);
    GateClient trainee{"TRAINEE42"};
    ASSERT_EQ(join(gate, 1, 5, trainee, 0).kind, SessionGate::Result::Kind::Proven);
    gate.remove(1);
    gate.leave(1);
    GateClient again{"TRAINEE42"};
    const SessionGate::Result r = join(gate, 2, 5, again, 0);
    ASSERT_EQ(r.kind, SessionGate::Result::Kind::Refuse);
    EXPECT_EQ(refuseReasonText(r.refuse), "the instructor removed you from the session");
    // The instructor at that address still joins: the removal holds the trainee code only.
    GateClient instructor{"TEACH3R99", Role::Instructor};
    EXPECT_EQ(join(gate, 3, 5, instructor, 0).kind, SessionGate::Result::Kind::Proven);
    gate.allowRejoin();
    GateClient back{"TRAINEE42"};
    EXPECT_EQ(join(gate, 4, 5, back, 0).kind, SessionGate::Result::Kind::Proven);
    const SecurityCounters c = book.read([](const ServerReport& rep) { return rep.security; });
    EXPECT_EQ(c.removed, 1u);
    EXPECT_EQ(c.removedRefused, 1u);
}

TEST(SessionGate, AnOpenSessionPassesMessagesAsTheyAreAndStillKeepsRemovals) {
    ReportBook book;
    SessionGate gate(ServerConfig{}, book);
    ASSERT_TRUE(gate.open());
    Handshake challenge;
    ASSERT_TRUE(decodeMessage(gate.connect(1, address(5)), challenge));
    EXPECT_TRUE(challenge.open);
    Hello h;
    const std::vector<uint8_t> hello = encodeMessage(h);
    const SessionGate::Result r = gate.receive(1, Channel::Control, hello, 0);
    ASSERT_EQ(r.kind, SessionGate::Result::Kind::Deliver);
    EXPECT_FALSE(gate.sealing(1));
    EXPECT_EQ(gate.seal(1, Channel::Control, hello), hello);
    gate.remove(1);
    gate.leave(1);
    gate.connect(2, address(5));
    EXPECT_EQ(gate.receive(2, Channel::Control, hello, 0).refuse, uint32_t(RefuseReason::Removed));
}

TEST(SessionGate, CodesThatCannotWorkAreRefusedAtStart) {
    ReportBook book;
    ServerConfig one;
    one.traineeCode = "ABCDEFGH";
    EXPECT_THROW(SessionGate g(one, book), Error);
    ServerConfig same;
    same.traineeCode = "abcd-efgh";
    same.instructorCode = "ABCDEFGH";
    EXPECT_THROW(SessionGate g(same, book), Error);
    ServerConfig bad = codedConfig();
    bad.instructorCode = "x";
    EXPECT_THROW(SessionGate g(bad, book), Error);
}

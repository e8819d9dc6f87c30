// New role codes while the server runs (docs/security.md, "New codes"), without sockets: the gate
// and the policy wired as the server's network thread wires them, with the time passed in. A new
// trainee code lets a removed trainee back and stops the old code joining; only instructors ask
// for codes and only instructors are sent them.
#include "net/secure_channel.h"
#include "net/session_codes.h"
#include "net/session_gate.h"
#include "net/session_policy.h"

#include "libsim/skull.h"

#include "gate_client.h"

#include <gtest/gtest.h>

#include <optional>

using namespace trephine;
using namespace trephine::net;
using trephine::testing::GateClient;

namespace {

constexpr const char* kTraineeCode = "TRAIN-EE42";
constexpr const char* kInstructorCode = "TEACH-3R99";

ENetAddress address(uint32_t host) {
    ENetAddress a{};
    a.host = host;
    a.port = 5000;
    return a;
}

// The gate and the policy over a 32^3 sphere, applied to each other as SessionServer does.
struct CodesRig {
    ServerConfig config;
    ReportBook book;
    std::optional<SessionGate> gate;
    std::optional<SessionPolicy> policy;
    uint64_t now = 1'000'000;
    std::map<uint16_t, SecureChannel> channels; // each joined client's end
    std::vector<std::string> printed;           // the server's lines for new codes

    explicit CodesRig(bool coded = true) {
        if (coded) {
            config.traineeCode = kTraineeCode;
            config.instructorCode = kInstructorCode;
        }
        config.volumeName = "sphere:32";
        const Volume sphere = makeSphere(32);
        config.scene = std::make_shared<const Scene>(buildScene(sphere));
        gate.emplace(config, book);
        policy.emplace(config, sphere.dims(), sphere.spacing(), book,
                       [](const ToolState&, glm::vec3) { return SessionPolicy::ForceAnswer{}; });
    }
    // SessionServer::Impl::apply's part for the gate.
    PolicyOutput apply(PolicyOutput out) {
        for (std::string& line : issueCodes(*gate, *policy, out))
            printed.push_back(std::move(line));
        for (uint16_t id : out.removed)
            gate->remove(id);
        if (out.allowRejoin)
            gate->allowRejoin();
        return out;
    }
    struct Joined {
        uint16_t id = 0;
        SessionGate::Result::Kind kind = SessionGate::Result::Kind::Bad;
        uint32_t refuse = 0;
        PolicyOutput hello; // what the policy answered the hello (when it got that far)
    };
    // Connects from `host`, proves `code` for `role` and says hello (sealed) when proven.
    Joined join(const std::string& name, Role role, const std::string& code, uint32_t host) {
        Joined j;
        PolicyOutput connected;
        j.id = policy->connect(kProtocolVersion, now, connected);
        EXPECT_NE(j.id, 0);
        GateClient client{code, role};
        const std::vector<uint8_t> challenge = gate->connect(j.id, address(host));
        SessionGate::Result r = gate->receive(j.id, Channel::Control, client.offer(challenge), now);
        if (r.kind == SessionGate::Result::Kind::Reply) {
            const std::vector<uint8_t> answer(r.message.begin(), r.message.end());
            r = gate->receive(j.id, Channel::Control, client.confirm(answer), now);
        }
        j.kind = r.kind;
        j.refuse = r.refuse;
        if (r.kind == SessionGate::Result::Kind::Refuse) {
            PolicyOutput out;
            policy->refuse(j.id, r.refuse, now, out);
            return j;
        }
        if (r.kind != SessionGate::Result::Kind::Proven)
            return j;
        policy->authenticate(j.id, r.role);
        channels.emplace(j.id, SecureChannel(*client.keys, false));
        Hello h;
        h.name = name;
        h.role = role;
        h.view.width = h.view.height = 32;
        j.hello = send(j.id, h);
        return j;
    }
    // A message from `id`, sealed by its client and opened by the gate, as the server gets it.
    template <typename M>
    PolicyOutput send(uint16_t id, M m) {
        const std::vector<uint8_t> sealed =
            channels.at(id).seal(Channel::Control, encodeMessage(m));
        const SessionGate::Result in = gate->receive(id, Channel::Control, sealed, now);
        EXPECT_EQ(in.kind, SessionGate::Result::Kind::Deliver);
        return apply(policy->receive(id, in.message, now));
    }
    void leave(uint16_t id) {
        PolicyOutput out;
        policy->disconnect(id, now, out);
        gate->leave(id);
        channels.erase(id);
    }
    SecurityCounters security() const {
        return book.read([](const ServerReport& r) { return r.security; });
    }
};

Codes issue(Role role) {
    Codes m;
    m.op = Codes::Op::Issue;
    m.role = role;
    return m;
}

// Every Codes message in `out`, with whom it goes to.
std::vector<std::pair<std::vector<uint16_t>, Codes>> codesSent(const PolicyOutput& out) {
    std::vector<std::pair<std::vector<uint16_t>, Codes>> found;
    for (const PolicyOutput::Message& m : out.messages) {
        Codes c;
        if (peekMessageType(m.bytes) == uint8_t(MessageType::Codes)) {
            EXPECT_TRUE(decodeMessage(m.bytes, c));
            EXPECT_EQ(m.channel, Channel::Control);
            found.emplace_back(m.to, c);
        }
    }
    return found;
}

} // namespace

TEST(SessionCodes, ANewTraineeCodeLetsTheRemovedBackAndTheOldCodeNoLongerJoins) {
    CodesRig rig;
    const auto cho = rig.join("Dr. Cho", Role::Instructor, kInstructorCode, 1);
    ASSERT_EQ(cho.kind, SessionGate::Result::Kind::Proven);
    const auto ada = rig.join("Ada", Role::Trainee, kTraineeCode, 5);
    const auto bob = rig.join("Bob", Role::Trainee, kTraineeCode, 6);
    ASSERT_EQ(ada.kind, SessionGate::Result::Kind::Proven);
    ASSERT_EQ(bob.kind, SessionGate::Result::Kind::Proven);

    // Removed: Ada's address is refused with the trainee code.
    PolicyOutput out = rig.send(cho.id, Remove{Remove::Op::Remove, ada.id});
    ASSERT_EQ(out.removed, std::vector<uint16_t>{ada.id});
    rig.leave(ada.id);
    const auto refused = rig.join("Ada", Role::Trainee, kTraineeCode, 5);
    ASSERT_EQ(refused.kind, SessionGate::Result::Kind::Refuse);
    EXPECT_EQ(refuseReasonText(refused.refuse), "the instructor removed you from the session");

    // A new trainee code: the instructor is sent it (the instructor code unchanged), and the
    // server prints it with who issued it.
    out = rig.send(cho.id, issue(Role::Trainee));
    EXPECT_FALSE(out.malformed);
    const auto sent = codesSent(out);
    ASSERT_EQ(sent.size(), 1u);
    EXPECT_EQ(sent[0].first, std::vector<uint16_t>{cho.id});
    const std::string fresh = sent[0].second.trainee;
    EXPECT_EQ(fresh.size(), 9u) << fresh; // generateCode's "ABCD-EFGH"
    EXPECT_NE(normaliseCode(fresh), normaliseCode(kTraineeCode));
    EXPECT_EQ(sent[0].second.instructor, kInstructorCode);
    ASSERT_EQ(rig.printed.size(), 1u);
    EXPECT_EQ(rig.printed[0], codeIssuedLine(Role::Trainee, fresh, "Dr. Cho"));
    EXPECT_NE(rig.printed[0].find(fresh), std::string::npos);
    EXPECT_NE(rig.printed[0].find("Dr. Cho"), std::string::npos);

    // The old code is a wrong code now, from anywhere; the new one joins, from Ada's address too.
    const auto old = rig.join("Eve", Role::Trainee, kTraineeCode, 9);
    ASSERT_EQ(old.kind, SessionGate::Result::Kind::Refuse);
    EXPECT_EQ(refuseReasonText(old.refuse), "wrong session code");
    const auto back = rig.join("Ada", Role::Trainee, fresh, 5);
    ASSERT_EQ(back.kind, SessionGate::Result::Kind::Proven);
    EXPECT_TRUE(rig.policy->admitted(back.id));
    // Those already in stay.
    EXPECT_TRUE(rig.policy->live(cho.id));
    EXPECT_TRUE(rig.policy->live(bob.id));
    EXPECT_EQ(rig.send(bob.id, Ping{1}).disconnects.size(), 0u);
    // The instructor code is untouched.
    EXPECT_EQ(rig.join("Dr. Lee", Role::Instructor, kInstructorCode, 2).kind,
              SessionGate::Result::Kind::Proven);
    const SecurityCounters c = rig.security();
    EXPECT_EQ(c.codesIssued, 1u);
    EXPECT_EQ(c.removedRefused, 1u);
    EXPECT_EQ(c.codesRefused, 1u);
}

TEST(SessionCodes, OnlyInstructorsAreSentTheCodesAndOnlyTheyMayIssueOne) {
    CodesRig rig;
    const auto ada = rig.join("Ada", Role::Trainee, kTraineeCode, 5);
    ASSERT_EQ(ada.kind, SessionGate::Result::Kind::Proven);
    EXPECT_TRUE(codesSent(ada.hello).empty()); // a trainee's welcome has no codes
    const auto cho = rig.join("Dr. Cho", Role::Instructor, kInstructorCode, 1);
    const auto atWelcome = codesSent(cho.hello);
    ASSERT_EQ(atWelcome.size(), 1u); // an instructor's has them, to read out
    EXPECT_EQ(atWelcome[0].first, std::vector<uint16_t>{cho.id});
    EXPECT_EQ(atWelcome[0].second.trainee, kTraineeCode);
    EXPECT_EQ(atWelcome[0].second.instructor, kInstructorCode);

    // A trainee's request: refused and counted, not malformed, nothing issued.
    for (Role role : {Role::Trainee, Role::Instructor}) {
        const PolicyOutput out = rig.send(ada.id, issue(role));
        EXPECT_FALSE(out.malformed);
        EXPECT_TRUE(codesSent(out).empty());
    }
    EXPECT_TRUE(rig.printed.empty());
    EXPECT_EQ(rig.security().newCodesRefused, 2u);
    EXPECT_EQ(rig.security().codesIssued, 0u);
    EXPECT_EQ(rig.join("Bob", Role::Trainee, kTraineeCode, 6).kind,
              SessionGate::Result::Kind::Proven);
    // The codes themselves come only from the server: a client's is malformed.
    Codes current;
    current.trainee = "ANY-CODE";
    EXPECT_TRUE(rig.send(cho.id, current).malformed);

    // A new instructor code goes to every instructor and to no trainee.
    const auto lee = rig.join("Dr. Lee", Role::Instructor, kInstructorCode, 2);
    const PolicyOutput out = rig.send(lee.id, issue(Role::Instructor));
    const auto sent = codesSent(out);
    ASSERT_EQ(sent.size(), 1u);
    EXPECT_EQ(sent[0].first, (std::vector<uint16_t>{cho.id, lee.id}));
    EXPECT_EQ(sent[0].second.trainee, kTraineeCode);
    const std::string fresh = sent[0].second.instructor;
    EXPECT_NE(normaliseCode(fresh), normaliseCode(kInstructorCode));
    // The old instructor code is wrong now; the new one joins as instructor and is welcomed
    // with the new codes.
    const auto old = rig.join("Dr. Old", Role::Instructor, kInstructorCode, 3);
    ASSERT_EQ(old.kind, SessionGate::Result::Kind::Refuse);
    EXPECT_EQ(refuseReasonText(old.refuse), "wrong session code");
    const auto kim = rig.join("Dr. Kim", Role::Instructor, fresh, 3);
    ASSERT_EQ(kim.kind, SessionGate::Result::Kind::Proven);
    const auto kimCodes = codesSent(kim.hello);
    ASSERT_EQ(kimCodes.size(), 1u);
    EXPECT_EQ(kimCodes[0].second.instructor, fresh);
    EXPECT_EQ(rig.security().codesIssued, 1u);
}

TEST(SessionCodes, AHandshakeAnsweredWithTheOldCodeDoesNotEndInTheSession) {
    CodesRig rig;
    const auto cho = rig.join("Dr. Cho", Role::Instructor, kInstructorCode, 1);
    // Ada's offer is answered under the old trainee code; the new code comes before her confirm.
    PolicyOutput connected;
    const uint16_t id = rig.policy->connect(kProtocolVersion, rig.now, connected);
    GateClient ada{kTraineeCode, Role::Trainee};
    const SessionGate::Result answer = rig.gate->receive(
        id, Channel::Control, ada.offer(rig.gate->connect(id, address(5))), rig.now);
    ASSERT_EQ(answer.kind, SessionGate::Result::Kind::Reply);
    const std::vector<uint8_t> answerBytes(answer.message.begin(), answer.message.end());
    rig.send(cho.id, issue(Role::Trainee));
    const SessionGate::Result r =
        rig.gate->receive(id, Channel::Control, ada.confirm(answerBytes), rig.now);
    ASSERT_EQ(r.kind, SessionGate::Result::Kind::Refuse);
    EXPECT_EQ(refuseReasonText(r.refuse), "wrong session code");
}

TEST(SessionCodes, AnOpenSessionHasNoCodesToSendOrIssue) {
    CodesRig rig(false);
    PolicyOutput connected;
    const uint16_t id = rig.policy->connect(kProtocolVersion, rig.now, connected);
    rig.gate->connect(id, address(1));
    Hello h;
    h.name = "Dr. Cho";
    h.role = Role::Instructor;
    h.view.width = h.view.height = 32;
    const std::vector<uint8_t> helloBytes = encodeMessage(h); // the gate passes it as it is
    const SessionGate::Result in = rig.gate->receive(id, Channel::Control, helloBytes, 0);
    ASSERT_EQ(in.kind, SessionGate::Result::Kind::Deliver);
    const PolicyOutput hello = rig.apply(rig.policy->receive(id, in.message, rig.now));
    ASSERT_TRUE(rig.policy->admitted(id));
    EXPECT_TRUE(codesSent(hello).empty());
    Codes request = issue(Role::Trainee);
    const PolicyOutput out = rig.apply(rig.policy->receive(id, encodeMessage(request), rig.now));
    EXPECT_FALSE(out.malformed);
    EXPECT_TRUE(codesSent(out).empty());
    EXPECT_TRUE(rig.printed.empty());
    EXPECT_EQ(rig.security().newCodesRefused, 1u);
}

TEST(SessionCodes, ACodeIsShownAsGivenUnlessTooLongAndPrintedInOneLine) {
    EXPECT_EQ(codeText("train-ee42"), "train-ee42");
    const std::string spaced = std::string(60, '-') + "ABCDEFGH" + std::string(60, ' ');
    EXPECT_EQ(codeText(spaced), "ABCDEFGH");
    const std::string line = codeIssuedLine(Role::Instructor, "ABCD-EFGH", "Dr. Cho");
    EXPECT_EQ(line.find('\n'), std::string::npos);
    EXPECT_EQ(line, "new instructor code ABCD-EFGH (issued by Dr. Cho; the old one no longer "
                    "joins)");
}

// Force models relayed to instructors (HapticRelay) over loopback: an instructor receives every
// trainee's force models; a trainee never receives another participant's. Deadlines only guard
// against hangs.
#include "net/session_client.h"
#include "net/session_server.h"

#include "libsim/skull.h"
#include "libsim/tool.h"
#include "net/view.h"

#include "loopback.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <chrono>
#include <functional>
#include <vector>

using namespace trephine;
using namespace trephine::net;

namespace {

using trephine::testing::loopbackServerConfig;
using trephine::testing::Pumped;

using trephine::testing::pumpUntil;

ClientConfig clientConfig(const Volume& v, const std::string& name, Role role) {
    return trephine::testing::namedClientConfig(v, name, role, 48);
}

// A burr pushed 1 mm into the top of the sphere: in contact, a non-zero force.
ToolState burrInBone(int n, uint32_t sequence) {
    ToolState t;
    t.sequence = sequence;
    t.toolKind = uint8_t(ToolKind::Burr);
    t.diameterMm = 4.0f;
    t.position = {0.0f, 0.0f, sphereRadiusMm(n) + 2.0f - 1.0f};
    return t;
}

} // namespace

TEST(SessionRelay, InstructorReceivesTheTraineesForceModels) {
    Volume sphere = makeSphere(40);
    ServerConfig sc = loopbackServerConfig("sphere:40");
    SessionServer server(sphere, sc);
    Pumped pumped(server);
    const ENetAddress at = parseAddress("127.0.0.1:" + std::to_string(server.port()));

    SessionClient trainee(clientConfig(sphere, "trainee", Role::Trainee));
    SessionClient other(clientConfig(sphere, "second trainee", Role::Trainee));
    SessionClient instructor(clientConfig(sphere, "instructor", Role::Instructor));
    std::vector<std::pair<uint16_t, HapticModel>> relayed;
    instructor.setRelayCallback(
        [&](uint16_t id, const HapticModel& m, uint64_t) { relayed.emplace_back(id, m); });
    for (SessionClient* c : {&trainee, &other, &instructor})
        c->connect(at);
    std::vector<SessionClient*> all = {&trainee, &other, &instructor};
    ASSERT_TRUE(pumpUntil(
        all, [&] { return trainee.welcomed() && other.welcomed() && instructor.welcomed(); }));

    const int kStates = 10;
    for (int i = 1; i <= kStates; ++i) {
        trainee.sendToolState(burrInBone(40, uint32_t(i)));
        ASSERT_TRUE(pumpUntil(all, [&] { return trainee.hapticModelsReceived() >= uint64_t(i); }));
    }
    ASSERT_TRUE(pumpUntil(all, [&] { return instructor.hapticRelaysReceived() >= kStates; }));
    pumpUntil(
        all, [] { return false; }, 0.2); // anything else in flight

    const uint16_t traineeId = trainee.welcome().clientId;
    ASSERT_EQ(relayed.size(), size_t(kStates));
    for (const auto& [id, m] : relayed)
        EXPECT_EQ(id, traineeId);
    ASSERT_EQ(instructor.relayedModels().size(), 1u);
    const HapticModel& newest = instructor.relayedModels().at(traineeId);
    EXPECT_EQ(newest.toolSequence, uint32_t(kStates));
    // The very model the trainee itself received for that tool state.
    ASSERT_TRUE(trainee.latestHapticModel().has_value());
    EXPECT_EQ(newest.force, trainee.latestHapticModel()->force);
    EXPECT_TRUE(newest.contact);
    EXPECT_GT(glm::length(newest.force), 0.0f);
    // The instructor's own force channel is not used for others' models.
    EXPECT_EQ(instructor.hapticModelsReceived(), 0u);

    // Trainees never receive another participant's model.
    EXPECT_EQ(other.hapticRelaysReceived(), 0u);
    EXPECT_TRUE(other.relayedModels().empty());
    EXPECT_EQ(other.hapticModelsReceived(), 0u);
    EXPECT_EQ(trainee.hapticRelaysReceived(), 0u);
    EXPECT_EQ(server.hapticRelaysSent(), uint64_t(kStates));
    EXPECT_EQ(instructor.stats().malformed(), 0u);
    // ENet's loss estimate is exposed once connected: a fraction in [0, 1].
    EXPECT_GE(instructor.stats().packetLoss, 0.0);
    EXPECT_LE(instructor.stats().packetLoss, 1.0);
    EXPECT_EQ(other.stats().malformed(), 0u);

    // The instructor's own tool is answered to it, and relayed to nobody (no other instructor).
    instructor.sendToolState(burrInBone(40, 1));
    ASSERT_TRUE(pumpUntil(all, [&] { return instructor.hapticModelsReceived() >= 1; }));
    pumpUntil(
        all, [] { return false; }, 0.2);
    EXPECT_EQ(trainee.hapticRelaysReceived(), 0u);
    EXPECT_EQ(other.hapticRelaysReceived(), 0u);
    EXPECT_EQ(server.hapticRelaysSent(), uint64_t(kStates));
    nlohmann::json report = nlohmann::json::parse(server.reportJson());
    EXPECT_EQ(report["haptic_relays_sent"], 10) << report.dump(2);
    for (nlohmann::json peer : report["peers"])
        EXPECT_EQ(peer["haptic_relays"], peer["name"] == "instructor" ? 10 : 0) << peer.dump();

    for (SessionClient* c : all)
        c->disconnect();
    server.stop();
}

TEST(SessionRelay, MessageRoundTripsAndRejectsTrailingBytes) {
    HapticRelay r;
    r.clientId = 7;
    r.model.toolSequence = 42;
    r.model.force = {1.0f, -2.0f, 0.5f};
    r.model.contact = true;
    std::vector<uint8_t> bytes = encodeMessage(r);
    ASSERT_FALSE(bytes.empty());
    EXPECT_EQ(peekMessageType(bytes), uint8_t(MessageType::HapticRelay));
    HapticRelay back;
    ASSERT_TRUE(decodeMessage(bytes, back));
    EXPECT_EQ(back.clientId, 7);
    EXPECT_EQ(back.model.toolSequence, 42u);
    EXPECT_EQ(back.model.force, r.model.force);
    EXPECT_TRUE(back.model.contact);
    bytes.push_back(0);
    EXPECT_FALSE(decodeMessage(bytes, back));
}

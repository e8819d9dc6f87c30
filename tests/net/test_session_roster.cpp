// Who is in the session (Participants) over loopback: every client learns everyone's name, role
// and design from the server; a participant who leaves is dropped from the roster together with
// its relayed tool; a switch of design shows; malformed rosters are dropped and counted.
// Deadlines only guard against hangs.
#include "net/session_client.h"
#include "net/session_server.h"

#include "libsim/skull.h"
#include "net/view.h"

#include "loopback.h"

#include <gtest/gtest.h>

using namespace trephine;
using namespace trephine::net;

namespace {

using trephine::testing::burrState;
using trephine::testing::loopback;
using trephine::testing::loopbackServerConfig;
using trephine::testing::Pumped;
using trephine::testing::pumpUntil;
using trephine::testing::sphereTop;

ClientConfig named(const Volume& v, const std::string& name, Role role) {
    return trephine::testing::namedClientConfig(v, name, role, 32);
}

// The roster as "id:name:role:sync" entries, for readable failures.
std::vector<std::string> describe(const SessionClient& c) {
    std::vector<std::string> out;
    for (const auto& [id, p] : c.participants())
        out.push_back(std::to_string(id) + ":" + p.name + ":" +
                      (p.role == Role::Instructor ? "instructor" : "trainee") + ":" +
                      (p.sync == Sync::Volume ? "volume" : "dbi"));
    return out;
}

} // namespace

TEST(SessionRoster, EveryoneLearnsNamesRolesAndLeavers) {
    Volume sphere = makeSphere(32);
    SessionServer server(sphere, loopbackServerConfig("sphere:32"));
    Pumped pumped(server);
    SessionClient ada(named(sphere, "Ada", Role::Trainee));
    SessionClient ben(named(sphere, "Ben", Role::Trainee));
    SessionClient cho(named(sphere, "Dr. Cho", Role::Instructor));
    std::vector<SessionClient*> all = {&ada, &ben, &cho};
    for (SessionClient* c : all)
        c->connect(loopback(server.port()));
    ASSERT_TRUE(pumpUntil(all, [&] {
        for (SessionClient* c : all)
            if (!c->welcomed() || c->participants().size() != 3)
                return false;
        return true;
    }));
    const uint16_t a = ada.welcome().clientId, b = ben.welcome().clientId,
                   c = cho.welcome().clientId;
    for (SessionClient* x : all) {
        SCOPED_TRACE(x->welcome().clientId);
        const auto& roster = x->participants();
        ASSERT_EQ(roster.size(), 3u);
        EXPECT_EQ(roster.at(a).name, "Ada");
        EXPECT_EQ(roster.at(a).role, Role::Trainee);
        EXPECT_EQ(roster.at(b).name, "Ben");
        EXPECT_EQ(roster.at(c).name, "Dr. Cho");
        EXPECT_EQ(roster.at(c).role, Role::Instructor);
        EXPECT_EQ(describe(*x), describe(ada)) << "one roster for everyone";
    }

    // Ben drills a little, so the others hold his tool; then he switches design and leaves.
    SurfaceSite site = sphereTop(32);
    ben.sendToolState(burrState(site, 0, 10, 1000));
    ASSERT_TRUE(pumpUntil(all, [&] { return ada.others().count(b) && cho.others().count(b); }));
    ben.requestSync(Sync::Volume);
    ASSERT_TRUE(pumpUntil(all, [&] {
        return ada.participants().at(b).sync == Sync::Volume &&
               cho.participants().at(b).sync == Sync::Volume;
    }));
    ben.disconnect(100);
    std::vector<SessionClient*> stay = {&ada, &cho};
    ASSERT_TRUE(pumpUntil(
        stay, [&] { return ada.participants().size() == 2 && cho.participants().size() == 2; }));
    EXPECT_FALSE(ada.participants().count(b));
    EXPECT_FALSE(ada.others().count(b)) << "a leaver's tool is not drawn any more";
    EXPECT_FALSE(cho.others().count(b));
    EXPECT_FALSE(cho.relayedModels().count(b)) << "nor plotted for the instructor";
    EXPECT_EQ(cho.participants().at(a).name, "Ada");
    EXPECT_EQ(ada.stats().malformed(), 0u);
    server.stop();
}

// A client connected to a fake server (a raw ENet host standing in), which sends it hand-made
// messages.
class FakeServerRoster : public ::testing::Test {
protected:
    void SetUp() override {
        client.connect(loopback(fake.port()));
        ASSERT_TRUE(fake.pumpWith(client, [&] { return fake.peer && client.connected(); }));
    }
    static ClientConfig tinyView() {
        ClientConfig cfg;
        cfg.view.width = cfg.view.height = 16;
        return cfg;
    }
    trephine::testing::FakeServer fake;
    SessionClient client{tinyView()};
};

TEST_F(FakeServerRoster, MalformedRostersAreDroppedAndCounted) {

    Participants good;
    good.list = {{1, Role::Trainee, Sync::Dbi, "Ada"}, {2, Role::Instructor, Sync::Volume, "Cho"}};
    std::vector<uint8_t> ok = encodeMessage(good);
    std::vector<uint8_t> truncated(ok.begin(), ok.end() - 2);
    std::vector<uint8_t> trailing = ok;
    trailing.push_back(0);
    Participants dup = good;
    dup.list[1].clientId = 1;
    Participants zero = good;
    zero.list[0].clientId = 0;
    std::vector<uint8_t> huge = {uint8_t(MessageType::Participants), 0xff, 0xff}; // 65535 entries
    for (const auto& bad : {truncated, trailing, encodeMessage(dup), encodeMessage(zero), huge})
        fake.send(Channel::Control, bad);
    fake.send(Channel::Control, ok);
    ASSERT_TRUE(fake.pumpWith(client, [&] { return client.rostersReceived() == 1; }));
    ASSERT_TRUE(fake.pumpWith(client, [&] { return client.stats().malformed() == 5; }));
    ASSERT_EQ(client.participants().size(), 2u);
    EXPECT_EQ(client.participants().at(2).name, "Cho");
    EXPECT_EQ(client.participants().at(2).sync, Sync::Volume);
}

// A relay can trail the roster that dropped its sender (they travel on different channels): once
// a roster has come, relays of ids it does not list are counted but neither drawn nor plotted.
TEST_F(FakeServerRoster, RelaysOfParticipantsNotListedAreNotKept) {
    auto relay = [&](uint16_t id) {
        ToolRelay r;
        r.clientId = id;
        r.tool.sequence = 1;
        fake.send(Channel::ToolState, encodeMessage(r));
        HapticRelay h;
        h.clientId = id;
        h.model.toolSequence = 1;
        fake.send(Channel::Haptic, encodeMessage(h));
    };
    relay(7); // before any roster: kept
    ASSERT_TRUE(fake.pumpWith(client, [&] { return client.others().count(7) == 1; }));
    Participants roster;
    roster.list = {{1, Role::Instructor, Sync::Dbi, "me"}, {2, Role::Trainee, Sync::Dbi, "Ada"}};
    fake.send(Channel::Control, encodeMessage(roster));
    ASSERT_TRUE(fake.pumpWith(client, [&] { return client.rostersReceived() == 1; }));
    EXPECT_EQ(client.others().count(7), 0u) << "the roster drops whom it does not list";
    relay(7); // trailing: counted, not kept
    relay(2);
    ASSERT_TRUE(fake.pumpWith(client, [&] {
        return client.relaysReceived() == 3 && client.hapticRelaysReceived() == 3;
    }));
    EXPECT_EQ(client.others().count(7), 0u);
    EXPECT_EQ(client.relayedModels().count(7), 0u);
    EXPECT_EQ(client.others().count(2), 1u);
    EXPECT_EQ(client.relayedModels().count(2), 1u);
    EXPECT_EQ(client.stats().malformed(), 0u);
}

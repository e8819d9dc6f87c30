// An instructor taking over a trainee (TakeOver) over loopback: while held, the trainee's drill
// touches the bone but cuts nothing and the instructor's drill cuts; everyone's roster says who
// holds whom; a trainee's take-over, and one of a trainee another instructor holds, are refused;
// handing back, or the instructor leaving, gives the trainee its drill again. Deadlines only guard
// against hangs.
#include "net/session_client.h"
#include "net/session_server.h"

#include "libsim/skull.h"

#include "loopback.h"

#include <gtest/gtest.h>

using namespace trephine;
using namespace trephine::net;

using trephine::testing::burrState;
using trephine::testing::loopback;
using trephine::testing::loopbackServerConfig;
using trephine::testing::namedClientConfig;
using trephine::testing::pumpUntil;

namespace {

constexpr int kN = 48;

size_t airVoxels(const Volume& v) {
    size_t n = 0;
    for (int z = 0; z < v.dims().z; ++z)
        for (int y = 0; y < v.dims().y; ++y)
            for (int x = 0; x < v.dims().x; ++x)
                n += v.density(x, y, z) < kSurfaceDensity;
    return n;
}

// A site on the sphere `degrees` from its top, towards +x.
SurfaceSite sphereSite(float degrees) {
    const float a = glm::radians(degrees);
    const glm::vec3 normal(std::sin(a), 0.0f, std::cos(a));
    return {normal * sphereRadiusMm(kN), normal};
}

struct Session {
    Volume sphere = makeSphere(kN);
    SessionServer server{sphere, loopbackServerConfig("sphere:48")};
    trephine::testing::Pumped pumped{server};
    SessionClient ada{namedClientConfig(sphere, "Ada", Role::Trainee, 32)};
    SessionClient cho{namedClientConfig(sphere, "Dr. Cho", Role::Instructor, 32)};
    SessionClient lee{namedClientConfig(sphere, "Dr. Lee", Role::Instructor, 32)};
    std::vector<SessionClient*> all{&ada, &cho, &lee};
    uint64_t statesSent = 0;
    std::map<const SessionClient*, uint32_t> sequence;

    // Who holds `trainee` as `viewer` last heard (0: nobody or not listed).
    static uint16_t holder(const SessionClient& viewer, uint16_t trainee) {
        auto it = viewer.participants().find(trainee);
        return it == viewer.participants().end() ? 0 : it->second.takenOverBy;
    }
    bool everyoneSees(uint16_t trainee, uint16_t by) {
        return pumpUntil(all, [&] {
            for (SessionClient* c : all)
                if (c->connected() && holder(*c, trainee) != by)
                    return false;
            return true;
        });
    }
    // A whole stroke by `who` at `site`, waited for until the server has applied every state;
    // then the air voxels of the server's volume.
    size_t stroke(SessionClient& who, const SurfaceSite& site) {
        constexpr int kStates = 12;
        for (int i = 0; i < kStates; ++i) {
            ToolState t = burrState(site, i, kStates, 1000000 + statesSent * 10000);
            t.sequence = ++sequence[&who]; // a client's states only count in increasing sequence
            who.sendToolState(t);
            trephine::testing::pollAll(all);
        }
        statesSent += kStates;
        EXPECT_TRUE(pumpUntil(all, [&] { return server.toolStatesApplied() >= statesSent; }));
        return airVoxels(server.volumeSnapshot());
    }
};

} // namespace

TEST(TakeOver, MessageAndRosterFieldRoundTrip) {
    TakeOver m{7}, back;
    ASSERT_TRUE(decodeMessage(encodeMessage(m), back));
    EXPECT_EQ(back.trainee, 7);
    std::vector<uint8_t> bytes = encodeMessage(m);
    EXPECT_FALSE(decodeMessage(std::span(bytes.data(), 2), back)) << "truncated";
    bytes.push_back(0);
    EXPECT_FALSE(decodeMessage(bytes, back)) << "trailing byte";

    Participants roster;
    roster.list = {{1, Role::Trainee, Sync::Dbi, "Ada", 2},
                   {2, Role::Instructor, Sync::Dbi, "Cho"}};
    Participants rosterBack;
    ASSERT_TRUE(decodeMessage(encodeMessage(roster), rosterBack));
    EXPECT_EQ(rosterBack.list, roster.list);
    EXPECT_EQ(rosterBack.list[0].takenOverBy, 2);
}

TEST(TakeOver, TheInstructorsDrillCutsWhileTheTraineesIsPaused) {
    Session s;
    for (SessionClient* c : s.all)
        c->connect(loopback(s.server.port()));
    ASSERT_TRUE(pumpUntil(s.all, [&] {
        return s.ada.welcomed() && s.cho.welcomed() && s.lee.welcomed() &&
               s.ada.participants().size() == 3 && s.lee.participants().size() == 3;
    }));
    const uint16_t ada = s.ada.welcome().clientId, cho = s.cho.welcome().clientId,
                   lee = s.lee.welcome().clientId;

    // Nobody held: the trainee cuts, an instructor holding nobody does not.
    size_t air = airVoxels(s.server.volumeSnapshot());
    size_t now = s.stroke(s.ada, sphereSite(0));
    EXPECT_GT(now, air) << "the trainee's drill cuts";
    air = now;
    EXPECT_EQ(s.stroke(s.lee, sphereSite(30)), air) << "an instructor holding nobody points only";
    EXPECT_GT(s.server.drillingPaused(), 0u);

    // Dr. Cho takes Ada over: everyone's roster says so.
    s.cho.takeOver(ada);
    ASSERT_TRUE(s.everyoneSees(ada, cho));
    EXPECT_EQ(Session::holder(s.ada, cho), 0) << "an instructor is never held";
    const uint64_t pausedBefore = s.server.drillingPaused();
    EXPECT_EQ(s.stroke(s.ada, sphereSite(-30)), air) << "the trainee's drill is paused";
    EXPECT_GT(s.server.drillingPaused(), pausedBefore);
    now = s.stroke(s.cho, sphereSite(-30));
    EXPECT_GT(now, air) << "the instructor's drill cuts";
    air = now;

    // Refused, counted, not applied: another instructor's take-over of a held trainee, a
    // trainee's take-over, a take-over of an instructor or of nobody there.
    s.lee.takeOver(ada);
    s.ada.takeOver(ada);
    s.lee.takeOver(cho);
    s.lee.takeOver(999);
    ASSERT_TRUE(pumpUntil(s.all, [&] { return s.server.takeOversRefused() == 4; }));
    EXPECT_EQ(Session::holder(s.ada, ada), cho);
    EXPECT_EQ(s.stroke(s.lee, sphereSite(45)), air) << "Dr. Lee still holds nobody";

    // Handed back: the trainee cuts again, the instructor does not.
    s.cho.takeOver(0);
    ASSERT_TRUE(s.everyoneSees(ada, 0));
    now = s.stroke(s.ada, sphereSite(60));
    EXPECT_GT(now, air) << "the trainee's drill cuts again";
    air = now;
    EXPECT_EQ(s.stroke(s.cho, sphereSite(-60)), air);

    // Dr. Lee takes over, then leaves: Ada is handed back.
    s.lee.takeOver(ada);
    ASSERT_TRUE(s.everyoneSees(ada, lee));
    s.lee.disconnect(200);
    ASSERT_TRUE(pumpUntil(s.all, [&] {
        return s.ada.participants().size() == 2 && Session::holder(s.ada, ada) == 0 &&
               Session::holder(s.cho, ada) == 0;
    }));
    EXPECT_GT(s.stroke(s.ada, sphereSite(75)), air) << "the trainee cuts once the holder left";
    EXPECT_EQ(s.server.takeOversRefused(), 4u);
}

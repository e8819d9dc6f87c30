// Hand links (HandLinks) over loopback, pumped: an instructor's request goes to the server, which
// tells everyone with the roster who feels whose forces and who guides whose hand. A client keeps
// the list with no handler of its own (SessionClient::newest); the links end with a hand-back or
// a leave; a trainee's request, and one to feel someone not in the session, are refused.
#include "net/client_thread.h"
#include "net/session_client.h"
#include "net/session_server.h"

#include "libsim/skull.h"

#include "loopback.h"

#include <gtest/gtest.h>

using namespace trephine;
using namespace trephine::net;

using trephine::testing::loopback;
using trephine::testing::loopbackServerConfig;
using trephine::testing::namedClientConfig;
using trephine::testing::pumpUntil;

namespace {

struct Session {
    Volume sphere = makeSphere(32);
    SessionServer server{sphere, loopbackServerConfig("sphere:32")};
    trephine::testing::Pumped pumped{server};
    SessionClient ada{namedClientConfig(sphere, "Ada", Role::Trainee, 32)};
    SessionClient ben{namedClientConfig(sphere, "Ben", Role::Trainee, 32)};
    SessionClient cho{namedClientConfig(sphere, "Dr. Cho", Role::Instructor, 32)};
    std::vector<SessionClient*> all{&ada, &ben, &cho};

    void join() {
        for (SessionClient* c : all)
            c->connect(loopback(server.port()));
        ASSERT_TRUE(pumpUntil(all, [&] {
            for (SessionClient* c : all)
                if (!c->welcomed() || c->participants().size() != all.size())
                    return false;
            return true;
        }));
    }
    // Every connected client's newest list is `want` (none: no list yet, or an empty one).
    bool everyoneHas(const std::vector<HandLink>& want) {
        return pumpUntil(all, [&] {
            for (SessionClient* c : all) {
                if (!c->connected())
                    continue;
                const std::optional<HandLinks> got = c->newest().get<HandLinks>();
                if ((got ? got->list : std::vector<HandLink>{}) != want)
                    return false;
            }
            return true;
        });
    }
};

} // namespace

TEST(HandLinks, RoundTripAndRefusedForms) {
    HandLinks m{{{2, 5, true}, {3, 0, true}}}, back;
    ASSERT_TRUE(decodeMessage(encodeMessage(m), back));
    EXPECT_EQ(back.list, m.list);
    HandLinks unordered{{{3, 1, false}, {2, 1, false}}};
    EXPECT_FALSE(decodeMessage(encodeMessage(unordered), back)) << "instructor ids must increase";
    std::vector<uint8_t> bytes = encodeMessage(m);
    bytes.back() = 2;
    EXPECT_FALSE(decodeMessage(bytes, back)) << "a boolean is 0 or 1";
}

TEST(HandLinks, EveryoneHearsWhoFeelsAndGuidesUntilHandBackAndLeave) {
    Session s;
    s.join();
    const uint16_t ada = s.ada.welcome().clientId, ben = s.ben.welcome().clientId,
                   cho = s.cho.welcome().clientId;

    // Feeling a trainee: everyone, the trainee felt included, hears of it.
    s.cho.send(HandLinks{{{0, ada, false}}});
    EXPECT_TRUE(s.everyoneHas({{cho, ada, false}}));

    // A guide is in force only while the instructor holds a trainee.
    s.cho.send(HandLinks{{{0, ada, true}}});
    s.cho.sendPing();
    EXPECT_TRUE(s.everyoneHas({{cho, ada, false}}));
    s.cho.takeOver(ben);
    EXPECT_TRUE(s.everyoneHas({{cho, ada, true}}));

    // Refused, changing nothing: a trainee's link, and feeling someone not in the session.
    const uint64_t refused = s.server.handLinksRefused();
    const uint64_t takeOversRefused = s.server.takeOversRefused();
    s.ada.send(HandLinks{{{0, ben, false}}});
    s.cho.send(HandLinks{{{0, 999, true}}});
    EXPECT_TRUE(pumpUntil(s.all, [&] { return s.server.handLinksRefused() == refused + 2; }));
    EXPECT_EQ(s.server.takeOversRefused(), takeOversRefused) << "counted as what they are";
    EXPECT_TRUE(s.everyoneHas({{cho, ada, true}}));

    // Handing back ends the guide; the felt trainee leaving ends the feel, and the empty list
    // reaches everyone left.
    s.cho.takeOver(0);
    EXPECT_TRUE(s.everyoneHas({{cho, ada, false}}));
    s.cho.takeOver(ben); // the guide is not carried to the next hold: it is asked for again
    EXPECT_TRUE(pumpUntil(s.all, [&] { return s.ben.participants().at(ben).takenOverBy == cho; }));
    EXPECT_TRUE(s.everyoneHas({{cho, ada, false}}));
    s.cho.takeOver(0);
    s.ada.disconnect();
    EXPECT_TRUE(s.everyoneHas({}));
    EXPECT_TRUE(s.ben.newest().get<HandLinks>().has_value()) << "the ending is said, not implied";
}

TEST(HandLinks, AWindowsClientThreadSendsAndShowsThemWithoutAHandlerOfItsOwn) {
    Session s;
    s.join();
    const uint16_t ada = s.ada.welcome().clientId;
    ClientThreadConfig config;
    config.client = namedClientConfig(s.sphere, "Dr. Lee", Role::Instructor, 32);
    config.address = "127.0.0.1:" + std::to_string(s.server.port());
    ClientThread lee(config);
    lee.start();
    ASSERT_TRUE(pumpUntil(s.all, [&] {
        auto snap = lee.snapshot();
        return snap->welcome && snap->participants.size() == 4;
    }));
    const uint16_t leeId = lee.snapshot()->welcome->clientId;
    ASSERT_TRUE(lee.send(HandLinks{{{0, ada, false}}}));
    EXPECT_TRUE(pumpUntil(s.all, [&] {
        const auto links = lee.snapshot()->newest.get<HandLinks>();
        return links && links->list == std::vector<HandLink>{{leeId, ada, false}};
    }));
    EXPECT_TRUE(s.everyoneHas({{leeId, ada, false}}));
    lee.stop();
}

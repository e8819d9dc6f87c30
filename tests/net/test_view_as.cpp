// Instructor view-as: the server keeps every participant's view and sends an instructor viewing as
// one that participant's view whenever it changes; the instructor asks for it at its own size, so
// its picture is the server's render of the participant's camera. A trainee's ViewAs is ignored.
#include "net/view_follow.h"

#include "libsim/camera.h"
#include "libsim/skull.h"
#include "net/session_client.h"
#include "net/session_server.h"
#include "net/view.h"

#include "loopback.h"

#include <gtest/gtest.h>

using namespace trephine;
using namespace trephine::net;
using trephine::testing::loopback;
using trephine::testing::Pumped;
using trephine::testing::pumpUntil;

namespace {

ViewSpec viewAt(float x) {
    ViewSpec v;
    v.eye = {x, 0, 300};
    return v;
}

} // namespace

TEST(ViewFollowers, AFollowerGetsTheTargetsViewNowAndOnEveryChangeUntilItStops) {
    ViewFollowers f;
    EXPECT_FALSE(f.follow(5, 2)) << "nobody 2 said hello yet";
    EXPECT_EQ(f.following(5), 0);
    EXPECT_TRUE(f.setView(2, viewAt(1)).empty());
    const auto now = f.follow(5, 2);
    ASSERT_TRUE(now);
    EXPECT_EQ(*now, viewAt(1));
    EXPECT_EQ(f.following(5), 2);
    EXPECT_EQ(f.setView(2, viewAt(2)), std::vector<uint16_t>{5});
    EXPECT_TRUE(f.setView(3, viewAt(3)).empty()) << "nobody follows 3";
    EXPECT_FALSE(f.follow(5, 5)) << "itself: its own view";
    EXPECT_EQ(f.following(5), 0);
    EXPECT_TRUE(f.setView(2, viewAt(4)).empty());
    ASSERT_TRUE(f.follow(5, 2));
    f.leave(2);
    EXPECT_EQ(f.following(5), 0) << "the target left";
    EXPECT_TRUE(f.setView(2, viewAt(5)).empty());
}

TEST(ViewAs, AnInstructorSeesThroughATraineesCameraAndFollowsItsChanges) {
    const Volume skull = makeSkull(48);
    SessionServer server(skull, trephine::testing::loopbackServerConfig("skull:48"));
    Pumped pumped(server);
    ClientConfig tc = trephine::testing::namedClientConfig(skull, "alex", Role::Trainee, 64);
    ClientConfig ic = trephine::testing::namedClientConfig(skull, "ines", Role::Instructor, 80);
    ic.view = toViewSpec(cameraPreset("front", skull, {80, 80}));
    SessionClient trainee(tc), instructor(ic);
    trainee.connect(loopback(server.port()));
    instructor.connect(loopback(server.port()));
    ASSERT_TRUE(pumpUntil({&trainee, &instructor}, [&] {
        return trainee.hasFullImage() && instructor.hasFullImage() &&
               instructor.participants().size() == 2;
    }));
    const uint16_t alex = trainee.welcome().clientId;
    // The trainee's camera at the instructor's size.
    auto asSeenBy = [](ViewSpec v) {
        v.width = v.height = 80;
        return v;
    };

    instructor.viewAs(alex);
    EXPECT_EQ(instructor.viewingAs(), alex);
    ASSERT_TRUE(pumpUntil({&trainee, &instructor}, [&] {
        return instructor.hasFullImage() && instructor.view() == asSeenBy(tc.view);
    }));
    const Dbi truth = server.renderView(instructor.view());
    EXPECT_EQ(instructor.dbi().width(), truth.width());
    int differ = 0;
    for (int y = 0; y < truth.height(); ++y)
        for (int x = 0; x < truth.width(); ++x)
            differ += std::memcmp(instructor.dbi().color(x, y), truth.color(x, y), 3) != 0;
    EXPECT_EQ(differ, 0) << "the server's render of the trainee's camera";

    // The trainee turns its view: the instructor's follows.
    const ViewSpec left = toViewSpec(cameraPreset("left", skull, {64, 64}));
    ASSERT_NE(trainee.requestView(left), 0u);
    ASSERT_TRUE(pumpUntil({&trainee, &instructor}, [&] {
        return instructor.hasFullImage() && instructor.view() == asSeenBy(left);
    }));

    // Its own view again: the trainee's next change is not followed.
    instructor.viewAs(0);
    ASSERT_NE(instructor.requestView(ic.view), 0u);
    ASSERT_TRUE(pumpUntil({&trainee, &instructor}, [&] {
        return instructor.hasFullImage() && instructor.view() == ic.view;
    }));
    const uint64_t views = instructor.participantViewsReceived();
    ASSERT_NE(trainee.requestView(toViewSpec(cameraPreset("back", skull, {64, 64}))), 0u);
    ASSERT_TRUE(pumpUntil({&trainee, &instructor}, [&] { return trainee.hasFullImage(); }));
    instructor.sendPing();
    const uint64_t pongs = instructor.stats().rttUs.size();
    ASSERT_TRUE(pumpUntil({&trainee, &instructor},
                          [&] { return instructor.stats().rttUs.size() > pongs; }));
    EXPECT_EQ(instructor.participantViewsReceived(), views);
    EXPECT_EQ(instructor.view(), ic.view);

    // A trainee's ViewAs is ignored: no participant's view reaches it.
    trainee.viewAs(instructor.welcome().clientId);
    trainee.sendPing();
    const uint64_t tpongs = trainee.stats().rttUs.size();
    ASSERT_TRUE(
        pumpUntil({&trainee, &instructor}, [&] { return trainee.stats().rttUs.size() > tpongs; }));
    EXPECT_EQ(trainee.participantViewsReceived(), 0u);
    server.stop();
}

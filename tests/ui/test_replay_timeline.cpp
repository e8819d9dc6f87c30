// A replay's timeline in the window (ui/panel_replay.cpp): what its keys and slider ask for, and
// a window on a served log whose Space plays it and whose Right seeks it, as the server applies.
// Windows need a display (xvfb-run).
#include "gl_window_test.h"
#include "ui/panels.h"
#include "ui/trainer_app.h"

#include "libsim/skull.h"
#include "net/replay_feed.h"
#include "net/session_server.h"

#include "loopback.h"
#include "recorded_session.h"
#include "test_support.h"

#include <GLFW/glfw3.h>
#include <gtest/gtest.h>

using namespace trephine;
using namespace trephine::ui;

TEST(ReplayTimeline, KeysAskPlayPauseAndSeeksAndASeekShowsUntilTheServerAnswers) {
    net::ReplayState s{2'000'000, 60'000'000, 1.0f, false, 4};
    ReplayControls c;
    EXPECT_EQ(c.shownUs(s, 2'000'000), 2'000'000u);
    c.keys(true, 0, s, 2'000'000);
    ASSERT_EQ(c.asked.size(), 1u);
    EXPECT_EQ(c.asked[0].op, net::ReplayControl::Op::Play) << "Space on a paused replay plays";
    c.asked.clear();
    s.playing = true;
    c.keys(true, 2, s, 3'000'000);
    ASSERT_EQ(c.asked.size(), 2u);
    EXPECT_EQ(c.asked[0].op, net::ReplayControl::Op::Pause);
    EXPECT_EQ(c.asked[1].op, net::ReplayControl::Op::Seek);
    EXPECT_EQ(c.asked[1].positionUs, 13'000'000u) << "two Rights: 10 s on";
    // Until a state with the seek counted arrives, the cursor stays where the seek went.
    EXPECT_EQ(c.shownUs(s, 3'100'000), 13'000'000u);
    s.seeks = 5;
    EXPECT_EQ(c.shownUs(s, 13'050'000), 13'050'000u);
    // Left past the start stops at 0; Right past the end at the end.
    c.asked.clear();
    c.keys(false, -9, s, 13'050'000);
    EXPECT_EQ(c.asked.at(0).positionUs, 0u);
    c.keys(false, +40, s, 0);
    EXPECT_EQ(c.asked.at(1).positionUs, 60'000'000u);
    // A slider held shows where it is.
    c.dragS = 42.5;
    EXPECT_EQ(c.shownUs(s, 0), 42'500'000u);
}

TEST(ReplayTimeline, SpaceInAWindowPlaysTheServedLogAndRightSeeksIt) {
    TREPHINE_NEED_DISPLAY("the instructor window");
    const trephine::testing::TempDir dir;
    const net::LogContents log = trephine::testing::recordTwoStrokes(dir / "two.log");
    ASSERT_TRUE(log.stopped.empty()) << log.stopped;
    const Volume start = net::logStartVolume(log.header, loadVolume);
    auto run = [&](std::vector<int> taps) {
        net::ServerConfig base = trephine::testing::loopbackServerConfig("sphere:48");
        net::SessionServer server(start, net::replayServerConfig(log.header, base));
        server.serveLog(log.records, 0.01, false); // slow: a hundredth of the pace
        trephine::testing::Pumped pumped(server);
        TrainerOptions o;
        o.address = "127.0.0.1:" + std::to_string(server.port());
        o.instructor = true;
        o.size = 96;
        o.frames = int(taps.size()) + 4;
        o.timeoutS = 60.0;
        o.visible = false;
        o.tapKeys = std::move(taps);
        EXPECT_EQ(trephine::testing::whilePumping([&] { return runTrainerWindow(o); }), 0);
        // The window's last control reaches the server's next pass.
        std::optional<net::ReplayState> s;
        EXPECT_TRUE(trephine::testing::pumpUntil({}, [&] {
            s = server.replayState();
            return s && server.idle();
        }));
        server.stop();
        return s.value_or(net::ReplayState{});
    };
    const net::ReplayState played = run({GLFW_KEY_SPACE});
    EXPECT_TRUE(played.playing) << "Space played the paused replay";
    EXPECT_EQ(played.seeks, 0u);
    const net::ReplayState sought = run({GLFW_KEY_RIGHT});
    EXPECT_FALSE(sought.playing);
    EXPECT_EQ(sought.seeks, 1u) << "Right sought 5 s on";
    EXPECT_EQ(sought.positionUs, std::min<uint64_t>(5'000'000, sought.durationUs));
}

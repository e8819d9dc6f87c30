// `trephine replay FILE --serve`: a recorded session played into a live server. The feed's
// pacing and the policy's replayed participants are tested on their own (no sockets, time
// passed in); then a recorded session is served to a watching window over loopback, whose last
// picture must equal, bit for bit, a render of the volume the log replays to, and whose roster
// must have listed the recorded trainee by name.
#include "child_process.h"
#include "net/replay_feed.h"
#include "net/session_log.h"
#include "net/session_policy.h"
#include "net/session_replay.h"

#include "net/session_client.h"
#include "net/session_server.h"
#include "net/view.h"

#include "libsim/error.h"
#include "libsim/skull.h"
#include "libsim/tool.h"
#include "libsim/volume_io.h"

#include "loopback.h"
#include "recorded_session.h"
#include "test_support.h"

#include "policy_output.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <optional>
#include <string>
#include <sys/wait.h>
#include <unistd.h>
#include <vector>

using namespace trephine;
using namespace trephine::net;
using trephine::testing::sentTo;

using trephine::testing::burrState;
using trephine::testing::Child;
using trephine::testing::loopback;
using trephine::testing::namedClientConfig;
using trephine::testing::pumpUntil;

namespace {

// A live session's policy on the 32^3 sphere, driven without sockets.
struct SpherePolicy {
    Volume sphere = makeSphere(32);
    ServerConfig config = [&] {
        ServerConfig c;
        c.volumeName = "sphere:32";
        c.scene = std::make_shared<const Scene>(buildScene(sphere));
        return c;
    }();
    ReportBook book;
    SessionPolicy policy{config, sphere.dims(), sphere.spacing(), book,
                         [](const ToolState&, glm::vec3) { return SessionPolicy::ForceAnswer{}; }};
};

} // namespace

TEST(ReplayPlayer, GivesEachRecordWhenItsTimeComesRoundAtTheSpeed) {
    std::vector<LogRecord> records{{5'000'000, HelloEvent{.client = 1}},
                                   {5'100'000, ToolEvent{.client = 1}},
                                   {6'000'000, ToolEvent{.client = 1}},
                                   // A resumed server's clock starts afresh: the session goes on.
                                   {200, ResumeEvent{}},
                                   {500'200, ToolEvent{.client = 1}}};
    EXPECT_EQ(sessionTimesUs(records),
              (std::vector<uint64_t>{0, 100'000, 1'000'000, 1'000'000, 1'500'000}));
    const uint64_t t0 = 7'000'000; // wall time: the player takes any origin
    ReplayPlayer player(records, 2.0, true, t0);
    EXPECT_EQ(player.durationUs(), 1'500'000u);
    EXPECT_EQ(player.advance(t0).records.size(), 1u);
    EXPECT_TRUE(player.advance(t0 + 49'999).records.empty());
    EXPECT_EQ(player.advance(t0 + 50'000).records.size(), 1u);
    const ReplayPlayer::Due next = player.advance(t0 + 700'000);
    ASSERT_EQ(next.records.size(), 2u) << "the stroke's end and the resume, not the state after";
    EXPECT_TRUE(next.records[1].is<ResumeEvent>());
    EXPECT_FALSE(next.rewind);
    EXPECT_FALSE(player.done());
    EXPECT_TRUE(player.playing());
    EXPECT_EQ(player.advance(t0 + 750'000).records.size(), 1u);
    EXPECT_TRUE(player.done());
    EXPECT_FALSE(player.playing()) << "it pauses at the end";
    EXPECT_EQ(player.positionUs(t0 + 10'000'000), 1'500'000u);
    EXPECT_TRUE(player.advance(t0 + 10'000'000).records.empty());
    EXPECT_THROW(ReplayPlayer(records, 0.0, true, 0), Error);
    EXPECT_THROW(ReplayPlayer(records, -1.0, true, 0), Error);
    EXPECT_THROW(ReplayPlayer(records, 1e7, true, 0), Error);
}

TEST(ReplayPlayer, PausesSeeksAndChangesSpeedAtTheTimesGiven) {
    std::vector<LogRecord> records;
    for (uint64_t s = 0; s <= 10; ++s)
        records.push_back({s * 1'000'000, ToolEvent{.client = 1}});
    uint64_t now = 100;
    ReplayPlayer player(records, 1.0, false, now);
    EXPECT_FALSE(player.playing());
    EXPECT_EQ(player.advance(now + 5'000'000).records.size(), 1u) << "paused at the start";
    now += 5'000'000;
    player.play(now);
    EXPECT_EQ(player.advance(now + 2'500'000).records.size(), 2u); // 1 s and 2 s
    now += 2'500'000;
    player.pause(now);
    EXPECT_EQ(player.positionUs(now + 9'000'000), 2'500'000u);
    EXPECT_TRUE(player.advance(now + 9'000'000).records.empty());
    // Forward: only what lies between is given, no rebuild.
    player.seek(6'000'000, now);
    ReplayPlayer::Due d = player.advance(now);
    EXPECT_FALSE(d.rewind);
    ASSERT_EQ(d.records.size(), 4u);
    EXPECT_EQ(d.records.back().timeUs, 6'000'000u);
    // Backwards: a rebuild, then everything up to the new position again.
    player.seek(1'500'000, now);
    d = player.advance(now);
    EXPECT_TRUE(d.rewind);
    ASSERT_EQ(d.records.size(), 2u);
    EXPECT_EQ(d.records.back().timeUs, 1'000'000u);
    // A seek back to where nothing given lies past it needs no rebuild.
    player.seek(1'800'000, now);
    EXPECT_FALSE(player.advance(now).rewind);
    EXPECT_EQ(player.seeks(), 3u);
    // Four times as fast from 1.8 s: 2 s of wall time is 8 s of session, clamped to the end.
    player.setSpeed(4.0, now);
    player.play(now);
    EXPECT_EQ(player.positionUs(now + 1'000'000), 5'800'000u);
    EXPECT_EQ(player.advance(now + 2'100'000).records.size(), 9u); // 2 s .. 10 s
    EXPECT_FALSE(player.playing());
    const ReplayState s = player.state(now + 3'000'000);
    EXPECT_EQ(s.positionUs, 10'000'000u);
    EXPECT_EQ(s.durationUs, 10'000'000u);
    EXPECT_EQ(s.speed, 4.0f);
    // Play at the end starts again from the start, as a video player does.
    now += 3'000'000;
    player.play(now);
    d = player.advance(now);
    EXPECT_TRUE(d.rewind);
    EXPECT_EQ(d.records.size(), 1u);
    EXPECT_TRUE(player.playing());
    // A window's controls: a speed out of range changes nothing.
    EXPECT_FALSE(player.control({ReplayControl::Op::Speed, 0, 0.0f}, now));
    EXPECT_EQ(player.speed(), 4.0);
    EXPECT_TRUE(player.control({ReplayControl::Op::Pause}, now));
    EXPECT_FALSE(player.playing());
}

TEST(SessionPolicyReplay, RecordedParticipantsAreListedRelayedDrilledAndLeave) {
    SpherePolicy live;
    SessionPolicy& policy = live.policy;
    uint64_t now = 1'000'000;
    PolicyOutput out;
    const uint16_t watcher = policy.connect(kProtocolVersion, now, out);
    Hello h;
    h.name = "Watcher";
    h.role = Role::Instructor;
    h.view.width = h.view.height = 32;
    policy.receive(watcher, encodeMessage(h), now);

    auto play = [&](const LogRecord& r) {
        PolicyOutput o;
        policy.replayed({&r, 1}, now, o);
        return o;
    };
    const LogRecord hello{0, HelloEvent{1, Role::Trainee, "Ada"}};
    play(hello);
    now += 1'000'000;
    PolicyOutput paced;
    policy.update(now, paced);
    const auto rosters = sentTo<Participants>(paced, watcher);
    ASSERT_EQ(rosters.size(), 1u);
    ASSERT_EQ(rosters[0].list.size(), 2u);
    EXPECT_EQ(rosters[0].list[0].clientId, watcher);
    EXPECT_EQ(rosters[0].list[1].clientId, SessionPolicy::replayedId(1));
    EXPECT_EQ(rosters[0].list[1].name, "Ada");
    EXPECT_EQ(rosters[0].list[1].role, Role::Trainee);

    JoinEvent join{.client = 1};
    join.sync = Sync::Volume;
    PolicyOutput joined = play({0, join});
    ASSERT_EQ(joined.events.size(), 1u);
    ASSERT_TRUE(joined.events[0].is<JoinEvent>());
    EXPECT_EQ(joined.events[0].as<JoinEvent>()->client, SessionPolicy::replayedId(1));
    EXPECT_EQ(joined.events[0].as<JoinEvent>()->sync, Sync::Dbi)
        << "nobody takes a replayed client's volume";

    ToolEvent tool{.client = 1};
    tool.tool.sequence = 7;
    tool.tool.position = glm::vec3(1, 2, 3);
    tool.tool.drilling = true;
    PolicyOutput drilled = play({0, tool});
    ASSERT_EQ(drilled.events.size(), 1u);
    ASSERT_TRUE(drilled.events[0].is<ToolEvent>());
    EXPECT_EQ(drilled.events[0].as<ToolEvent>()->client, SessionPolicy::replayedId(1));
    EXPECT_EQ(drilled.events[0].as<ToolEvent>()->tool.sequence, 7u);
    EXPECT_EQ(drilled.events[0].timeUs, now);
    const auto relays = sentTo<ToolRelay>(drilled, watcher);
    ASSERT_EQ(relays.size(), 1u);
    EXPECT_EQ(relays[0].clientId, SessionPolicy::replayedId(1));
    EXPECT_EQ(relays[0].tool.position, glm::vec3(1, 2, 3));

    // A recorded instructor's mark, then its removal by the log's id.
    MarkEvent mark{Annotate::Op::Add, {41, 2, glm::vec3(4, 5, 6), "here"}};
    play({0, mark});
    ASSERT_EQ(policy.marks().size(), 1u);
    EXPECT_EQ(policy.marks().begin()->second.label, "here");
    EXPECT_EQ(policy.marks().begin()->second.author, SessionPolicy::replayedId(2));
    mark.op = Annotate::Op::Remove;
    mark.mark.id = 41;
    play({0, mark});
    EXPECT_TRUE(policy.marks().empty());

    PolicyOutput left = play({0, LeaveEvent{1}});
    ASSERT_EQ(left.events.size(), 1u);
    EXPECT_TRUE(left.events[0].is<LeaveEvent>());
    now += 1'000'000;
    PolicyOutput after;
    policy.update(now, after);
    const auto last = sentTo<Participants>(after, watcher);
    ASSERT_EQ(last.size(), 1u);
    ASSERT_EQ(last[0].list.size(), 1u) << "Ada left the recorded session";

    // A real client never gets an id a replayed participant holds.
    play(hello);
    for (int i = 0; i < 3; ++i) {
        PolicyOutput c;
        EXPECT_NE(policy.connect(kProtocolVersion, now, c), SessionPolicy::replayedId(1));
    }
}

TEST(ReplayServeCli, AWatcherSeesTheRecordedSessionsFinalPictureAndItsTrainee) {
    constexpr int kN = 48;
    const Volume sphere = makeSphere(kN);
    const trephine::testing::TempDir dir;
    const std::string log = dir / "s.log";
    {
        Child server({"server", "--open", "--port", "0", "--volume", "sphere:48",
                      "--render-threads", "1", "--record", log});
        const int port = server.port();
        ASSERT_GT(port, 0);
        SessionClient ada(namedClientConfig(sphere, "Ada", Role::Trainee, 48));
        ada.connect(loopback(uint16_t(port)));
        ASSERT_TRUE(pumpUntil({&ada}, [&] { return ada.hasFullImage(); }));
        const glm::vec3 normal(0.0f, 0.0f, 1.0f);
        const SurfaceSite site{normal * sphereRadiusMm(kN), normal};
        for (int i = 0; i < 40; ++i) {
            ada.sendToolState(burrState(site, i, 40, 1000000));
            ada.poll(2);
        }
        for (int i = 0; i < 50; ++i)
            ada.poll(1);
        EXPECT_EQ(server.end(SIGTERM), 0);
    }
    const LogContents contents = readSessionLog(log);
    ASSERT_TRUE(contents.stopped.empty()) << contents.stopped;
    SessionReplay replay(contents.header, logStartVolume(contents.header, loadVolume));
    ClientConfig config = namedClientConfig(sphere, "Watcher", Role::Instructor, 40);
    config.codec = Codec::Raw; // the DBI's depth is then the server's floats, bit for bit
    const Dbi start = replay.render(toCamera(config.view));
    replay.applyAll(contents.records);
    const Dbi expected = replay.render(toCamera(config.view));
    ASSERT_FALSE(expected == start) << "the recorded session drilled nothing";
    uint16_t adaId = 0;
    for (const LogRecord& r : contents.records)
        if (const HelloEvent* h = r.as<HelloEvent>(); h && h->name == "Ada")
            adaId = h->client;
    ASSERT_NE(adaId, 0);

    Child served({"replay", log, "--serve", "--port", "0", "--speed", "4", "--render-threads", "1",
                  "--wait"});
    const int port = served.port();
    ASSERT_GT(port, 0);
    SessionClient watcher(config);
    watcher.connect(loopback(uint16_t(port)));
    bool listedAda = false, sawAdasTool = false;
    auto watch = [&] {
        for (const auto& [id, p] : watcher.participants())
            listedAda = listedAda || (p.name == "Ada" && p.role == Role::Trainee &&
                                      id == SessionPolicy::replayedId(adaId));
        sawAdasTool = sawAdasTool || watcher.others().count(SessionPolicy::replayedId(adaId));
    };
    EXPECT_TRUE(pumpUntil({&watcher}, [&] {
        watch();
        return watcher.hasFullImage() && watcher.dbi() == expected;
    })) << "the watcher's picture never became the replayed session's last";
    EXPECT_TRUE(listedAda) << "the roster never listed the recorded trainee";
    EXPECT_TRUE(sawAdasTool) << "the recorded trainee's tool was never relayed";
    EXPECT_NE(served.waitFor("at the end of the session"), "");
    // Served on after the end: the picture stays the session's last.
    for (int i = 0; i < 100; ++i)
        watcher.poll(1);
    EXPECT_TRUE(watcher.dbi() == expected);
    EXPECT_EQ(served.end(SIGTERM), 0);
}

TEST(ReplayServe, WindowsSeekBackAndForthAndTheVolumeIsTheLogsAtThatTimeBitForBit) {
    const trephine::testing::TempDir dir;
    const LogContents log = trephine::testing::recordTwoStrokes(dir / "two.log");
    ASSERT_TRUE(log.stopped.empty()) << log.stopped;
    const std::vector<uint64_t> times = sessionTimesUs(log.records);
    // Between the strokes: the session time of the first stroke's last tool state.
    size_t tools = 0;
    uint64_t between = 0;
    for (size_t i = 0; i < log.records.size(); ++i)
        if (log.records[i].is<ToolEvent>() && ++tools == 12)
            between = times[i];
    ASSERT_EQ(tools, 24u);
    const Volume start = logStartVolume(log.header, loadVolume);
    auto volumeAt = [&](uint64_t positionUs) {
        SessionReplay replay(log.header, start);
        for (size_t i = 0; i < log.records.size() && times[i] <= positionUs; ++i)
            replay.apply(log.records[i]);
        return replay.volume();
    };
    const Volume middle = volumeAt(between), end = volumeAt(times.back());
    ASSERT_FALSE(middle == end) << "the second stroke drilled nothing";

    ServerConfig base = trephine::testing::loopbackServerConfig("sphere:48");
    SessionServer server(start, replayServerConfig(log.header, base));
    server.serveLog(log.records, 1.0, false);
    trephine::testing::Pumped pumped(server);
    ClientConfig config = namedClientConfig(start, "Watcher", Role::Instructor, 40);
    config.codec = Codec::Raw; // the DBI's depth is then the server's floats, bit for bit
    SessionClient watcher(config);
    // A trainee's window on a replay watches: its drill touches the bone but never cuts.
    SessionClient trainee(namedClientConfig(start, "Eve", Role::Trainee, 32));
    watcher.connect(loopback(server.port()));
    trainee.connect(loopback(server.port()));
    ASSERT_TRUE(pumpUntil({&watcher, &trainee}, [&] {
        return watcher.hasFullImage() && trainee.hasFullImage() && watcher.replay().has_value();
    }));
    EXPECT_FALSE(watcher.replay()->playing) << "served paused until a window plays it";
    EXPECT_EQ(watcher.replay()->positionUs, 0u);
    EXPECT_EQ(watcher.replay()->durationUs, times.back());

    const SurfaceSite top{glm::vec3(0.0f, 0.0f, sphereRadiusMm(48)), glm::vec3(0, 0, 1)};
    for (int i = 0; i < 12; ++i) {
        trainee.sendToolState(burrState(top, i, 12, 2000000));
        trephine::testing::pollAll({&trainee});
    }
    const Camera camera = toCamera(config.view);
    auto shows = [&](const Volume& v, uint32_t seeks) {
        SessionReplay at(log.header, v);
        const Dbi picture = at.render(camera);
        return pumpUntil({&watcher, &trainee}, [&] {
            return server.idle() && watcher.replay() && watcher.replay()->seeks == seeks &&
                   server.volumeSnapshot() == v && watcher.dbi() == picture;
        });
    };
    watcher.controlReplay({ReplayControl::Op::Seek, times.back()});
    EXPECT_TRUE(shows(end, 1)) << "a seek to the end did not reach the log's final volume";
    EXPECT_GT(server.drillingPaused(), 0u);
    watcher.controlReplay({ReplayControl::Op::Seek, between});
    EXPECT_TRUE(shows(middle, 2)) << "a seek back did not rebuild the volume between the strokes";
    EXPECT_EQ(watcher.replay()->positionUs, between);
    EXPECT_TRUE(pumpUntil({&watcher, &trainee}, [&] {
        return std::any_of(watcher.participants().begin(), watcher.participants().end(),
                           [](const auto& p) { return p.second.name == "Ada"; });
    })) << "the recorded trainee is listed again after the rebuild";
    // Played on from there at 100x, it ends on the final volume, paused at the end.
    trainee.controlReplay({ReplayControl::Op::Speed, 0, 100.0f});
    trainee.controlReplay({ReplayControl::Op::Play});
    EXPECT_TRUE(pumpUntil({&watcher, &trainee}, [&] {
        return watcher.replay() && !watcher.replay()->playing &&
               watcher.replay()->positionUs == times.back() && server.idle() &&
               server.volumeSnapshot() == end;
    }));
    EXPECT_EQ(watcher.replay()->speed, 100.0f);
    EXPECT_EQ(server.counters().replayControlsRefused, 0u);
    server.stop();
}

TEST(SessionPolicyReplay, ALiveSessionIgnoresTimelineControlsAndCountsThem) {
    SpherePolicy live;
    SessionPolicy& policy = live.policy;
    ReportBook& book = live.book;
    PolicyOutput out;
    const uint16_t id = policy.connect(kProtocolVersion, 1000, out);
    Hello h;
    h.view.width = h.view.height = 32;
    policy.receive(id, encodeMessage(h), 1000);
    ReplayControl seek{ReplayControl::Op::Seek, 5};
    PolicyOutput o = policy.receive(id, encodeMessage(seek), 2000);
    EXPECT_TRUE(o.replayControls.empty());
    EXPECT_FALSE(o.malformed);
    EXPECT_EQ(book.counter(&ServerCounters::replayControlsRefused), 1u);
}

TEST(ReplayServeCli, ServeOptionsAreCheckedInOneLine) {
    const trephine::testing::TempDir dir;
    const std::string log = dir / "none.log";
    std::ofstream(log) << "x";
    trephine::testing::CommandResult r = trephine::testing::runTrephine(
        dir, "replay " + trephine::testing::shellQuote(log) + " --serve --speed 0");
    EXPECT_NE(r.exitCode, 0);
    EXPECT_NE(r.err.find("--speed"), std::string::npos) << r.err;
    r = trephine::testing::runTrephine(dir, "replay " + trephine::testing::shellQuote(log) +
                                                " --speed 2");
    EXPECT_NE(r.exitCode, 0);
    EXPECT_NE(r.err.find("--serve"), std::string::npos) << r.err;
}

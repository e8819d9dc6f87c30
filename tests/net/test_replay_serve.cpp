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
#include "net/view.h"

#include "libsim/error.h"
#include "libsim/skull.h"
#include "libsim/tool.h"
#include "libsim/volume_io.h"

#include "loopback.h"
#include "test_support.h"

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

using trephine::testing::burrState;
using trephine::testing::Child;
using trephine::testing::loopback;
using trephine::testing::namedClientConfig;
using trephine::testing::pumpUntil;

namespace {

LogRecord record(LogRecord::Kind kind, uint64_t timeUs, uint16_t client = 0) {
    LogRecord r;
    r.kind = kind;
    r.timeUs = timeUs;
    r.client = client;
    return r;
}

template <typename M>
std::vector<M> sentTo(const PolicyOutput& out, uint16_t id) {
    std::vector<M> found;
    for (const PolicyOutput::Message& m : out.messages) {
        if (std::find(m.to.begin(), m.to.end(), id) == m.to.end() ||
            peekMessageType(m.bytes) != uint8_t(M::kType))
            continue;
        M decoded;
        EXPECT_TRUE(decodeMessage(m.bytes, decoded));
        found.push_back(std::move(decoded));
    }
    return found;
}

} // namespace

TEST(ReplayFeed, GivesEachRecordWhenItsTimeComesRoundAtTheSpeed) {
    std::vector<LogRecord> records{
        record(LogRecord::Kind::Hello, 5'000'000, 1), record(LogRecord::Kind::Tool, 5'100'000, 1),
        record(LogRecord::Kind::Tool, 6'000'000, 1),
        // A resumed server's clock starts afresh: the session goes on.
        record(LogRecord::Kind::Resume, 200, 0), record(LogRecord::Kind::Tool, 500'200, 1)};
    EXPECT_EQ(sessionTimesUs(records),
              (std::vector<uint64_t>{0, 100'000, 1'000'000, 1'000'000, 1'500'000}));
    ReplayFeed feed(records, 2.0);
    EXPECT_EQ(feed.durationUs(), 750'000u);
    EXPECT_EQ(feed.due(0).size(), 1u);
    EXPECT_TRUE(feed.due(49'999).empty());
    EXPECT_EQ(feed.due(50'000).size(), 1u);
    const std::vector<LogRecord> next = feed.due(700'000);
    ASSERT_EQ(next.size(), 2u) << "the stroke's end and the resume, not the state after";
    EXPECT_EQ(next[1].kind, LogRecord::Kind::Resume);
    EXPECT_FALSE(feed.done());
    EXPECT_EQ(feed.due(750'000).size(), 1u);
    EXPECT_TRUE(feed.done());
    EXPECT_TRUE(feed.due(10'000'000).empty());
    EXPECT_THROW(ReplayFeed(records, 0.0), Error);
    EXPECT_THROW(ReplayFeed(records, -1.0), Error);
}

TEST(SessionPolicyReplay, RecordedParticipantsAreListedRelayedDrilledAndLeave) {
    const Volume sphere = makeSphere(32);
    ServerConfig config;
    config.volumeName = "sphere:32";
    config.scene = std::make_shared<const Scene>(buildScene(sphere));
    ReportBook book;
    SessionPolicy policy(config, sphere.dims(), sphere.spacing(), book,
                         [](const ToolState&, glm::vec3) { return SessionPolicy::ForceAnswer{}; });
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
        policy.replayed(r, now, o);
        return o;
    };
    LogRecord hello = record(LogRecord::Kind::Hello, 0, 1);
    hello.name = "Ada";
    hello.role = Role::Trainee;
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

    LogRecord join = record(LogRecord::Kind::Join, 0, 1);
    join.sync = Sync::Volume;
    PolicyOutput joined = play(join);
    ASSERT_EQ(joined.events.size(), 1u);
    EXPECT_EQ(joined.events[0].kind, SimEvent::Kind::Join);
    EXPECT_EQ(joined.events[0].client, SessionPolicy::replayedId(1));
    EXPECT_EQ(joined.events[0].sync, Sync::Dbi) << "nobody takes a replayed client's volume";

    LogRecord tool = record(LogRecord::Kind::Tool, 0, 1);
    tool.tool.sequence = 7;
    tool.tool.position = glm::vec3(1, 2, 3);
    tool.tool.drilling = true;
    PolicyOutput drilled = play(tool);
    ASSERT_EQ(drilled.events.size(), 1u);
    EXPECT_EQ(drilled.events[0].kind, SimEvent::Kind::Tool);
    EXPECT_EQ(drilled.events[0].client, SessionPolicy::replayedId(1));
    EXPECT_EQ(drilled.events[0].tool.sequence, 7u);
    EXPECT_EQ(drilled.events[0].arrivedUs, now);
    const auto relays = sentTo<ToolRelay>(drilled, watcher);
    ASSERT_EQ(relays.size(), 1u);
    EXPECT_EQ(relays[0].clientId, SessionPolicy::replayedId(1));
    EXPECT_EQ(relays[0].tool.position, glm::vec3(1, 2, 3));

    // A recorded instructor's mark, then its removal by the log's id.
    LogRecord mark = record(LogRecord::Kind::Mark, 0, 2);
    mark.op = Annotate::Op::Add;
    mark.mark = {41, 2, glm::vec3(4, 5, 6), "here"};
    play(mark);
    ASSERT_EQ(policy.marks().size(), 1u);
    EXPECT_EQ(policy.marks().begin()->second.label, "here");
    EXPECT_EQ(policy.marks().begin()->second.author, SessionPolicy::replayedId(2));
    mark.op = Annotate::Op::Remove;
    mark.mark.id = 41;
    play(mark);
    EXPECT_TRUE(policy.marks().empty());

    PolicyOutput left = play(record(LogRecord::Kind::Leave, 0, 1));
    ASSERT_EQ(left.events.size(), 1u);
    EXPECT_EQ(left.events[0].kind, SimEvent::Kind::Leave);
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
        if (r.kind == LogRecord::Kind::Hello && r.name == "Ada")
            adaId = r.client;
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
    EXPECT_NE(served.waitFor("the replay has finished"), "");
    // Served on after the end: the picture stays the session's last.
    for (int i = 0; i < 100; ++i)
        watcher.poll(1);
    EXPECT_TRUE(watcher.dbi() == expected);
    EXPECT_EQ(served.end(SIGTERM), 0);
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

// The session policy on its own: no ENet, no threads, no sleeps. A test plays the network thread:
// it connects peers, hands it messages and advances time, and reads what the policy answers
// (messages, disconnects, events for the simulation) and what it records in the report.
#include "net/session_policy.h"

#include "libsim/skull.h"
#include "libsim/tool.h"
#include "net/view.h"

#include "policy_output.h"

#include <gtest/gtest.h>

#include <optional>
#include <span>

using namespace trephine;
using namespace trephine::net;
using trephine::testing::sentTo;

namespace {

constexpr uint64_t kStartUs = 1'000'000;

template <typename E>
size_t eventsOf(const PolicyOutput& out) {
    return size_t(std::count_if(out.events.begin(), out.events.end(),
                                [&](const LogRecord& e) { return e.is<E>(); }));
}

bool disconnected(const PolicyOutput& out, uint16_t id, RefuseReason why) {
    return std::any_of(out.disconnects.begin(), out.disconnects.end(),
                       [&](const auto& d) { return d.client == id && d.data == uint32_t(why); });
}

ViewSpec smallView() {
    ViewSpec v;
    v.width = v.height = 32;
    return v;
}

// A policy over a 32^3 sphere whose force at a tool state is its position (so a test can tell
// which state a model answers) and is done 7 us after it arrived.
struct PolicyRig {
    ServerConfig config;
    ReportBook book;
    std::optional<SessionPolicy> policy;
    uint64_t now = kStartUs;
    int forces = 0;

    explicit PolicyRig(ServerConfig c = {}) : config(std::move(c)) {
        config.volumeName = "sphere:32";
        const Volume sphere = makeSphere(32);
        config.scene = std::make_shared<const Scene>(buildScene(sphere));
        policy.emplace(config, sphere.dims(), sphere.spacing(), book,
                       [this](const ToolState& t, glm::vec3) {
                           ++forces;
                           SessionPolicy::ForceAnswer a;
                           a.force.force = t.position;
                           a.force.contact = true;
                           a.computeUs = 5;
                           a.doneUs = now + 7;
                           return a;
                       });
    }
    SessionPolicy& p() { return *policy; }
    template <typename M>
    PolicyOutput send(uint16_t id, M m) {
        return p().receive(id, encodeMessage(m), now);
    }
    // Connects and says hello; returns the id and the output of the hello.
    uint16_t join(const std::string& name, Role role, PolicyOutput* hello = nullptr,
                  Sync sync = Sync::Dbi) {
        PolicyOutput out;
        const uint16_t id = p().connect(kProtocolVersion, now, out);
        EXPECT_NE(id, 0);
        Hello h;
        h.name = name;
        h.role = role;
        h.sync = sync;
        h.view = smallView();
        PolicyOutput answer = send(id, h);
        if (hello)
            *hello = std::move(answer);
        return id;
    }
    PolicyOutput update() {
        PolicyOutput out;
        p().update(now, out);
        return out;
    }
    ServerCounters counters() const {
        return book.read([](const ServerReport& r) { return r.counters; });
    }
    PeerReport peer(uint16_t id) const {
        return book.read([&](const ServerReport& r) { return r.peers.at(id); });
    }
};

ToolState toolAt(glm::vec3 position, uint32_t sequence, bool drilling = true) {
    ToolState t;
    t.sequence = sequence;
    t.clientTimeUs = 1000 * uint64_t(sequence);
    t.toolKind = uint8_t(ToolKind::Burr);
    t.diameterMm = 4.0f;
    t.position = position;
    t.speed = 1.0f;
    t.drilling = drilling;
    return t;
}

} // namespace

TEST(SessionPolicy, AHelloIsWelcomedListedAndJoinsTheSimulation) {
    PolicyRig rig;
    PolicyOutput hello;
    const uint16_t ada = rig.join("Ada", Role::Trainee, &hello);
    const auto welcome = sentTo<Welcome>(hello, ada);
    ASSERT_EQ(welcome.size(), 1u);
    EXPECT_EQ(welcome[0].clientId, ada);
    EXPECT_EQ(welcome[0].serverTimeUs, rig.now);
    EXPECT_EQ(welcome[0].volumeDims, glm::ivec3(32));
    EXPECT_EQ(welcome[0].volumeName, "sphere:32");
    const auto scene = sentTo<Scene>(hello, ada);
    ASSERT_EQ(scene.size(), 1u) << "the scene follows the welcome";
    EXPECT_EQ(scene[0], *rig.config.scene);
    ASSERT_EQ(eventsOf<JoinEvent>(hello), 1u);
    EXPECT_EQ(hello.events[0].as<JoinEvent>()->inFlight, rig.p().inFlight(ada))
        << "the outbox counts its bytes";
    EXPECT_TRUE(sentTo<Annotations>(hello, ada).empty()) << "no marks, no list";

    // The roster goes at the next pass, at once for a join, to everyone listed.
    const uint16_t cho = rig.join("Dr. Cho", Role::Instructor);
    PolicyOutput pass = rig.update();
    for (uint16_t id : {ada, cho}) {
        const auto roster = sentTo<Participants>(pass, id);
        ASSERT_EQ(roster.size(), 1u);
        ASSERT_EQ(roster[0].list.size(), 2u);
        EXPECT_EQ(roster[0].list[0].name, "Ada");
        EXPECT_EQ(roster[0].list[1].role, Role::Instructor);
    }
    EXPECT_TRUE(rig.update().messages.empty()) << "sent once";
    EXPECT_EQ(rig.counters().clients, 2u);
    EXPECT_TRUE(rig.peer(cho).participating());
}

TEST(SessionPolicy, AnotherVersionAndOneClientTooManyAreRefused) {
    ServerConfig c;
    c.maxClients = 1;
    PolicyRig rig(c);
    PolicyOutput out;
    EXPECT_EQ(rig.p().connect(kProtocolVersion + 1, rig.now, out), 0);
    ASSERT_EQ(out.disconnects.size(), 1u);
    EXPECT_EQ(out.disconnects[0].data, uint32_t(RefuseReason::Version) | (kProtocolVersion << 8));
    rig.join("one", Role::Trainee);
    out = {};
    EXPECT_EQ(rig.p().connect(kProtocolVersion, rig.now, out), 0);
    EXPECT_TRUE(disconnected(out, 0, RefuseReason::ServerFull));
    EXPECT_EQ(rig.counters().refusedFull, 1u);
}

// A connection that never says hello is closed after the hello timeout (time passed in), and its
// slot goes to the next.
TEST(SessionPolicy, AConnectionThatNeverSaysHelloIsClosedAndFreesItsSlot) {
    ServerConfig c;
    c.maxClients = 1;
    c.helloTimeoutS = 0.3f;
    PolicyRig rig(c);
    PolicyOutput out;
    const uint16_t silent = rig.p().connect(kProtocolVersion, rig.now, out);
    ASSERT_NE(silent, 0);
    rig.now += 300000;
    EXPECT_TRUE(rig.update().disconnects.empty()) << "not yet";
    rig.now += 1;
    out = rig.update();
    EXPECT_TRUE(disconnected(out, silent, RefuseReason::BadHello));
    EXPECT_EQ(rig.counters().helloTimeouts, 1u);
    EXPECT_FALSE(rig.p().live(silent));
    out = {};
    rig.p().disconnect(silent, rig.now, out);
    EXPECT_EQ(eventsOf<LeaveEvent>(out), 1u);
    out = {};
    EXPECT_NE(rig.p().connect(kProtocolVersion, rig.now, out), 0) << "the slot is free";
    EXPECT_EQ(rig.counters().refusedFull, 0u);
}

TEST(SessionPolicy, MalformedMessagesAreCountedAndAPersistentOffenderSentAway) {
    ServerConfig c;
    c.malformedLimit = 3;
    PolicyRig rig(c);
    PolicyOutput out;
    const uint16_t id = rig.p().connect(kProtocolVersion, rig.now, out);
    // Anything but a hello first is malformed.
    EXPECT_TRUE(rig.send(id, Ping{1}).malformed);
    rig.join("good", Role::Trainee);
    Hello h;
    h.view = smallView();
    EXPECT_FALSE(rig.send(id, h).malformed);
    const std::vector<uint8_t> unknown = {200, 1, 2};
    Ping ping{42};
    std::vector<uint8_t> truncated = encodeMessage(ping);
    truncated.pop_back();
    ToolState huge = toolAt({0, 0, 0}, 1);
    huge.diameterMm = 12.0f; // on the wire range, but no burr is that large
    EXPECT_TRUE(rig.p().receive(id, unknown, rig.now).malformed);
    out = rig.p().receive(id, truncated, rig.now);
    EXPECT_TRUE(out.malformed);
    EXPECT_TRUE(out.disconnects.empty()) << "three, the limit: only dropped";
    out = rig.send(id, huge);
    EXPECT_TRUE(out.malformed);
    EXPECT_EQ(rig.forces, 0) << "no force for an impossible tool";
    EXPECT_TRUE(disconnected(out, id, RefuseReason::Malformed)) << "the fourth";
    EXPECT_EQ(rig.counters().malformedKicks, 1u);
    EXPECT_EQ(rig.peer(id).malformed, 4u);
    EXPECT_TRUE(rig.peer(id).kicked);
    EXPECT_TRUE(rig.p().receive(id, unknown, rig.now).messages.empty()) << "no longer heard";
}

// Each tool state is answered at once with the force at its pose, relayed as a HapticRelay to
// every instructor but its own client, relayed as a ToolRelay to everyone else, and handed to the
// simulation.
TEST(SessionPolicy, AToolStateIsAnsweredRelayedAndQueued) {
    PolicyRig rig;
    const uint16_t ada = rig.join("Ada", Role::Trainee);
    const uint16_t bob = rig.join("Bob", Role::Trainee);
    const uint16_t cho = rig.join("Dr. Cho", Role::Instructor);
    const uint16_t lee = rig.join("Dr. Lee", Role::Instructor);
    ToolState t = toolAt({1.0f, 2.0f, 3.0f}, 5);
    t.orientation = glm::quat(1.25f, 0.0f, 0.0f, 0.0f); // scaled: taken as the unit rotation
    const PolicyOutput out = rig.send(ada, t);
    const auto model = sentTo<HapticModel>(out, ada);
    ASSERT_EQ(model.size(), 1u);
    EXPECT_EQ(model[0].toolSequence, 5u);
    EXPECT_EQ(model[0].force, t.position);
    EXPECT_EQ(model[0].serverReceivedUs, rig.now);
    EXPECT_EQ(model[0].serverSentUs, rig.now + 7);
    EXPECT_TRUE(out.flush) << "the answer leaves at once";
    for (uint16_t id : {cho, lee}) {
        const auto relay = sentTo<HapticRelay>(out, id);
        ASSERT_EQ(relay.size(), 1u) << id;
        EXPECT_EQ(relay[0].clientId, ada);
        EXPECT_EQ(relay[0].model.force, model[0].force);
    }
    EXPECT_TRUE(sentTo<HapticRelay>(out, bob).empty()) << "trainees see no one's forces";
    for (uint16_t id : {bob, cho, lee})
        EXPECT_EQ(sentTo<ToolRelay>(out, id).size(), 1u) << id;
    EXPECT_TRUE(sentTo<ToolRelay>(out, ada).empty()) << "not its own tool";
    ASSERT_EQ(eventsOf<ToolEvent>(out), 1u);
    EXPECT_EQ(out.events[0].timeUs, rig.now);
    EXPECT_FLOAT_EQ(glm::length(out.events[0].as<ToolEvent>()->tool.orientation), 1.0f);
    const ServerCounters c = rig.counters();
    EXPECT_EQ(c.hapticModelsSent, 1u);
    EXPECT_EQ(c.hapticRelaysSent, 2u);
    EXPECT_EQ(rig.peer(ada).toolStates, 1u);
    EXPECT_EQ(rig.book.read([](const ServerReport& r) { return r.hapticServiceUs.max(); }), 7.0);

    // An instructor's own tool is answered to it and relayed to the other instructor only.
    const PolicyOutput mine = rig.send(cho, toolAt({0, 0, 0}, 1, false));
    EXPECT_EQ(sentTo<HapticModel>(mine, cho).size(), 1u);
    EXPECT_EQ(sentTo<HapticRelay>(mine, lee).size(), 1u);
    EXPECT_TRUE(sentTo<HapticRelay>(mine, cho).empty());
    EXPECT_EQ(rig.counters().hapticRelaysSent, 3u);

    ServerConfig quiet;
    quiet.hapticModels = false;
    PolicyRig off(quiet);
    const uint16_t solo = off.join("solo", Role::Trainee);
    const PolicyOutput none = off.send(solo, t);
    EXPECT_TRUE(sentTo<HapticModel>(none, solo).empty());
    EXPECT_EQ(eventsOf<ToolEvent>(none), 1u);
    EXPECT_EQ(off.forces, 0);
}

// Take-overs: an instructor holds one trainee at a time, a trainee one instructor; the tool of a
// held trainee, or of an instructor holding nobody, reaches the simulation with drilling cleared.
TEST(SessionPolicy, TakeOversPauseTheRightDrillsAndAreListed) {
    PolicyRig rig;
    const uint16_t ada = rig.join("Ada", Role::Trainee);
    const uint16_t cho = rig.join("Dr. Cho", Role::Instructor);
    const uint16_t lee = rig.join("Dr. Lee", Role::Instructor);
    rig.update();
    uint32_t sequence = 0;
    auto drills = [&](uint16_t id) {
        const PolicyOutput out = rig.send(id, toolAt({0, 0, 0}, ++sequence));
        return out.events.at(0).as<ToolEvent>()->tool.drilling;
    };
    EXPECT_TRUE(drills(ada));
    EXPECT_FALSE(drills(lee)) << "an instructor holding nobody points only";
    EXPECT_EQ(rig.counters().drillingPaused, 1u);

    EXPECT_FALSE(rig.send(cho, TakeOver{ada}).malformed);
    rig.now += kRosterIntervalUs;
    const auto roster = sentTo<Participants>(rig.update(), ada);
    ASSERT_EQ(roster.size(), 1u);
    EXPECT_EQ(roster[0].list[0].takenOverBy, cho);
    EXPECT_FALSE(drills(ada)) << "held: paused";
    EXPECT_TRUE(drills(cho)) << "the holder cuts";

    // Refused, counted: another instructor's take-over of a held trainee, a trainee's, one of an
    // instructor, one of nobody there.
    rig.send(lee, TakeOver{ada});
    rig.send(ada, TakeOver{ada});
    rig.send(lee, TakeOver{cho});
    rig.send(lee, TakeOver{999});
    EXPECT_EQ(rig.counters().takeOversRefused, 4u);
    EXPECT_FALSE(drills(ada));

    // Handed back when the holder leaves.
    PolicyOutput out;
    rig.p().disconnect(cho, rig.now, out);
    EXPECT_TRUE(drills(ada));
    rig.send(lee, TakeOver{ada});
    EXPECT_FALSE(drills(ada));
    rig.send(lee, TakeOver{0});
    EXPECT_TRUE(drills(ada)) << "handed back";
}

// An instructor editing marks as fast as it can send: everyone gets the whole list at most once
// every kAnnotationsIntervalUs, and the last list is right; trainees' edits are refused.
TEST(SessionPolicy, MarkEditsAsFastAsTheyComeGoOutPaced) {
    PolicyRig rig;
    const uint16_t cho = rig.join("Dr. Cho", Role::Instructor);
    const uint16_t ada = rig.join("Ada", Role::Trainee);
    rig.update();
    Annotate add;
    add.op = Annotate::Op::Add;
    add.position = {1.0f, 2.0f, 3.0f};
    add.label = "m";
    Annotate remove;
    remove.op = Annotate::Op::Remove;
    constexpr int kEdits = 1000;
    const uint64_t t0 = rig.now;
    int lists = 0;
    std::optional<Annotations> last;
    auto pass = [&] {
        const auto sent = sentTo<Annotations>(rig.update(), ada);
        lists += int(sent.size());
        if (!sent.empty())
            last = sent.back();
    };
    for (int i = 0; i < kEdits; ++i) { // one edit every 100 us, the loop passing after each
        rig.now += 100;
        if (i % 2 == 0) {
            rig.send(cho, add);
        } else {
            remove.id = uint32_t(i / 2 + 1); // the mark just added (ids count from 1)
            rig.send(cho, remove);
        }
        pass();
    }
    add.label = "last";
    rig.send(cho, add);
    rig.now += kAnnotationsIntervalUs;
    pass();
    const double intervals = double(rig.now - t0) / double(kAnnotationsIntervalUs);
    EXPECT_GE(lists, 1);
    EXPECT_LE(double(lists), intervals + 1) << "one list per edit is not paced";
    ASSERT_TRUE(last);
    ASSERT_EQ(last->list.size(), 1u);
    EXPECT_EQ(last->list[0].label, "last");
    EXPECT_EQ(last->list[0].author, cho);

    rig.send(ada, add);
    EXPECT_EQ(rig.counters().annotationsRefused, 1u) << "a trainee's edit";
    // A newcomer gets the list after its welcome.
    PolicyOutput hello;
    const uint16_t lee = rig.join("Dr. Lee", Role::Instructor, &hello);
    ASSERT_EQ(sentTo<Annotations>(hello, lee).size(), 1u);
    EXPECT_EQ(sentTo<Annotations>(hello, lee)[0].list, last->list);
    // Adds beyond kMaxAnnotations are refused.
    for (int i = 1; i < kMaxAnnotations; ++i)
        rig.send(cho, add);
    EXPECT_EQ(rig.p().marks().size(), size_t(kMaxAnnotations));
    rig.send(cho, add);
    EXPECT_EQ(rig.counters().annotationsRefused, 2u);
    Annotate clear;
    clear.op = Annotate::Op::Clear;
    rig.send(lee, clear);
    EXPECT_TRUE(rig.p().marks().empty());
}

// A client switching designs as fast as it can send: its switches reach the simulation at most
// every kSyncSwitchIntervalUs, as its latest mode, and the roster at most every
// kRosterIntervalUs; while a switch waits the policy says so (the server is not idle).
TEST(SessionPolicy, ModeSwitchesAsFastAsTheyComeArePaced) {
    PolicyRig rig;
    const uint16_t listener = rig.join("listener", Role::Trainee);
    const uint16_t switcher = rig.join("switcher", Role::Trainee);
    rig.update();
    const uint64_t t0 = rig.now;
    size_t switches = 0, rosters = 0;
    std::optional<Participants> lastRoster;
    std::optional<SyncEvent> lastSwitch;
    auto take = [&](const PolicyOutput& out) {
        switches += eventsOf<SyncEvent>(out);
        for (const LogRecord& e : out.events)
            if (const SyncEvent* s = e.as<SyncEvent>())
                lastSwitch = *s;
        const auto r = sentTo<Participants>(out, listener);
        rosters += r.size();
        if (!r.empty())
            lastRoster = r.back();
    };
    constexpr int kSwitches = 300;
    for (int i = 0; i < kSwitches; ++i) { // one every 3 ms, the loop passing after each
        rig.now += 3000;
        SyncMode m;
        m.sync = i % 2 == 0 ? Sync::Volume : Sync::Dbi; // the last one (odd) is DBI
        m.volumeCodec = Codec::Lz4;
        take(rig.send(switcher, m));
        take(rig.update());
    }
    EXPECT_TRUE(rig.p().switchWaiting()) << "the last switch waits its turn";
    rig.now += kSyncSwitchIntervalUs;
    take(rig.update());
    EXPECT_FALSE(rig.p().switchWaiting());
    const double seconds = double(rig.now - t0) * 1e-6;
    EXPECT_LE(double(switches), seconds / (double(kSyncSwitchIntervalUs) * 1e-6) + 2);
    EXPECT_LE(double(rosters), seconds / (double(kRosterIntervalUs) * 1e-6) + 2);
    EXPECT_LT(rosters, size_t(kSwitches) / 4);
    ASSERT_TRUE(lastSwitch && lastRoster);
    EXPECT_EQ(lastSwitch->sync, Sync::Dbi) << "the latest mode wins";
    EXPECT_EQ(lastRoster->list.at(1).sync, Sync::Dbi);
    EXPECT_EQ(rig.peer(switcher).syncSwitches, uint64_t(kSwitches));

    // The mode and codec it already has: nothing at all.
    SyncMode same;
    same.sync = Sync::Dbi;
    same.volumeCodec = Codec::Lz4;
    rig.now += kSyncSwitchIntervalUs;
    EXPECT_TRUE(rig.send(switcher, same).events.empty());
    EXPECT_FALSE(rig.p().switchWaiting());
    EXPECT_EQ(rig.peer(switcher).syncSwitches, uint64_t(kSwitches));
}

// Views over maxViewPixels: a hello is refused (BadHello) before it is listed; a view request is
// dropped and counted, not malformed, and the peer keeps its session.
TEST(SessionPolicy, ViewsOverTheLimitAreRefused) {
    ServerConfig c;
    c.maxViewPixels = 64 * 64;
    PolicyRig rig(c);
    const uint16_t ok = rig.join("ok", Role::Trainee);
    PolicyOutput out;
    const uint16_t big = rig.p().connect(kProtocolVersion, rig.now, out);
    Hello h;
    h.view.width = h.view.height = 65;
    out = rig.send(big, h);
    EXPECT_TRUE(disconnected(out, big, RefuseReason::BadHello));
    EXPECT_TRUE(out.events.empty());
    const auto roster = sentTo<Participants>(rig.update(), ok);
    ASSERT_EQ(roster.size(), 1u);
    EXPECT_EQ(roster[0].list.size(), 1u) << "never listed";

    ViewRequest r;
    r.requestId = 1;
    r.view.width = r.view.height = 100;
    out = rig.send(ok, r);
    EXPECT_FALSE(out.malformed);
    EXPECT_TRUE(out.events.empty());
    EXPECT_EQ(rig.counters().viewsRefused, 1u);
    EXPECT_EQ(rig.peer(ok).viewsRefused, 1u);
    r.view.width = r.view.height = 64;
    out = rig.send(ok, r);
    ASSERT_EQ(eventsOf<ViewEvent>(out), 1u);
    EXPECT_EQ(out.events[0].as<ViewEvent>()->viewId, 1u);
    EXPECT_TRUE(rig.p().live(ok));
}

TEST(SessionPolicy, APingIsAnsweredWithTheServerTime) {
    PolicyRig rig;
    const uint16_t id = rig.join("p", Role::Trainee);
    rig.now += 1234;
    const auto pong = sentTo<Pong>(rig.send(id, Ping{42}), id);
    ASSERT_EQ(pong.size(), 1u);
    EXPECT_EQ(pong[0].clientTimeUs, 42u);
    EXPECT_EQ(pong[0].serverTimeUs, rig.now);
}

// Stopping: everyone is told Shutdown and counts as gone in the report from then on.
TEST(SessionPolicy, GoodbyeSendsEveryoneAwayAndTheReportListsNoneConnected) {
    PolicyRig rig;
    const uint16_t a = rig.join("a", Role::Trainee);
    const uint16_t b = rig.join("b", Role::Instructor);
    PolicyOutput out;
    rig.p().goodbye(rig.now, out);
    EXPECT_TRUE(disconnected(out, a, RefuseReason::Shutdown));
    EXPECT_TRUE(disconnected(out, b, RefuseReason::Shutdown));
    EXPECT_FALSE(rig.peer(a).participating());
    EXPECT_EQ(rig.book.read([](const ServerReport& r) { return r.modeTotals(Sync::Dbi).clients; }),
              0u);
}

TEST(Pacer, GoesAtOnceThenAtMostOnceAnIntervalAndUrgentAtTheNextPass) {
    Pacer p(100);
    EXPECT_FALSE(p.due(0)) << "nothing marked";
    p.mark();
    EXPECT_TRUE(p.due(5)) << "the first goes at once";
    p.mark();
    EXPECT_FALSE(p.due(50));
    EXPECT_TRUE(p.pending());
    EXPECT_TRUE(p.due(105));
    EXPECT_FALSE(p.pending());
    p.mark(true);
    EXPECT_TRUE(p.due(106)) << "urgent";
}

// With codes the role is the proven code's (net/session_gate.h): a hello claiming the instructor
// from a peer that proved the trainee code joins as a trainee, and its instructor's messages are
// refused as a trainee's.
TEST(SessionPolicy, AProvenRoleReplacesTheHellos) {
    PolicyRig rig;
    PolicyOutput out;
    const uint16_t id = rig.p().connect(kProtocolVersion, rig.now, out);
    rig.p().authenticate(id, Role::Trainee);
    Hello h;
    h.name = "Mallory";
    h.role = Role::Instructor;
    h.view = smallView();
    out = rig.send(id, h);
    const std::vector<Participants> rosters = [&] {
        PolicyOutput later;
        rig.p().update(rig.now, later);
        return sentTo<Participants>(later, id);
    }();
    ASSERT_EQ(rosters.size(), 1u);
    ASSERT_EQ(rosters[0].list.size(), 1u);
    EXPECT_EQ(rosters[0].list[0].role, Role::Trainee);
    rig.send(id, Annotate{Annotate::Op::Clear, 0, {}, ""});
    EXPECT_EQ(rig.book.counter(&ServerCounters::annotationsRefused), 1u);
    // And a trainee's Remove is refused, not applied.
    const uint16_t other = rig.join("Ada", Role::Trainee);
    out = rig.send(id, Remove{Remove::Op::Remove, other});
    EXPECT_TRUE(out.removed.empty());
    EXPECT_TRUE(out.disconnects.empty());
    EXPECT_EQ(rig.book.read([](const ServerReport& r) { return r.security.removalsRefused; }), 1u);
}

// An instructor's Remove sends the participant away with its reason and names it for the gate;
// letting the removed rejoin is passed on too. Itself, or someone not listed, it cannot remove.
TEST(SessionPolicy, AnInstructorsRemoveSendsAParticipantAway) {
    PolicyRig rig;
    const uint16_t cho = rig.join("Dr. Cho", Role::Instructor);
    const uint16_t ada = rig.join("Ada", Role::Trainee);
    PolicyOutput out = rig.send(cho, Remove{Remove::Op::Remove, cho});
    EXPECT_TRUE(out.removed.empty());
    out = rig.send(cho, Remove{Remove::Op::Remove, 999});
    EXPECT_TRUE(out.removed.empty());
    out = rig.send(cho, Remove{Remove::Op::Remove, ada});
    EXPECT_EQ(out.removed, std::vector<uint16_t>{ada});
    EXPECT_TRUE(disconnected(out, ada, RefuseReason::Removed));
    EXPECT_FALSE(rig.p().live(ada));
    out = rig.send(cho, Remove{Remove::Op::AllowRejoin, 0});
    EXPECT_TRUE(out.allowRejoin);
    EXPECT_FALSE(out.malformed);
}

// A sealed message that fails to open (forged, replayed: the gate drops it) counts as malformed:
// a peer that keeps sending them is sent away like one sending malformed messages.
TEST(SessionPolicy, RejectedMessagesCountTowardTheMalformedLimit) {
    ServerConfig c;
    c.malformedLimit = 3;
    PolicyRig rig(c);
    const uint16_t ada = rig.join("Ada", Role::Trainee);
    for (int i = 0; i < 3; ++i) {
        const PolicyOutput out = rig.p().reject(ada, rig.now);
        EXPECT_TRUE(out.malformed);
        EXPECT_TRUE(out.disconnects.empty());
    }
    const PolicyOutput out = rig.p().reject(ada, rig.now);
    EXPECT_TRUE(disconnected(out, ada, RefuseReason::Malformed));
    EXPECT_FALSE(rig.p().live(ada));
    EXPECT_EQ(rig.counters().malformedKicks, 1u);
}

// The defaults take a classroom: 64 trainees at the default 500 x 500 view, and their
// instructors up to maxClients, each welcomed (the views' total has room for them all).
TEST(SessionPolicy, AClassroomOf64JoinsWithTheDefaults) {
    PolicyRig rig;
    std::vector<uint16_t> ids;
    const int places = int(ServerConfig{}.maxClients);
    ASSERT_GE(places, 65);
    for (int i = 0; i < places; ++i) {
        PolicyOutput out;
        const uint16_t id = rig.p().connect(kProtocolVersion, rig.now, out);
        ASSERT_NE(id, 0) << "participant " << i;
        Hello h;
        h.name = "p" + std::to_string(i);
        h.role = i >= 64 ? Role::Instructor : Role::Trainee;
        PolicyOutput answer = rig.send(id, h);
        ASSERT_EQ(sentTo<Welcome>(answer, id).size(), 1u) << "participant " << i;
        ids.push_back(id);
    }
    for (uint16_t id : ids)
        EXPECT_TRUE(rig.p().admitted(id));
    EXPECT_EQ(rig.counters().refusedFull, 0u);
}

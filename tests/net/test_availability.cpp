// Availability without sockets: the admission rules (net/admission.h), the per-peer budgets and
// names (net/budgets.h), the policy's places, idle timeouts and view budget, and the simulation
// step's work shared fairly among peers (net/fair_share.h). Time is passed in; nothing sleeps.
#include "net/admission.h"
#include "net/budgets.h"
#include "net/codec.h"
#include "net/fair_share.h"
#include "net/secure_channel.h"
#include "net/send_passes.h"
#include "net/session_codes.h"
#include "net/session_gate.h"
#include "net/session_policy.h"
#include "net/sim_step.h"

#include "libsim/skull.h"
#include "net/view.h"

#include "counting_renderer.h"
#include "gate_client.h"
#include "manual_executor.h"

#include <enet/protocol.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <cstring>
#include <optional>
#include <thread>

using namespace trephine;
using namespace trephine::net;
using trephine::testing::CountingRenderer;

namespace {

constexpr uint64_t kStartUs = 1'000'000;
constexpr uint64_t kLater = kStartUs + 2'000'000; // every peer of kStartUs's old enough to displace

// An ENet CONNECT datagram as a client sends it (header with sent time, then the command).
std::vector<uint8_t> connectDatagram(uint32_t connectId = 0x1234) {
    std::vector<uint8_t> d(4 + sizeof(ENetProtocolConnect), 0);
    const uint16_t peer =
        uint16_t(ENET_PROTOCOL_MAXIMUM_PEER_ID) | uint16_t(ENET_PROTOCOL_HEADER_FLAG_SENT_TIME);
    d[0] = uint8_t(peer >> 8);
    d[1] = uint8_t(peer);
    ENetProtocolConnect c{};
    c.header.command =
        uint8_t(ENET_PROTOCOL_COMMAND_CONNECT) | uint8_t(ENET_PROTOCOL_COMMAND_FLAG_ACKNOWLEDGE);
    c.channelCount = ENET_HOST_TO_NET_32(5);
    c.connectID = connectId;
    std::memcpy(d.data() + 4, &c, sizeof c);
    return d;
}

bool disconnected(const PolicyOutput& out, uint16_t id, RefuseReason why) {
    return std::any_of(out.disconnects.begin(), out.disconnects.end(),
                       [&](const auto& d) { return d.client == id && d.data == uint32_t(why); });
}

template <typename E>
size_t eventsOf(const PolicyOutput& out) {
    return size_t(std::count_if(out.events.begin(), out.events.end(),
                                [&](const LogRecord& e) { return e.is<E>(); }));
}

ViewSpec viewOf(int w, int h) {
    ViewSpec v = toViewSpec(cameraPreset("top", makeSphere(32), {w, h}));
    return v;
}

struct PolicyRig {
    ServerConfig config;
    ReportBook book;
    std::optional<SessionPolicy> policy;
    uint64_t now = kStartUs;

    explicit PolicyRig(ServerConfig c = {}) : config(std::move(c)) {
        const Volume sphere = makeSphere(32);
        config.scene = std::make_shared<const Scene>(buildScene(sphere));
        policy.emplace(config, sphere.dims(), sphere.spacing(), book,
                       [this](const ToolState&, glm::vec3) {
                           SessionPolicy::ForceAnswer a;
                           a.doneUs = now;
                           return a;
                       });
    }
    SessionPolicy& p() { return *policy; }
    template <typename M>
    PolicyOutput send(uint16_t id, M m) {
        return p().receive(id, encodeMessage(m), now);
    }
    uint16_t connect() {
        PolicyOutput out;
        return p().connect(kProtocolVersion, now, out);
    }
    PolicyOutput hello(uint16_t id, const std::string& name, ViewSpec view = viewOf(32, 32)) {
        Hello h;
        h.name = name;
        h.view = view;
        return send(id, h);
    }
    uint16_t join(const std::string& name, ViewSpec view = viewOf(32, 32)) {
        const uint16_t id = connect();
        EXPECT_NE(id, 0);
        hello(id, name, view);
        return id;
    }
    PolicyOutput update() {
        PolicyOutput out;
        p().update(now, out);
        return out;
    }
    AvailabilityCounters availability() const {
        return book.read([](const ServerReport& r) { return r.availability; });
    }
    ServerCounters counters() const {
        return book.read([](const ServerReport& r) { return r.counters; });
    }
    std::vector<std::string> roster(const PolicyOutput& out) const {
        std::vector<std::string> names;
        for (const auto& m : out.messages) {
            Participants list;
            if (peekMessageType(m.bytes) == uint8_t(MessageType::Participants) &&
                decodeMessage(m.bytes, list)) {
                names.clear();
                for (const auto& e : list.list)
                    names.push_back(e.name);
            }
        }
        return names;
    }
};

} // namespace

// [SECTION] admission rules

TEST(Admission, AConnectDatagramIsToldFromEveryOtherDatagram) {
    EXPECT_TRUE(isEnetConnect(connectDatagram()));
    std::vector<uint8_t> toPeer = connectDatagram();
    toPeer[1] = 3; // addressed to peer 3: a command within a connection
    EXPECT_FALSE(isEnetConnect(toPeer));
    std::vector<uint8_t> ping = connectDatagram();
    ping[4] = ENET_PROTOCOL_COMMAND_PING;
    EXPECT_FALSE(isEnetConnect(ping));
    std::vector<uint8_t> cut = connectDatagram();
    cut.resize(10);
    EXPECT_FALSE(isEnetConnect(cut)) << "too short to be a connect";
    EXPECT_FALSE(isEnetConnect({}));
}

TEST(Admission, EachAddressOpensABurstThenConnectionsAtItsRate) {
    ConnectBuckets buckets(4.0, 3.0);
    const uint32_t a = 0x0100007f, b = 0x0200007f;
    for (int i = 0; i < 3; ++i)
        EXPECT_TRUE(buckets.take(a, kStartUs)) << i;
    EXPECT_FALSE(buckets.take(a, kStartUs)) << "burst spent";
    EXPECT_TRUE(buckets.take(b, kStartUs)) << "another address has its own bucket";
    EXPECT_FALSE(buckets.take(a, kStartUs + 240000)) << "0.96 of a token after 0.24 s";
    EXPECT_TRUE(buckets.take(a, kStartUs + 250000)) << "one token after 0.25 s at 4/s";
    EXPECT_FALSE(buckets.take(a, kStartUs + 250000));
    // Idle for long, the bucket holds the burst, not more.
    for (int i = 0; i < 3; ++i)
        EXPECT_TRUE(buckets.take(a, kStartUs + 60'000'000)) << i;
    EXPECT_FALSE(buckets.take(a, kStartUs + 60'000'000));
}

TEST(Admission, AConnectIsJudgedByAddressThenSlotsThenRate) {
    AdmissionLimits limits;
    limits.waitingSlots = 4;
    limits.waitingPerAddress = 2;
    limits.connectsPerS = 1.0;
    limits.connectBurst = 1.0;
    ConnectBuckets buckets(limits.connectsPerS, limits.connectBurst);
    const std::vector<WaitingPeer> some{{7, 10}, {8, 20}};
    const std::vector<WaitingPeer> busy{{7, 10}, {7, 20}};
    const std::vector<WaitingPeer> even{{7, 10}, {8, 20}, {9, 30}, {10, 40}};
    EXPECT_EQ(judgeConnect(limits, buckets, 7, busy, kStartUs).verdict,
              ConnectVerdict::AddressBusy);
    EXPECT_EQ(judgeConnect(limits, buckets, 7, even, kStartUs).verdict, ConnectVerdict::PoolFull)
        << "every address holds one: 7 holds no fewer than any";
    EXPECT_EQ(judgeConnect(limits, buckets, 11, even, kLater).verdict, ConnectVerdict::PoolFull)
        << "every address holds one: a newcomer's share would be no smaller";
    EXPECT_EQ(judgeConnect(limits, buckets, 7, some, kStartUs).verdict, ConnectVerdict::Accept);
    EXPECT_EQ(judgeConnect(limits, buckets, 7, some, kStartUs).verdict,
              ConnectVerdict::RateLimited);
    EXPECT_EQ(judgeConnect(limits, buckets, 8, some, kStartUs).verdict, ConnectVerdict::Accept);
}

// The pool full, a newcomer takes the oldest slot of the address holding the most; it spends a
// token like any accepted connection.
TEST(Admission, ANewcomerDisplacesTheOldestPeerOfTheAddressHoldingTheMost) {
    AdmissionLimits limits;
    limits.waitingSlots = 5;
    limits.waitingPerAddress = 4;
    ConnectBuckets buckets(limits.connectsPerS, limits.connectBurst);
    const std::vector<WaitingPeer> pool{{7, 50}, {8, 10}, {7, 30}, {7, 40}, {9, 5}};
    const ConnectDecision d = judgeConnect(limits, buckets, 11, pool, kLater);
    EXPECT_EQ(d.verdict, ConnectVerdict::Displace);
    EXPECT_EQ(d.displace, 2u) << "address 7 holds three; its oldest is at index 2";
    EXPECT_EQ(judgeConnect(limits, buckets, 8, pool, kLater).verdict, ConnectVerdict::Displace)
        << "8 holds one, two fewer than 7's three";
    EXPECT_EQ(judgeConnect(limits, buckets, 7, pool, kLater).verdict, ConnectVerdict::PoolFull)
        << "the address holding the most takes no one's slot";
    ConnectBuckets empty(1.0, 1.0);
    ASSERT_TRUE(empty.take(11, kLater));
    EXPECT_EQ(judgeConnect(limits, empty, 11, pool, kLater).verdict, ConnectVerdict::RateLimited)
        << "a newcomer over its rate displaces no one";
}

// Among the slots of the address holding the most, a silent one goes before one whose peer is
// under way (it has made its code offer).
TEST(Admission, ASilentSlotGoesBeforeAJoinerUnderWay) {
    AdmissionLimits limits;
    limits.waitingSlots = 4;
    ConnectBuckets buckets(limits.connectsPerS, limits.connectBurst);
    std::vector<WaitingPeer> pool{{7, 10, true}, {7, 30, false}, {7, 40, false}, {8, 5}};
    ConnectDecision d = judgeConnect(limits, buckets, 11, pool, kLater);
    ASSERT_EQ(d.verdict, ConnectVerdict::Displace);
    EXPECT_EQ(d.displace, 1u) << "the oldest silent one, though the one under way is older";
    pool[1].progressing = pool[2].progressing = true;
    d = judgeConnect(limits, buckets, 11, pool, kLater);
    ASSERT_EQ(d.verdict, ConnectVerdict::Displace);
    EXPECT_EQ(d.displace, 0u) << "all under way: the oldest";
}

// The probe that locked every newcomer out: 16 addresses each sending 1000 half-open CONNECTs a
// second keep the 256 waiting slots full. With the pool shared fairly, a newcomer's CONNECT
// always finds a slot, and keeps it while it joins.
TEST(Admission, SixteenFloodingAddressesCannotKeepANewcomerOut) {
    const AdmissionLimits limits; // the server's defaults
    ConnectBuckets buckets(limits.connectsPerS, limits.connectBurst);
    std::vector<WaitingPeer> pool;
    const uint32_t newcomer = 0x0100007f;
    uint64_t now = kStartUs;
    size_t refused = 0, displacedNewcomer = 0;
    auto connect = [&](uint32_t address) {
        std::erase_if(pool, [&](const WaitingPeer& w) {
            return now - w.sinceUs > limits.handshakeTimeoutUs; // the reaper
        });
        const ConnectDecision d = judgeConnect(limits, buckets, address, pool, now);
        if (d.verdict == ConnectVerdict::Displace) {
            displacedNewcomer += pool[d.displace].address == newcomer;
            pool.erase(pool.begin() + ptrdiff_t(d.displace));
        }
        if (d.verdict == ConnectVerdict::Accept || d.verdict == ConnectVerdict::Displace) {
            pool.push_back({address, now});
            return true;
        }
        ++refused;
        return false;
    };
    // 10 s of flood: each address every 1 ms; the pool fills within the first seconds.
    for (int ms = 0; ms < 10000; ++ms, now += 1000)
        for (uint32_t a = 0; a < 16; ++a)
            connect(0x0200007f + (a << 24));
    EXPECT_EQ(pool.size(), limits.waitingSlots) << "the flood holds every waiting slot";
    EXPECT_GT(refused, 0u);
    // The newcomer connects in the thick of it; its handshake and hello take 50 ms of flood.
    ASSERT_TRUE(connect(newcomer));
    for (int ms = 0; ms < 50; ++ms, now += 1000)
        for (uint32_t a = 0; a < 16; ++a)
            connect(0x0200007f + (a << 24));
    EXPECT_EQ(displacedNewcomer, 0u);
    EXPECT_EQ(std::count_if(pool.begin(), pool.end(),
                            [&](const WaitingPeer& w) { return w.address == newcomer; }),
              1);
}

TEST(Admission, ACookieHoldsForItsAddressAndPortForOneEpochMore) {
    const ConnectCookies cookies;
    ENetAddress a{};
    a.host = 0x0100007f;
    a.port = 40000;
    const uint64_t t = 5 * ConnectCookies::kEpochUs + 1;
    const uint32_t c = cookies.cookie(a, t);
    EXPECT_LT(c, 1u << 24) << "it travels in a disconnect's data, above the reason's byte";
    EXPECT_TRUE(cookies.valid(c, a, t));
    EXPECT_TRUE(cookies.valid(c, a, t + ConnectCookies::kEpochUs)) << "the next epoch too";
    EXPECT_FALSE(cookies.valid(c, a, t + 2 * ConnectCookies::kEpochUs)) << "then it expires";
    ENetAddress otherPort = a, otherHost = a;
    otherPort.port = 40001;
    otherHost.host = 0x0200007f;
    EXPECT_FALSE(cookies.valid(c, otherPort, t));
    EXPECT_FALSE(cookies.valid(c, otherHost, t));
    EXPECT_NE(ConnectCookies().cookie(a, t), c) << "a key of its own per server run";
}

// A refused CONNECT is answered with a DISCONNECT to the connecting peer, carrying the reason.
TEST(Admission, ARefusalAnswersTheConnectingPeerByItsOwnId) {
    std::vector<uint8_t> connect = connectDatagram();
    ENetProtocolConnect c;
    std::memcpy(&c, connect.data() + 4, sizeof c);
    c.outgoingPeerID = ENET_HOST_TO_NET_16(3);
    std::memcpy(connect.data() + 4, &c, sizeof c);
    const std::vector<uint8_t> r = refusalDatagram(connect, uint32_t(RefuseReason::Busy));
    ASSERT_EQ(r.size(), 2 + sizeof(ENetProtocolDisconnect));
    EXPECT_EQ((r[0] << 8 | r[1]), 3) << "addressed to the client's peer 3, no flags";
    ENetProtocolDisconnect cmd;
    std::memcpy(&cmd, r.data() + 2, sizeof cmd);
    EXPECT_EQ(cmd.header.command & ENET_PROTOCOL_COMMAND_MASK, ENET_PROTOCOL_COMMAND_DISCONNECT);
    EXPECT_EQ(cmd.header.command & ENET_PROTOCOL_COMMAND_FLAG_ACKNOWLEDGE, 0);
    EXPECT_EQ(ENET_NET_TO_HOST_32(cmd.data), uint32_t(RefuseReason::Busy));
    EXPECT_TRUE(refusalDatagram(std::vector<uint8_t>(6, 0), 1).empty()) << "not a CONNECT";
}

TEST(Admission, ASlotStuckInAHandshakeExpiresAfterTheTimeout) {
    SlotTimer timer(3);
    EXPECT_FALSE(timer.expired(1, true, kStartUs, 1000));
    EXPECT_FALSE(timer.expired(1, true, kStartUs + 1000, 1000));
    EXPECT_TRUE(timer.expired(1, true, kStartUs + 1001, 1000));
    EXPECT_FALSE(timer.expired(2, false, kStartUs + 5000, 1000)) << "connected: never expires";
    // Leaving the state restarts the clock.
    EXPECT_FALSE(timer.expired(0, true, kStartUs, 1000));
    EXPECT_FALSE(timer.expired(0, false, kStartUs + 500, 1000));
    EXPECT_FALSE(timer.expired(0, true, kStartUs + 1200, 1000));
    EXPECT_TRUE(timer.expired(0, true, kStartUs + 2201, 1000));
}

// [SECTION] budgets and names

TEST(Budgets, AViewBudgetRefillsAtItsRateUpToItsBurst) {
    RateBudget budget(1000.0, 2000.0);
    EXPECT_TRUE(budget.take(1500, kStartUs));
    EXPECT_FALSE(budget.take(1000, kStartUs));
    EXPECT_TRUE(budget.take(1000, kStartUs + 500000));
    EXPECT_FALSE(budget.covers(2001, kStartUs + 100'000'000)) << "never more than the burst";
    EXPECT_TRUE(budget.covers(2000, kStartUs + 100'000'000));
}

// Work measured once done is spent into debt, and the budget says when it holds enough again.
TEST(Budgets, ASpentBudgetOwesItsDebtAndSaysWhenItIsDue) {
    RateBudget budget(1000.0, 500.0);
    EXPECT_EQ(budget.dueUs(1, kStartUs), kStartUs) << "starts full";
    budget.spend(1500, kStartUs);
    EXPECT_FALSE(budget.covers(1, kStartUs + 999'000));
    EXPECT_EQ(budget.dueUs(1, kStartUs + 999'000), kStartUs + 1'001'000) << "1000 owed, then 1";
    EXPECT_TRUE(budget.covers(1, kStartUs + 1'001'000));
    EXPECT_EQ(RateBudget(0, 0).dueUs(1, kStartUs), UINT64_MAX) << "a budget that never refills";
}

TEST(Budgets, OverItsControlBudgetAPeerGetsTheLatestRosterAndNoPongs) {
    ControlBudget budget(1000);
    Participants first, second;
    first.list.push_back({1, Role::Trainee, Sync::Dbi, "a", 0});
    second.list.push_back({1, Role::Trainee, Sync::Dbi, "b", 0});
    const auto roster1 = encodeMessage(first), roster2 = encodeMessage(second);
    Pong pongMessage{1, 2};
    const auto pong = encodeMessage(pongMessage);
    Welcome w;
    const auto welcome = encodeMessage(w);
    EXPECT_EQ(budget.offer(4, roster1, 999), ControlBudget::Action::Send);
    EXPECT_EQ(budget.offer(4, roster1, 1000), ControlBudget::Action::Hold);
    EXPECT_EQ(budget.offer(4, roster2, 5000), ControlBudget::Action::Hold);
    EXPECT_EQ(budget.counts().coalesced, 1u) << "the first roster held is superseded";
    EXPECT_EQ(budget.offer(4, pong, 5000), ControlBudget::Action::Drop);
    EXPECT_EQ(budget.offer(4, welcome, 5000), ControlBudget::Action::Send)
        << "once-a-join messages go whatever the backlog";
    EXPECT_EQ(budget.counts().dropped, 1u);
    EXPECT_TRUE(budget.due([](uint16_t) { return int64_t(2000); }).empty()) << "still over";
    const auto due = budget.due([](uint16_t) { return int64_t(0); });
    ASSERT_EQ(due.size(), 1u);
    EXPECT_EQ(due[0].first, 4);
    EXPECT_EQ(due[0].second, roster2) << "the newest state only";
    EXPECT_FALSE(budget.holding());
    // A roster sent directly supersedes one held.
    EXPECT_EQ(budget.offer(5, roster1, 5000), ControlBudget::Action::Hold);
    EXPECT_EQ(budget.offer(5, roster2, 0), ControlBudget::Action::Send);
    EXPECT_FALSE(budget.holding());
}

TEST(Budgets, NamesAreMadeValidTextAndUnique) {
    bool repaired = false;
    EXPECT_EQ(admitName("alice", {}, 64, &repaired), "alice");
    EXPECT_FALSE(repaired);
    EXPECT_EQ(admitName("alice", {"alice"}, 64, &repaired), "alice (2)");
    EXPECT_TRUE(repaired);
    EXPECT_EQ(admitName("alice", {"alice", "alice (2)"}, 64), "alice (3)");
    EXPECT_EQ(admitName("b\xff\xfe"
                        "c",
                        {}, 64),
              "b\xEF\xBF\xBD\xEF\xBF\xBD"
              "c");
    EXPECT_EQ(admitName("tab\there\nnl", {}, 64), "tab here nl");
    EXPECT_EQ(admitName("\xC3\xA9t\xC3\xA9", {}, 64), "\xC3\xA9t\xC3\xA9") << "UTF-8 kept";
    EXPECT_EQ(admitName("\xC0\xAF", {}, 64), "\xEF\xBF\xBD\xEF\xBF\xBD") << "overlong form";
    // Cut to fit, on a character: 63 x 'a' then a 2-byte character does not fit 64.
    const std::string longName = std::string(63, 'a') + "\xC3\xA9";
    EXPECT_EQ(admitName(longName, {}, 64), std::string(63, 'a'));
    EXPECT_EQ(admitName(std::string(64, 'x'), {std::string(64, 'x')}, 64),
              std::string(60, 'x') + " (2)");
    // Whatever the bytes, the result is JSON text.
    std::string noise;
    for (int i = 0; i < 256; ++i)
        noise += char(i);
    EXPECT_NO_THROW((void)nlohmann::json(admitName(noise, {}, 1000)).dump());
}

// [SECTION] the policy

TEST(AvailabilityPolicy, ConnectionsNotYetAdmittedHoldNoPlace) {
    ServerConfig c;
    c.maxClients = 1;
    PolicyRig rig(c);
    const uint16_t silent = rig.connect();
    const uint16_t slow = rig.connect();
    ASSERT_NE(silent, 0);
    ASSERT_NE(slow, 0) << "waiting connections do not fill the session";
    const uint16_t ada = rig.join("ada");
    EXPECT_TRUE(rig.p().admitted(ada));
    EXPECT_FALSE(rig.p().admitted(silent));
    PolicyOutput out;
    EXPECT_EQ(rig.p().connect(kProtocolVersion, rig.now, out), 0);
    EXPECT_TRUE(disconnected(out, 0, RefuseReason::ServerFull)) << "the place is taken";
    // One that connected before the place was taken is refused at its hello.
    out = rig.hello(slow, "late");
    EXPECT_TRUE(disconnected(out, slow, RefuseReason::ServerFull));
    EXPECT_EQ(rig.counters().refusedFull, 2u);
}

TEST(AvailabilityPolicy, TooManyWaitingConnectionsAreRefusedBusy) {
    ServerConfig c;
    c.admission.waitingSlots = 2;
    PolicyRig rig(c);
    ASSERT_NE(rig.connect(), 0);
    ASSERT_NE(rig.connect(), 0);
    PolicyOutput out;
    EXPECT_EQ(rig.p().connect(kProtocolVersion, rig.now, out), 0);
    EXPECT_TRUE(disconnected(out, 0, RefuseReason::Busy));
    EXPECT_EQ(rig.availability().refusedBusy, 1u);
    EXPECT_NE(refuseReasonText(uint32_t(RefuseReason::Busy)).find("retrying"), std::string::npos);
}

// A code offer the gate holds for its turn is no late hello: the hello timeout counts from the
// last time the gate held it.
TEST(AvailabilityPolicy, AConnectionWhoseOfferIsHeldIsNotTimedOutForItsHello) {
    ServerConfig c;
    c.helloTimeoutS = 1.0f;
    PolicyRig rig(c);
    const uint16_t held = rig.connect(), silent = rig.connect();
    bool silentSent = false, heldSent = false;
    for (int i = 0; i < 30; ++i) { // 3 s, the gate holding `held`'s offer all along
        rig.now += 100000;
        rig.p().holdHelloClock(held, rig.now);
        PolicyOutput out;
        rig.p().update(rig.now, out);
        silentSent = silentSent || disconnected(out, silent, RefuseReason::BadHello);
        heldSent = heldSent || disconnected(out, held, RefuseReason::BadHello);
    }
    EXPECT_TRUE(silentSent);
    EXPECT_FALSE(heldSent);
    PolicyOutput out;
    rig.now += 1100000; // answered, then silent for longer than the timeout
    rig.p().update(rig.now, out);
    EXPECT_TRUE(disconnected(out, held, RefuseReason::BadHello));
}

TEST(AvailabilityPolicy, AParticipantSilentForTheIdleTimeoutIsSentAway) {
    ServerConfig c;
    c.idleTimeoutS = 2.0f;
    c.helloTimeoutS = 100.0f;
    PolicyRig rig(c);
    const uint16_t talker = rig.join("talker");
    const uint16_t quiet = rig.join("quiet");
    rig.now += 1'500'000;
    rig.send(talker, Ping{1});
    rig.now += 600'000; // quiet: 2.1 s; talker: 0.6 s
    PolicyOutput out = rig.update();
    EXPECT_TRUE(disconnected(out, quiet, RefuseReason::Idle));
    EXPECT_FALSE(disconnected(out, talker, RefuseReason::Idle));
    EXPECT_EQ(rig.availability().idleTimeouts, 1u);
    EXPECT_TRUE(rig.p().admitted(talker));
    EXPECT_FALSE(rig.p().live(quiet));
    rig.now += 1'500'000;
    EXPECT_TRUE(disconnected(rig.update(), talker, RefuseReason::Idle));
}

// Views of 100^2 at most, with a render budget of one such view a second, two saved up.
ServerConfig oneViewASecond() {
    ServerConfig c;
    c.maxViewPixels = 100 * 100;
    c.viewPixelsPerS = 10000;
    return c;
}

TEST(AvailabilityPolicy, ViewRequestsBeyondTheRenderBudgetWaitAndTheNewestWins) {
    PolicyRig rig(oneViewASecond());
    const uint16_t id = rig.join("orbit");
    size_t applied = 0;
    for (uint32_t i = 1; i <= 5; ++i) {
        ViewRequest r;
        r.requestId = i;
        r.view = viewOf(100, 100);
        r.view.eye.x += float(i);
        applied += eventsOf<ViewEvent>(rig.send(id, r));
    }
    EXPECT_EQ(applied, 2u) << "the saved-up budget";
    const AvailabilityCounters a = rig.availability();
    EXPECT_EQ(a.viewsDeferred, 3u);
    EXPECT_EQ(a.viewsCoalesced, 2u);
    rig.now += 500'000;
    EXPECT_EQ(eventsOf<ViewEvent>(rig.update()), 0u) << "half a view's budget";
    rig.now += 500'000;
    PolicyOutput out = rig.update();
    ASSERT_EQ(eventsOf<ViewEvent>(out), 1u);
    const LogRecord& ev = *std::find_if(out.events.begin(), out.events.end(),
                                        [](const auto& e) { return e.template is<ViewEvent>(); });
    EXPECT_EQ(ev.as<ViewEvent>()->viewId, 5u) << "the newest request";
    rig.now += 10'000'000;
    EXPECT_EQ(eventsOf<ViewEvent>(rig.update()), 0u) << "nothing left waiting";
}

// The policy walks its peers once a scan period, or sooner when it knows something falls due: a
// paced design switch and a deferred view, each asked for just after a walk, go at their
// microsecond, not a period later.
TEST(AvailabilityPolicy, WhatFallsDueBetweenScansGoesAtItsMicrosecond) {
    PolicyRig rig(oneViewASecond());
    const uint16_t id = rig.join("orbit");
    rig.update();
    const uint64_t t0 = rig.now;
    ViewRequest r;
    r.view = viewOf(100, 100);
    for (uint32_t i = 1; i <= 2; ++i) {
        r.requestId = i;
        r.view.eye.x += 1.0f;
        ASSERT_EQ(eventsOf<ViewEvent>(rig.send(id, r)), 1u) << "the saved-up budget";
    }
    SyncMode m;
    m.sync = Sync::Volume;
    m.volumeCodec = Codec::Lz4;
    EXPECT_EQ(eventsOf<SyncEvent>(rig.send(id, m)), 1u) << "the first switch goes at once";
    rig.now = t0 + kSyncSwitchIntervalUs - 5000;
    EXPECT_TRUE(rig.update().events.empty()) << "a walk, with nothing due";
    rig.now += 1000;
    m.sync = Sync::Dbi;
    EXPECT_EQ(eventsOf<SyncEvent>(rig.send(id, m)), 0u) << "paced";
    rig.now = t0 + kSyncSwitchIntervalUs - 1;
    EXPECT_EQ(eventsOf<SyncEvent>(rig.update()), 0u);
    rig.now = t0 + kSyncSwitchIntervalUs;
    EXPECT_EQ(eventsOf<SyncEvent>(rig.update()), 1u) << "at its microsecond, within a scan period";
    rig.now = t0 + 995'000;
    EXPECT_TRUE(rig.update().events.empty()) << "a walk, with nothing due";
    r.requestId = 3;
    EXPECT_EQ(eventsOf<ViewEvent>(rig.send(id, r)), 0u) << "it waits for a second's budget";
    rig.now = t0 + 1'000'000 - 1;
    EXPECT_EQ(eventsOf<ViewEvent>(rig.update()), 0u);
    rig.now = t0 + 1'000'000;
    EXPECT_EQ(eventsOf<ViewEvent>(rig.update()), 1u) << "at its microsecond, within a scan period";
}

// A view waiting for its budget that another peer's larger view leaves no room for is refused at
// the next pass, not at the next scan.
TEST(AvailabilityPolicy, AWaitingViewAnotherViewLeavesNoRoomForIsRefusedAtTheNextPass) {
    ServerConfig c = oneViewASecond();
    c.maxTotalViewPixels = 100 * 100 + 10 * 10 + 50;
    PolicyRig rig(c);
    const uint16_t a = rig.join("a", viewOf(10, 10));
    const uint16_t b = rig.join("b", viewOf(10, 10));
    ViewRequest r;
    uint32_t request = 0;
    for (auto [w, h] : {std::pair{100, 100}, {100, 99}, {10, 10}}) { // the budget spent
        r.requestId = ++request;
        r.view = viewOf(w, h);
        ASSERT_EQ(eventsOf<ViewEvent>(rig.send(a, r)), 1u);
    }
    r.requestId = ++request;
    r.view = viewOf(100, 100);
    EXPECT_EQ(eventsOf<ViewEvent>(rig.send(a, r)), 0u) << "it fits, and waits for its budget";
    rig.update();
    ViewRequest grow;
    grow.requestId = 1;
    grow.view = viewOf(20, 20);
    ASSERT_EQ(eventsOf<ViewEvent>(rig.send(b, grow)), 1u);
    EXPECT_EQ(rig.availability().viewsOverTotal, 0u);
    const PolicyOutput out = rig.update(); // the same microsecond
    EXPECT_EQ(rig.availability().viewsOverTotal, 1u);
    ViewRefused refused;
    ASSERT_EQ(out.messages.size(), 1u);
    EXPECT_EQ(out.messages[0].to, std::vector<uint16_t>{a});
    ASSERT_TRUE(decodeMessage(out.messages[0].bytes, refused));
    EXPECT_EQ(refused.requestId, uint32_t(request));
}

TEST(AvailabilityPolicy, AllViewsTogetherStayUnderThePixelTotal) {
    ServerConfig c;
    c.maxViewPixels = 100 * 100;
    c.maxTotalViewPixels = 2 * 100 * 100 + 50;
    PolicyRig rig(c);
    const uint16_t a = rig.join("a", viewOf(100, 100));
    rig.join("b", viewOf(100, 100));
    const uint16_t third = rig.connect();
    PolicyOutput out = rig.hello(third, "c", viewOf(10, 10));
    EXPECT_TRUE(disconnected(out, third, RefuseReason::ViewsFull));
    EXPECT_EQ(rig.availability().refusedViewTotal, 1u);
    const uint16_t small = rig.join("d", viewOf(5, 5));
    EXPECT_TRUE(rig.p().admitted(small));
    ViewRequest grow;
    grow.requestId = 7;
    grow.view = viewOf(50, 50);
    PolicyOutput refusedOut = rig.send(small, grow);
    EXPECT_EQ(eventsOf<ViewEvent>(refusedOut), 0u);
    EXPECT_EQ(rig.availability().viewsOverTotal, 1u);
    // The peer is told, with what it could have; it keeps its view.
    ASSERT_EQ(refusedOut.messages.size(), 1u);
    EXPECT_EQ(refusedOut.messages[0].to, std::vector<uint16_t>{small});
    ViewRefused refused;
    ASSERT_TRUE(decodeMessage(refusedOut.messages[0].bytes, refused));
    EXPECT_EQ(refused.requestId, 7u);
    EXPECT_EQ(refused.freePixels, 50u);
    // A view that shrinks frees pixels for the others.
    ViewRequest shrink;
    shrink.view = viewOf(10, 10);
    EXPECT_EQ(eventsOf<ViewEvent>(rig.send(a, shrink)), 1u);
    EXPECT_EQ(eventsOf<ViewEvent>(rig.send(small, grow)), 1u);
}

TEST(AvailabilityPolicy, NamesInTheRosterAreValidAndUnique) {
    PolicyRig rig;
    rig.join("alice");
    const uint16_t second = rig.connect();
    const PolicyOutput out = rig.hello(second, "alice");
    rig.join("bad\xff");
    const auto names = rig.roster(rig.update());
    ASSERT_EQ(names.size(), 3u);
    EXPECT_EQ(names[0], "alice");
    EXPECT_EQ(names[1], "alice (2)");
    EXPECT_EQ(names[2], "bad\xEF\xBF\xBD");
    EXPECT_EQ(rig.availability().namesRepaired, 2u);
    const std::string report =
        rig.book.read([](const ServerReport& r) { return toJsonText(r, NetStats{}); });
    EXPECT_TRUE(nlohmann::json::accept(report));
    EXPECT_NE(report.find("\"names_repaired\": 2"), std::string::npos);
}

// [SECTION] the simulation step

namespace {

struct SliceRig {
    // Pixels rendered: the work clock when the rig counts pixels (pixelClock).
    std::shared_ptr<uint64_t> pixels = std::make_shared<uint64_t>(0);
    ReportBook book;
    Outbox outbox{1 << 30, book, steadyNowUs};
    SimulationStep step;
    uint64_t now = kStartUs;

    // What the step's `yield` says (events wait, or they do from its ask `waitFromAsk` on) and
    // how often it was asked.
    bool eventsWait = false;
    int yieldAsked = 0, waitFromAsk = 0;
    // How often the step let what it posted go out first (StepConfig::letSend), and what then.
    int letSends = 0;
    std::function<void()> onLetSend;

    SliceRig(Volume v, int64_t slicePixels, int64_t chunkPixels = int64_t(1) << 13,
             bool pixelClock = false)
        : step(std::move(v),
               StepConfig{
                   .maxStepS = 0.05f,
                   .maxSweepMm = 10.0f,
                   .renderThreads = 1,
                   .slicePixels = slicePixels,
                   .chunkPixels = chunkPixels,
                   .workClock =
                       pixelClock ? ServerClock([p = pixels] { return *p; }) : ServerClock(),
                   .yield =
                       [this] {
                           ++yieldAsked;
                           return eventsWait || (waitFromAsk > 0 && yieldAsked >= waitFromAsk);
                       },
                   .letSend =
                       [this] {
                           ++letSends;
                           if (onLetSend)
                               onLetSend();
                       },
                   .renderer = pixelClock ? DbiRendererFactory([p = pixels](const Volume& vol,
                                                                            ThreadPool* pool) {
                       return std::make_unique<CountingRenderer>(vol, pool, p);
                   })
                                          : DbiRendererFactory()},
               outbox, book, steadyNowUs) {}
    LogRecord join(uint16_t id, const Camera& camera) {
        JoinEvent ev{.client = id, .view = toViewSpec(camera), .volumeCodec = Codec::Lz4};
        ev.inFlight = std::make_shared<std::atomic<int64_t>>(0);
        return {0, ev};
    }
    std::vector<Outbox::Ready> run(std::vector<LogRecord> batch, uint64_t advanceUs = 10000) {
        now += advanceUs;
        step.step(batch, now);
        outbox.finishCoding(); // full images of views larger than a slice are coded apart
        return outbox.take([](uint16_t) { return true; }).updates;
    }
};

bool has(const std::vector<Outbox::Ready>& updates, uint16_t client, bool full) {
    return std::any_of(updates.begin(), updates.end(),
                       [&](const auto& u) { return u.client == client && u.full == full; });
}

} // namespace

// A large new view renders a slice a step, while a small view's dirty rectangles go out at once;
// whole, the large view is the full render's pixels.
TEST(AvailabilitySlices, ALargeNewViewRendersInSlicesWhileOthersGetTheirUpdates) {
    const Volume skull = makeSkull(48);
    SliceRig rig(skull, 64 * 64);
    const Camera small = cameraPreset("top", skull, {64, 64});
    const Camera large = cameraPreset("paper", skull, {256, 256});
    auto first = rig.run({rig.join(1, small)});
    EXPECT_TRUE(has(first, 1, true)) << "64 x 64 fits one slice";
    EXPECT_FALSE(rig.step.rendering());
    EXPECT_TRUE(rig.run({rig.join(2, large)}).empty());
    EXPECT_TRUE(rig.step.rendering());
    int steps = 1;
    Box3i box{skull.dims() / 2 - glm::ivec3(3), skull.dims() / 2 + glm::ivec3(3)};
    box.lo.z = skull.dims().z - 12;
    box.hi.z = skull.dims().z;
    auto during = rig.run({{rig.now, CutEvent{box}}});
    ++steps;
    EXPECT_TRUE(has(during, 1, false)) << "the small view's rectangle does not wait";
    EXPECT_FALSE(has(during, 2, true));
    std::vector<Outbox::Ready> done;
    while (rig.step.rendering() && steps < 100) {
        done = rig.run({});
        ++steps;
    }
    EXPECT_EQ(steps, 256 * 256 / (64 * 64)) << "one slice a step";
    ASSERT_TRUE(has(done, 2, true));
    const auto& full =
        *std::find_if(done.begin(), done.end(), [](const auto& u) { return u.client == 2; });
    ImageUpdate u;
    ASSERT_TRUE(decodeMessage(full.message, u));
    Dbi got;
    ASSERT_TRUE(decodeImage(u.payload, u.rawBytes, u.codec, u.width, u.height, large, got));
    EXPECT_TRUE(compare(got, rig.step.render(large)).identical()) << "with the cut in it";
    EXPECT_EQ(rig.step.viewPixels(), 64 * 64 + 256 * 256);
}

namespace {

// A cut of bone in the middle of the skull's top, seen by the `top` and `paper` cameras.
LogRecord topCut(const Volume& skull, uint64_t now) {
    Box3i box{skull.dims() / 2 - glm::ivec3(6), skull.dims() / 2 + glm::ivec3(6)};
    box.lo.z = skull.dims().z - 12;
    box.hi.z = skull.dims().z;
    return {now, CutEvent{box}};
}

// The decoded pixels of client `id`'s update in `updates`, written over `into`.
bool applyUpdate(const std::vector<Outbox::Ready>& updates, uint16_t id, const Camera& camera,
                 Dbi& into) {
    auto it =
        std::find_if(updates.begin(), updates.end(), [&](const auto& u) { return u.client == id; });
    if (it == updates.end())
        return false;
    ImageUpdate u;
    Dbi got;
    if (!decodeMessage(it->message, u) ||
        !decodeImage(u.payload, u.rawBytes, u.codec, u.width, u.height, camera, got))
        return false;
    if (u.full)
        into = got;
    else
        into.apply(got, u.x, u.y);
    return true;
}

// A cut 4 voxels deeper than topCut: client 1's rectangle and client 2's (the `large` view, whose
// picture `largeSeen` takes it) both go in the step, and the large one shows the render.
void deeperCutGoesInTheStep(SliceRig& rig, const Volume& skull, const Camera& large,
                            Dbi& largeSeen) {
    LogRecord again = topCut(skull, rig.now);
    again.as<CutEvent>()->box.lo.z -= 4;
    auto at = rig.run({again});
    EXPECT_TRUE(has(at, 1, false));
    ASSERT_TRUE(applyUpdate(at, 2, large, largeSeen));
    EXPECT_TRUE(compare(largeSeen, rig.step.render(large)).identical());
}

} // namespace

// Past the smallest view's rectangle, a large view's change renders a chunk of rows at a time
// while events wait (each step applies them first), and reaches its client whole once done; the
// small view's rectangle goes in the step of the change however many events wait.
TEST(AvailabilitySlices, ALargeViewsChangeYieldsToWaitingEventsAChunkAtATime) {
    const Volume skull = makeSkull(48);
    SliceRig rig(skull, 64 * 64, 256 * 4);
    const Camera small = cameraPreset("top", skull, {64, 64});
    const Camera large = cameraPreset("top", skull, {256, 256});
    Dbi smallSeen, largeSeen;
    auto joined = rig.run({rig.join(1, small), rig.join(2, large)});
    while (rig.step.rendering())
        for (const auto& u : rig.run({}))
            joined.push_back(std::move(u));
    ASSERT_TRUE(applyUpdate(joined, 1, small, smallSeen));
    ASSERT_TRUE(applyUpdate(joined, 2, large, largeSeen));

    rig.eventsWait = true; // from now on, events always wait
    rig.yieldAsked = 0;
    auto during = rig.run({topCut(skull, rig.now)});
    ASSERT_TRUE(applyUpdate(during, 1, small, smallSeen)) << "the small view does not wait";
    EXPECT_FALSE(has(during, 2, false)) << "the large view's change is more than one chunk";
    EXPECT_EQ(rig.yieldAsked, 1) << "one piece (the small view's turn), then the events";
    EXPECT_TRUE(rig.step.rendering());
    int steps = 1;
    std::vector<Outbox::Ready> done;
    while (!has(done, 2, false) && steps < 200) {
        rig.yieldAsked = 0;
        done = rig.run({});
        EXPECT_LE(rig.yieldAsked, 1) << "step " << steps;
        ++steps;
    }
    EXPECT_GT(steps, 2) << "the change took several chunks, one a step";
    EXPECT_FALSE(rig.step.rendering());
    ASSERT_TRUE(applyUpdate(done, 2, large, largeSeen));
    EXPECT_TRUE(compare(smallSeen, rig.step.render(small)).identical());
    EXPECT_TRUE(compare(largeSeen, rig.step.render(large)).identical()) << "with the cut in it";

    // Nothing waiting: the whole change goes in the step, as before.
    rig.eventsWait = false;
    deeperCutGoesInTheStep(rig, skull, large, largeSeen);
}

// A new view larger than a slice renders a chunk a step while events wait (a column of tiles,
// then the rest of the chunk), a slice a step when none do; its copy for the full image then
// goes a piece a step while events wait.
TEST(AvailabilitySlices, ANewLargeViewRendersAChunkAStepWhileEventsWait) {
    const Volume skull = makeSkull(48);
    SliceRig rig(skull, 256 * 64, 256 * 16);
    const Camera large = cameraPreset("paper", skull, {256, 256});
    rig.eventsWait = true;
    int steps = 0;
    std::vector<Outbox::Ready> done = rig.run({rig.join(2, large)});
    for (++steps; !has(done, 2, true) && steps < 100; ++steps)
        done = rig.run({});
    EXPECT_EQ(steps, 256 / 16 + 256 / 64)
        << "16 rows a step, then the copy for its full image, 64 rows a step";
    rig.eventsWait = false;
    steps = 0;
    const Camera other = cameraPreset("top", skull, {256, 256});
    rig.outbox.viewChanged(2, 1);
    done = rig.run({{0, ViewEvent{2, toViewSpec(other), 1}}});
    for (++steps; !has(done, 2, true) && steps < 100; ++steps)
        done = rig.run({});
    EXPECT_EQ(steps, 256 / 64) << "64 rows a step";
    Dbi seen;
    ASSERT_TRUE(applyUpdate(done, 2, other, seen));
    EXPECT_TRUE(compare(seen, rig.step.render(other)).identical());
}

// A new view's rows are bulk work: once events wait, its band stops at the next column of tiles
// (16 pixels wide here), not at the end of its band; the step then gives new views the rest of a
// chunk's worth (the other newcomer's turn) and stops. Whole, each is the full render's pixels.
TEST(AvailabilitySlices, ANewViewsRowsGiveWayAtTheNextColumnOfTilesOnceEventsWait) {
    const Volume skull = makeSkull(48);
    SliceRig rig(skull, 256 * 64, 256 * 16, true);
    const Camera first = cameraPreset("working", skull, {256, 256}); // bone in its first band
    const Camera second = cameraPreset("top", skull, {256, 256});
    rig.waitFromAsk = 4; // three columns past the first, then events wait
    EXPECT_TRUE(rig.run({rig.join(1, first), rig.join(2, second)}).empty());
    EXPECT_EQ(rig.step.share().charged(1), uint64_t(4 * 16 * 16)) << "4 columns of its band";
    EXPECT_EQ(rig.step.share().charged(2), uint64_t(12 * 16 * 16)) << "the rest of the chunk";
    // A cut that changes the first view's columns done: its band starts again.
    const Dbi before = rig.step.render(first);
    const Box3i all{glm::ivec3(0), skull.dims()};
    rig.run({{rig.now, CutEvent{all}}});
    const PixelRect doneColumns{0, 0, 4 * 16, 16};
    ASSERT_FALSE(rig.step.render(first).extract(doneColumns) == before.extract(doneColumns))
        << "the cut shows in the columns done";
    rig.waitFromAsk = 0;
    *rig.pixels = 0;
    rig.run({});
    EXPECT_EQ(*rig.pixels, uint64_t(256 * 64)) << "nothing waiting: a slice";
    std::vector<Outbox::Ready> done;
    for (int steps = 0; !(has(done, 1, true) && has(done, 2, true)) && steps < 20; ++steps)
        for (auto& u : rig.run({}))
            done.push_back(std::move(u));
    Dbi seen;
    for (auto [id, camera] : {std::pair{uint16_t(1), first}, std::pair{uint16_t(2), second}}) {
        ASSERT_TRUE(applyUpdate(done, id, camera, seen));
        EXPECT_TRUE(compare(seen, rig.step.render(camera)).identical()) << id;
    }
}

// [SECTION] the fair share of the simulation's time

// Two peers always ready share the time equally whatever their pieces cost: one's 4 ms pieces
// against the other's 1 ms ones.
TEST(FairShare, TwoBusyPeersShareTheTimeEquallyWhateverTheirPiecesCost) {
    uint64_t clock = 0;
    FairShare share([&] { return clock; });
    const std::vector<uint16_t> ready{1, 2};
    std::map<uint16_t, uint64_t> used;
    for (int i = 0; i < 1000; ++i) {
        const uint16_t peer = ready[share.pick(ready)];
        const uint64_t cost = peer == 1 ? 4000 : 1000;
        clock += cost;
        share.charge(std::vector<uint16_t>{peer}, cost);
        used[peer] += cost;
    }
    EXPECT_EQ(used[1], share.charged(1));
    EXPECT_LE(std::abs(int64_t(used[1]) - int64_t(used[2])), 4000) << "within one piece";
}

// A peer idle while another worked banks nothing: back, it goes first once, then they take turns
// instead of it running for as long as it was away.
TEST(FairShare, APeerIdleForAWhileGoesFirstButBanksNoCredit) {
    FairShare share([] { return uint64_t(0); });
    const std::vector<uint16_t> alone{1}, both{1, 2};
    for (int i = 0; i < 100; ++i) {
        ASSERT_EQ(share.pick(alone), 0u);
        share.charge(uint16_t(1), 1000);
    }
    std::vector<uint16_t> order;
    for (int i = 0; i < 6; ++i) {
        const uint16_t peer = both[share.pick(both)];
        share.charge(peer, 1000);
        order.push_back(peer);
    }
    EXPECT_EQ(order, (std::vector<uint16_t>{2, 1, 2, 1, 2, 1}));
    EXPECT_EQ(share.charged(2), 3000u);
    // Where each stands (the order the server sends updates in) is a piece apart, not the
    // 100 ms peer 1 worked alone.
    EXPECT_LE(share.standing(1) - share.standing(2), 1000u);
    EXPECT_EQ(share.charged(1), 103000u);
    share.forget(2); // gone: its report keeps the total the step last wrote
    EXPECT_EQ(share.charged(2), 0u) << "a later peer given its id starts from nothing";
}

// [SECTION] the network thread's share: FairInbox, CodeMint

// A peer whose messages cost the network thread more falls behind in its own queue: each pass the
// honest peer's message, sent after a pile of the other's, is handled first or after at most one
// of them, and only the costly peer's queue grows.
TEST(FairInbox, APeerWhoseMessagesCostMoreFallsBehindWhileAnHonestPeersGoFirst) {
    uint64_t clock = 0;
    FairInbox inbox([&] { return clock; });
    const std::vector<uint8_t> costly{1}, cheap{2};
    size_t lastGreedyWaiting = 0;
    for (int pass = 0; pass < 50; ++pass) {
        for (int i = 0; i < 10; ++i)
            inbox.push(5, Channel::Control, costly); // 10 x 2 ms arrive first
        inbox.push(1, Channel::ToolState, cheap);
        int position = 0, honestAt = -1;
        inbox.serve(4000, [&](uint16_t peer, Channel, std::span<const uint8_t> m) {
            clock += m[0] == 1 ? 2000 : 50;
            if (peer == 1)
                honestAt = position;
            ++position;
        });
        EXPECT_GE(honestAt, 0) << "pass " << pass << ": the honest message waited";
        EXPECT_LE(honestAt, 1) << "pass " << pass;
        EXPECT_EQ(inbox.waiting(1), 0u);
        EXPECT_GE(inbox.waiting(5), lastGreedyWaiting);
        lastGreedyWaiting = inbox.waiting(5);
    }
    EXPECT_GT(lastGreedyWaiting, 300u) << "its own queue grew";
    EXPECT_GT(inbox.charged(5), 20 * inbox.charged(1));
}

// Work done for a peer outside its messages (its updates' sending, its codes' hashing) counts as
// theirs do: charged, the peer goes after one that was not.
TEST(FairInbox, WorkChargedOutsideItsMessagesPutsAPeerBehind) {
    uint64_t clock = 0;
    FairInbox inbox([&] { return clock; });
    inbox.push(1, Channel::Control, std::vector<uint8_t>{0});
    inbox.push(2, Channel::Control, std::vector<uint8_t>{0});
    inbox.serve(0, [&](uint16_t, Channel, std::span<const uint8_t>) { clock += 10; });
    inbox.serve(0, [&](uint16_t, Channel, std::span<const uint8_t>) { clock += 10; });
    inbox.charge(1, 20000); // a whole volume sent to peer 1
    std::vector<uint16_t> order;
    for (int i = 0; i < 3; ++i) {
        inbox.push(1, Channel::Control, std::vector<uint8_t>{0});
        inbox.push(2, Channel::Control, std::vector<uint8_t>{0});
    }
    inbox.serve(1000000, [&](uint16_t peer, Channel, std::span<const uint8_t>) {
        clock += 10;
        order.push_back(peer);
    });
    EXPECT_EQ(order, (std::vector<uint16_t>{2, 2, 2, 1, 1, 1}));
}

// The queue is bounded in bytes too: large packets fill it long before the message count, and
// one larger than the bound is dropped on its own, leaving nothing queued.
TEST(FairInbox, AQueueIsBoundedInBytesAndAnOversizedMessageIsDropped) {
    FairInbox inbox([] { return uint64_t(0); });
    const std::vector<uint8_t> large(FairInbox::kMaxWaitingBytes / 3 + 1, 7);
    EXPECT_TRUE(inbox.push(1, Channel::Control, large));
    EXPECT_TRUE(inbox.push(1, Channel::Control, large));
    EXPECT_FALSE(inbox.push(1, Channel::Control, large)) << "past the bytes, not the count";
    EXPECT_TRUE(inbox.push(1, Channel::Control, std::vector<uint8_t>{1}));
    const std::vector<uint8_t> oversized(FairInbox::kMaxWaitingBytes + 1, 7);
    EXPECT_FALSE(inbox.push(2, Channel::Control, oversized));
    EXPECT_EQ(inbox.waiting(2), 0u);
    size_t handled = 0;
    inbox.serve(1000000, [&](uint16_t peer, Channel, std::span<const uint8_t>) {
        EXPECT_EQ(peer, 1);
        ++handled;
    });
    EXPECT_EQ(handled, 3u);
    EXPECT_TRUE(inbox.push(1, Channel::Control, large)) << "handled, its bytes are free again";
}

// A full queue drops what comes next; a peer leaving has what it sent handled first, in order.
TEST(FairInbox, AFullQueueDropsTheNextAndALeavingPeersMessagesAreHandledInOrder) {
    FairInbox inbox([] { return uint64_t(0); }, 3);
    for (uint8_t i = 0; i < 3; ++i)
        EXPECT_TRUE(inbox.push(7, Channel::Control, std::vector<uint8_t>{i}));
    EXPECT_FALSE(inbox.push(7, Channel::Control, std::vector<uint8_t>{3}));
    EXPECT_TRUE(inbox.push(8, Channel::Control, std::vector<uint8_t>{9})) << "per peer";
    std::vector<uint8_t> seen;
    inbox.drain(7, [&](uint16_t peer, Channel, std::span<const uint8_t> m) {
        EXPECT_EQ(peer, 7);
        seen.push_back(m[0]);
    });
    EXPECT_EQ(seen, (std::vector<uint8_t>{0, 1, 2}));
    EXPECT_EQ(inbox.waiting(), 1u);
}

// A peer that floods and leaves has only the first kDrainMessages handled as it goes: the rest of
// its flood is dropped, not handled at once outside the fair order.
TEST(FairInbox, ALeavingPeersFloodIsDroppedPastTheFirstFew) {
    FairInbox inbox([] { return uint64_t(0); });
    const size_t flood = 3 * FairInbox::kDrainMessages;
    for (size_t i = 0; i < flood; ++i)
        ASSERT_TRUE(inbox.push(7, Channel::ToolState, std::vector<uint8_t>{uint8_t(i)}));
    inbox.push(8, Channel::Control, std::vector<uint8_t>{1});
    size_t handled = 0;
    const size_t dropped = inbox.drain(7, [&](uint16_t, Channel, std::span<const uint8_t> m) {
        EXPECT_EQ(m[0], uint8_t(handled)) << "in order";
        ++handled;
    });
    EXPECT_EQ(handled, FairInbox::kDrainMessages);
    EXPECT_EQ(dropped, flood - FairInbox::kDrainMessages);
    EXPECT_EQ(inbox.waiting(), 1u) << "the other peer's message still waits";
    EXPECT_EQ(inbox.waiting(7), 0u);
}

// Sealed messages spoilt by an authenticated peer (a byte flipped, cut short, replayed, empty)
// are dropped and counted by the gate, never delivered, and the time spent refusing them is the
// sender's: its queue waits while an honest peer's message goes first.
TEST(FairInbox, SpoiltSealedMessagesAreDroppedCountedAndChargedToTheirSender) {
    ServerConfig config;
    config.traineeCode = "TRAIN-EE42";
    config.instructorCode = "TEACH-3R99";
    ReportBook book;
    SessionGate gate(config, book);
    trephine::testing::GateClient client{config.traineeCode};
    ENetAddress at{};
    at.host = 0x0100007f;
    const std::vector<uint8_t> challenge = gate.connect(5, at);
    const SessionGate::Result answer =
        gate.receive(5, Channel::Control, client.offer(challenge), 0);
    ASSERT_EQ(answer.kind, SessionGate::Result::Kind::Reply);
    const std::vector<uint8_t> confirm =
        client.confirm(std::vector<uint8_t>(answer.message.begin(), answer.message.end()));
    ASSERT_EQ(gate.receive(5, Channel::Control, confirm, 0).kind,
              SessionGate::Result::Kind::Proven);
    SecureChannel sender(*client.keys, false);

    uint64_t clock = 0;
    FairInbox inbox([&] { return clock; });
    ToolState t;
    const std::vector<uint8_t> intact = sender.seal(Channel::ToolState, encodeMessage(t));
    ASSERT_EQ(gate.receive(5, Channel::ToolState, intact, 0).kind,
              SessionGate::Result::Kind::Deliver);
    for (uint32_t i = 1; i <= 300; ++i) {
        t.sequence = i;
        std::vector<uint8_t> m = sender.seal(Channel::ToolState, encodeMessage(t));
        switch (i % 4) {
        case 0:
            m[m.size() / 2] ^= 0x40;
            break;
        case 1:
            m.resize(m.size() - 5);
            break;
        case 2:
            m = intact;
            break; // opened once already
        default:
            m.resize(i % 8);
            break;
        }
        inbox.push(5, Channel::ToolState, m);
    }
    inbox.push(1, Channel::ToolState, std::vector<uint8_t>{uint8_t(MessageType::Ping)});
    int delivered = 0, bad = 0, position = 0, honestAt = -1;
    // The fake clock stands for the time each refusal takes.
    const auto handle = [&](uint16_t peer, Channel ch, std::span<const uint8_t> m) {
        if (peer == 1)
            honestAt = position;
        ++position;
        clock += 20;
        if (peer != 5)
            return;
        const SessionGate::Result r = gate.receive(peer, ch, m, clock);
        delivered += r.kind == SessionGate::Result::Kind::Deliver;
        bad += r.kind == SessionGate::Result::Kind::Bad;
    };
    inbox.serve(100, handle);
    EXPECT_LE(honestAt, 1) << "the honest message waits behind at most one";
    while (inbox.waiting() > 0)
        inbox.serve(100, handle);
    EXPECT_EQ(delivered, 0);
    EXPECT_EQ(bad, 300);
    const SecurityCounters s = book.read([](const ServerReport& r) { return r.security; });
    EXPECT_GT(s.forged, 0u);
    EXPECT_GT(s.replayed, 0u);
    EXPECT_EQ(s.forged + s.replayed, 300u) << "each one counted once";
    EXPECT_EQ(inbox.charged(5), 300u * 20u);
}

// An instructor asking for a new code 200 times while one is hashed costs two hashes, not 200:
// the newest waiting request wins, it waits until the role's hashing is under its duty cycle,
// and each hash's time comes back to be charged to whoever asked.
TEST(CodeMint, RequestsWhileACodeIsHashedCoalesceNewestWinsWithinTheDutyCycle) {
    trephine::testing::ManualExecutor worker;
    Salt salt{};
    salt[0] = 7;
    CodeMint mint(worker);
    for (uint16_t i = 0; i < 200; ++i)
        mint.request({Role::Instructor, 3, "cho" + std::to_string(i)}, salt, 1000 + i);
    mint.request({Role::Trainee, 3, "cho"}, salt, 1200); // another role hashes beside it
    EXPECT_EQ(worker.tasks.size(), 2u) << "one hash a role at a time";
    EXPECT_TRUE(mint.take(1300).empty()) << "nothing hashed yet";
    worker.run();
    std::vector<CodeMint::Done> issued = mint.take(1300);
    ASSERT_EQ(issued.size(), 2u);
    EXPECT_EQ(issued[0].request.byName, "cho0");
    EXPECT_GT(issued[0].us, 0u) << "the hash's time, to charge";
    EXPECT_EQ(issued[0].minted.w, codeScalar(normaliseCode(issued[0].minted.code), salt));
    EXPECT_TRUE(worker.tasks.empty()) << "the next waits for its turn";
    const uint64_t turn = 1000 + uint64_t(double(issued[0].us) / CodeMint::kDutyCycle);
    EXPECT_TRUE(mint.take(turn - 1).empty());
    EXPECT_TRUE(worker.tasks.empty());
    mint.take(turn);
    ASSERT_EQ(worker.tasks.size(), 1u) << "its turn: the newest request";
    worker.run();
    issued = mint.take(turn);
    ASSERT_EQ(issued.size(), 1u);
    EXPECT_EQ(issued[0].request.byName, "cho199");
    EXPECT_FALSE(mint.busy());
}

// A lone view gets every step's whole slice whatever its size: a 1920 x 1080 view renders a slice
// a step with nothing else to do (its half-size preview, then its rows), never waiting for a rate,
// and a change of it goes in the step.
TEST(AvailabilityFairShare, ALoneLargeViewGetsTheWholeStepWhateverItsSize) {
    const Volume skull = makeSkull(48);
    constexpr int64_t kSlice = 1920 * 64;
    constexpr int64_t kPixels = 1920 * 1080 + 960 * 540; // the exact frame and its preview
    SliceRig rig(skull, kSlice, 1920 * 8, true);
    const Camera hd = cameraPreset("top", skull, {1920, 1080});
    std::vector<Outbox::Ready> done = rig.run({rig.join(1, hd)});
    int steps = 1, fullImages = 0;
    for (; (fullImages += has(done, 1, true)) < 2 && steps < 100; ++steps) {
        EXPECT_EQ(*rig.pixels, uint64_t(steps) * kSlice) << "a whole slice every step";
        EXPECT_TRUE(rig.step.rendering()) << "work now: the server's loop does not wait";
        done = rig.run({});
    }
    EXPECT_EQ(steps, (kPixels + kSlice - 1) / kSlice) << "the preview, then the exact frame";
    Dbi seen;
    ASSERT_TRUE(applyUpdate(done, 1, hd, seen));
    EXPECT_EQ(rig.step.share().charged(1), uint64_t(kPixels)) << "all charged to it";
    auto cut = rig.run({topCut(skull, rig.now)});
    ASSERT_TRUE(applyUpdate(cut, 1, hd, seen)) << "its change goes in the step";
    EXPECT_FALSE(rig.step.rendering());
    EXPECT_TRUE(compare(seen, rig.step.render(hd)).identical()) << "with the cut in it";
}

// An honest trainee drilling (a cut a step) beside a greedy peer asking for a new 256 x 256 view
// every step, with events always waiting (one piece a step): the trainee's rectangles go within
// its share, at most a step late, and its picture stays exact; the greedy peer is charged its
// share and its own views never finish while it keeps asking; once it stops, its last one does.
TEST(AvailabilityFairShare, AnHonestPeersUpdatesGoWithinItsShareWhileAGreedyPeersWorkWaits) {
    const Volume skull = makeSkull(48);
    SliceRig rig(skull, 64 * 64 * 4, 256 * 4, true);
    const Camera small = cameraPreset("top", skull, {64, 64});
    const Camera greedy = cameraPreset("paper", skull, {256, 256});
    Dbi seen;
    auto first = rig.run({rig.join(1, small), rig.join(2, greedy)});
    ASSERT_TRUE(applyUpdate(first, 1, small, seen));
    rig.eventsWait = true;
    int late = 0, greedyFull = 0, sinceUpdate = 0;
    for (int i = 0; i < 60; ++i) {
        ViewSpec next = toViewSpec(greedy);
        next.eye.x += 0.5f * float(i % 7 + 1);
        rig.outbox.viewChanged(2, uint32_t(i + 2));
        LogRecord cut = topCut(skull, rig.now);
        cut.as<CutEvent>()->box.lo.z -= i % 6; // deeper each time: a change every step
        auto out = rig.run({cut, {0, ViewEvent{2, next, uint32_t(i + 2)}}});
        greedyFull += has(out, 2, true);
        sinceUpdate = applyUpdate(out, 1, small, seen) ? 0 : sinceUpdate + 1;
        late += sinceUpdate > 0;
        EXPECT_LE(sinceUpdate, 1) << "step " << i;
    }
    EXPECT_EQ(greedyFull, 0) << "its newest view replaces the one under way";
    EXPECT_LT(late, 30) << "most of the trainee's rectangles go in the step";
    const int64_t honestUs = int64_t(rig.step.share().charged(1)),
                  greedyUs = int64_t(rig.step.share().charged(2));
    EXPECT_GT(greedyUs, 0);
    rig.eventsWait = false;
    rig.run({}); // the trainee's last change, if it waited
    EXPECT_TRUE(compare(seen, rig.step.render(small)).identical());
    std::vector<Outbox::Ready> done;
    for (int steps = 0; !has(done, 2, true) && steps < 100; ++steps)
        done = rig.run({});
    EXPECT_TRUE(has(done, 2, true)) << "alone, its last view finishes";
    EXPECT_GT(greedyUs, 0) << "it had the time the trainee left";
    EXPECT_GT(honestUs, 0);
}

// Two new views, an honest peer's asked for once and a greedy peer's asked for anew every step,
// events always waiting: they take turns piece for piece, so the honest view arrives in about
// twice the steps it takes alone, while the greedy peer's never does.
TEST(AvailabilityFairShare, NewViewsShareTheStepsFairlyWhileTheGreedyPeerStartsOver) {
    const Volume skull = makeSkull(48);
    SliceRig rig(skull, 64 * 64 * 4, 256 * 4, true);
    const Camera honest = cameraPreset("top", skull, {256, 256});
    const Camera greedy = cameraPreset("paper", skull, {256, 256});
    rig.eventsWait = true;
    std::vector<Outbox::Ready> out = rig.run({rig.join(1, honest), rig.join(2, greedy)});
    int steps = 1, greedyFull = 0;
    for (; !has(out, 1, true) && steps < 400; ++steps) {
        ViewSpec next = toViewSpec(greedy);
        next.eye.x += 0.5f * float(steps % 7 + 1);
        rig.outbox.viewChanged(2, uint32_t(steps + 1));
        out = rig.run({{0, ViewEvent{2, next, uint32_t(steps + 1)}}});
        greedyFull += has(out, 2, true);
    }
    ASSERT_TRUE(has(out, 1, true));
    // Its frame's copy goes a piece a step (4 chunks' worth), free on the pixel clock; the greedy
    // peer meanwhile gets the chunk of new rows every step gives.
    const int copySteps = 256 * 256 / (256 * 4 * 4);
    EXPECT_LE(steps, 2 * 256 / 4 + copySteps + 1) << "half the pieces, then its frame's copy";
    EXPECT_EQ(greedyFull, 0);
    const int64_t honestUs = int64_t(rig.step.share().charged(1)),
                  greedyUs = int64_t(rig.step.share().charged(2));
    EXPECT_LE(std::abs(honestUs - greedyUs), (2 + copySteps) * 256 * 4)
        << "within a piece or two, and the copy's";
}

// Updates of whole views come before new views' rows, whoever's turn it is: a newcomer (charged
// nothing yet) waits behind a trainee's rectangle.
TEST(AvailabilityFairShare, UpdatesOfHeldViewsGoBeforeNewViewsRows) {
    const Volume skull = makeSkull(48);
    SliceRig rig(skull, 64 * 64 * 4, 256 * 4, true);
    const Camera small = cameraPreset("top", skull, {64, 64});
    Dbi seen;
    ASSERT_TRUE(applyUpdate(rig.run({rig.join(1, small)}), 1, small, seen));
    rig.eventsWait = true;
    const uint64_t before = *rig.pixels;
    auto out =
        rig.run({topCut(skull, rig.now), rig.join(3, cameraPreset("paper", skull, {256, 256}))});
    ASSERT_TRUE(applyUpdate(out, 1, small, seen)) << "the trainee's rectangle first";
    EXPECT_FALSE(has(out, 3, true));
    EXPECT_LE(*rig.pixels - before, uint64_t(64 * 64)) << "and nothing of the newcomer's rows";
    EXPECT_TRUE(rig.step.rendering());
    EXPECT_TRUE(compare(seen, rig.step.render(small)).identical());
}

// Chunked work for another peer waits until the updates posted in the step are handed to the
// network: the trainee's rectangle is taken before the larger view's change renders. A lone
// trainee never waits, nor do views of at most a slice changed in one step (a classroom's).
TEST(AvailabilityFairShare, ALargerViewsChunksWaitUntilTheUpdatesBeforeThemAreTaken) {
    const Volume skull = makeSkull(48);
    SliceRig rig(skull, 64 * 64 * 4, 256 * 4, true);
    const Camera small = cameraPreset("top", skull, {64, 64});
    const Camera large = cameraPreset("top", skull, {256, 256});
    Dbi smallSeen, largeSeen;
    ASSERT_TRUE(applyUpdate(rig.run({rig.join(1, small)}), 1, small, smallSeen));
    ASSERT_TRUE(applyUpdate(rig.run({topCut(skull, rig.now)}), 1, small, smallSeen));
    EXPECT_EQ(rig.letSends, 0) << "alone, nothing waits";
    const Camera other = cameraPreset("paper", skull, {64, 64});
    Dbi otherSeen;
    ASSERT_TRUE(applyUpdate(rig.run({rig.join(3, other)}), 3, other, otherSeen));
    LogRecord both = topCut(skull, rig.now);
    both.as<CutEvent>()->box.lo.z -= 2;
    const std::vector<Outbox::Ready> classroom = rig.run({both});
    ASSERT_TRUE(applyUpdate(classroom, 1, small, smallSeen));
    ASSERT_TRUE(applyUpdate(classroom, 3, other, otherSeen));
    EXPECT_EQ(rig.letSends, 0) << "two small views changed in one step do not wait";

    std::vector<Outbox::Ready> joined = rig.run({rig.join(2, large)});
    for (int steps = 0; rig.step.rendering() && steps < 100; ++steps)
        for (auto& u : rig.run({}))
            joined.push_back(std::move(u));
    ASSERT_TRUE(applyUpdate(joined, 2, large, largeSeen));

    rig.letSends = 0;
    std::vector<Outbox::Ready> handed; // what the network took when the step let it send
    uint64_t renderedThen = 0;         // and the pixels rendered in the step by then
    const uint64_t before = *rig.pixels;
    rig.onLetSend = [&] {
        renderedThen = *rig.pixels - before;
        for (auto& u : rig.outbox.take([](uint16_t) { return true; }).updates)
            handed.push_back(std::move(u));
    };
    LogRecord deeper = topCut(skull, rig.now);
    deeper.as<CutEvent>()->box.lo.z -= 4;
    const std::vector<Outbox::Ready> after = rig.run({deeper});
    EXPECT_EQ(rig.letSends, 1) << "once, before the large view's first piece";
    EXPECT_LE(renderedThen, uint64_t(2 * 64 * 64)) << "the small views' pixels only";
    ASSERT_TRUE(applyUpdate(handed, 1, small, smallSeen)) << "the trainee's rectangle went first";
    EXPECT_FALSE(has(handed, 2, false));
    ASSERT_TRUE(applyUpdate(after, 2, large, largeSeen)) << "the large view's change in the step";
    EXPECT_TRUE(compare(smallSeen, rig.step.render(small)).identical());
    EXPECT_TRUE(compare(largeSeen, rig.step.render(large)).identical());
}

// The simulation waits for a network pass that began after the last post: not one under way
// then, never while nothing is posted or the network thread is closed, and at most the bound.
TEST(AvailabilitySendPasses, TheSimulationWaitsForAPassThatBeganAfterThePost) {
    SendPasses passes;
    passes.posted();
    EXPECT_TRUE(passes.awaitPosted(10'000'000)) << "closed: no network thread to wait for";
    passes.open();
    EXPECT_FALSE(passes.awaitPosted(2000)) << "posted and no pass since: the bound";
    { const SendPasses::Pass pass(passes); }
    EXPECT_TRUE(passes.awaitPosted(10'000'000)) << "a pass after the post";
    EXPECT_TRUE(passes.awaitPosted(10'000'000)) << "nothing posted since";
    {
        const SendPasses::Pass underWay(passes);
        passes.posted();
    }
    EXPECT_FALSE(passes.awaitPosted(2000)) << "the pass under way at the post may have missed it";

    bool released = false;
    std::thread simulation([&] { released = passes.awaitPosted(10'000'000); });
    { const SendPasses::Pass pass(passes); }
    simulation.join();
    EXPECT_TRUE(released) << "the network thread's pass lets the simulation go";
    passes.posted();
    passes.close();
    EXPECT_TRUE(passes.awaitPosted(10'000'000)) << "closed again";
}

// Others' changes, anew every step while events always wait, never starve a newcomer: each step
// that gave new views nothing gives them a piece, so its first picture arrives.
TEST(AvailabilityFairShare, ANewcomerIsNotStarvedByAViewChangedEveryStep) {
    const Volume skull = makeSkull(48);
    SliceRig rig(skull, 64 * 64 * 4, 256 * 4, true);
    const Camera busy = cameraPreset("top", skull, {256, 256});
    std::vector<Outbox::Ready> out = rig.run({rig.join(1, busy)});
    for (int steps = 0; !has(out, 1, true) && steps < 100; ++steps)
        out = rig.run({});
    ASSERT_TRUE(has(out, 1, true));
    rig.eventsWait = true;
    out = rig.run({rig.join(3, cameraPreset("paper", skull, {64, 64}))});
    int steps = 1;
    for (; !has(out, 3, true) && steps < 200; ++steps) {
        LogRecord cut = topCut(skull, rig.now);
        cut.as<CutEvent>()->box.lo.z -= steps % 6; // a change to the busy view every step
        out = rig.run({cut});
    }
    EXPECT_TRUE(has(out, 3, true)) << "the newcomer's first picture after " << steps << " steps";
    EXPECT_LE(steps, 64 * 64 / (256 * 4) + 3) << "a piece a step, then its frame's copy";
}

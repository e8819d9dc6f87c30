// A server facing peers that do not play by the rules: a view request reusing its id for a
// smaller window while an update waits, a connection that never says hello, an instructor editing
// marks or switching sync modes as fast as it can send, tool states with an unnormalised rotation
// or a position far off. Server and peers in one process over loopback; deadlines only guard
// against hangs.
#include "net/enet_host.h"
#include "net/protocol.h"
#include "net/session_client.h"
#include "net/session_server.h"
#include "net/view.h"

#include "libsim/skull.h"

#include "loopback.h"

#include <gtest/gtest.h>

#include <glm/gtx/quaternion.hpp>

#include <chrono>
#include <optional>
#include <thread>

using namespace trephine;
using namespace trephine::net;
using trephine::testing::burrState;
using trephine::testing::loopback;
using trephine::testing::loopbackServerConfig;
using trephine::testing::pumpUntil;
using trephine::testing::sphereTop;

namespace {

// A hand-driven ENet client: it services (and so acknowledges) only when told to.
struct RawPeer {
    Host host = Host::client();
    ENetPeer* peer = nullptr;
    bool disconnected = false;
    uint32_t disconnectData = 0;
    std::vector<ImageUpdate> images;
    int annotationLists = 0;
    std::optional<Annotations> lastMarks;
    int rosters = 0;
    std::optional<Participants> lastRoster;

    // Connects, says hello (lz4 images of `view`) and waits for the first image.
    bool join(uint16_t port, const std::string& name, const ViewSpec& view) {
        if (!connect(port))
            return false;
        Hello h;
        h.name = name;
        h.codec = Codec::Lz4;
        h.view = view;
        send(Channel::Control, h);
        return serviceUntil([&] { return !images.empty(); });
    }
    bool connect(uint16_t port) {
        peer = host.connect(loopback(port), kProtocolVersion);
        bool up = false;
        serviceUntil([&] { return up; },
                     [&](const ENetEvent& e) { up = up || e.type == ENET_EVENT_TYPE_CONNECT; });
        return up;
    }
    template <typename M>
    void send(Channel channel, M m) {
        host.send(peer, channel, encodeMessage(m));
        host.flush(); // out, and nothing received: nothing acknowledged
    }
    // Services (receiving, acknowledging) until pred() holds; false after the guard.
    bool serviceUntil(const std::function<bool()>& pred,
                      const std::function<void(const ENetEvent&)>& extra = {},
                      double guardS = 20.0) {
        auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(guardS);
        while (std::chrono::steady_clock::now() < deadline) {
            host.service(2, [&](const ENetEvent& e) {
                if (extra)
                    extra(e);
                if (e.type == ENET_EVENT_TYPE_DISCONNECT) {
                    disconnected = true;
                    disconnectData = e.data;
                }
                if (e.type != ENET_EVENT_TYPE_RECEIVE)
                    return;
                std::span<const uint8_t> bytes(e.packet->data, e.packet->dataLength);
                ImageUpdate u;
                Annotations marks;
                Participants roster;
                if (decodeMessage(bytes, u)) {
                    images.push_back(std::move(u));
                } else if (decodeMessage(bytes, marks)) {
                    ++annotationLists;
                    lastMarks = std::move(marks);
                } else if (decodeMessage(bytes, roster)) {
                    ++rosters;
                    lastRoster = std::move(roster);
                }
            });
            if (pred())
                return true;
        }
        return false;
    }
};

void sleepMs(int ms) {
    std::this_thread::sleep_for(std::chrono::milliseconds(ms));
}

} // namespace

// A client asks for a smaller window under the id of the view it has while an update of the old
// one waits in the outbox (ENet still holds its unacknowledged full image). The waiting update is
// dropped with the view it belongs to: the server sends the new window's full image, never pixels
// read from outside it (before, the merge read the old rectangle past the smaller frame).
TEST(SessionHostile, AViewRequestReusingItsIdForASmallerWindowSendsOnlyThatWindow) {
    Volume sphere = makeSphere(64);
    ServerConfig sc = loopbackServerConfig("sphere:64");
    sc.maxInFlightBytes = 0; // anything unacknowledged holds the next update in the outbox
    SessionServer server(sphere, sc);
    server.start();
    RawPeer c;
    ASSERT_TRUE(c.connect(server.port()));
    Hello h;
    h.name = "hostile";
    h.codec = Codec::Lz4;
    h.view = toViewSpec(cameraPreset("top", sphere, {256, 256}));
    c.send(Channel::Control, h);
    sleepMs(400); // the full image goes out and stays unacknowledged
    server.submitBoxCut(surfaceBox(sphere, 8));
    sleepMs(300); // its rectangle waits in the outbox
    ViewRequest r;
    r.requestId = 0; // the hello's view id
    r.view = toViewSpec(cameraPreset("top", sphere, {64, 64}));
    c.send(Channel::Control, r);
    sleepMs(300); // the view changes while the update still waits (nothing acknowledged yet)
    ASSERT_TRUE(c.serviceUntil([&] {
        return !c.images.empty() && c.images.back().full && c.images.back().width == 64;
    })) << "the new window's full image";
    ASSERT_TRUE(c.serviceUntil([&] { return server.idle(); }));
    // The waiting update may still leave for the 256 x 256 view before the change; the only
    // full image after the first is the 64 x 64 one (the merge made it 143 x 143), and nothing
    // after it reaches outside 64 x 64.
    size_t fullAt = 0;
    for (size_t i = 1; i < c.images.size(); ++i) {
        const ImageUpdate& u = c.images[i];
        if (u.full) {
            EXPECT_EQ(u.width, 64) << "update " << i;
            EXPECT_EQ(u.height, 64) << "update " << i;
            fullAt = fullAt ? fullAt : i;
        } else if (fullAt) {
            EXPECT_LE(u.x + u.width, 64) << "update " << i;
            EXPECT_LE(u.y + u.height, 64) << "update " << i;
        }
    }
    EXPECT_GT(fullAt, 0u);
    server.stop();
}

// A connection that never says hello is closed after the hello timeout (BadHello), and its slot
// goes to a real client (before, maxClients silent connections locked everyone out).
TEST(SessionHostile, AConnectionThatNeverSaysHelloIsClosedAndFreesItsSlot) {
    Volume sphere = makeSphere(32);
    ServerConfig sc = loopbackServerConfig("sphere:32");
    sc.maxClients = 1;
    sc.helloTimeoutS = 0.3f;
    SessionServer server(sphere, sc);
    server.start();
    RawPeer silent;
    ASSERT_TRUE(silent.connect(server.port()));
    ASSERT_TRUE(silent.serviceUntil([&] { return silent.disconnected; }));
    EXPECT_EQ(silent.disconnectData, uint32_t(RefuseReason::BadHello));
    EXPECT_EQ(server.helloTimeouts(), 1u);

    ClientConfig cc = trephine::testing::namedClientConfig(sphere, "real", Role::Trainee, 64);
    SessionClient client(cc);
    client.connect(loopback(server.port()));
    ASSERT_TRUE(pumpUntil({&client}, [&] { return client.hasFullImage() || client.closed(); }));
    EXPECT_FALSE(client.closed()) << client.closeReason();
    EXPECT_EQ(server.refusedFull(), 0u);
    server.stop();
}

// An instructor adds and removes a mark as fast as it can send: the other participants get the
// list coalesced (at most one every kAnnotationsIntervalUs), not one per edit, and end with the
// right marks.
TEST(SessionHostile, MarkEditsAsFastAsTheyComeGoOutCoalesced) {
    Volume sphere = makeSphere(32);
    SessionServer server(sphere, loopbackServerConfig("sphere:32"));
    server.start();
    ClientConfig ic = trephine::testing::namedClientConfig(sphere, "ins", Role::Instructor, 64);
    SessionClient instructor(ic);
    instructor.connect(loopback(server.port()));
    ASSERT_TRUE(pumpUntil({&instructor}, [&] { return instructor.hasFullImage(); }));
    RawPeer listener;
    ASSERT_TRUE(listener.join(server.port(), "listener", ic.view)) << "joined (its first image)";
    const int before = listener.annotationLists; // none: no marks yet

    constexpr int kEdits = 1000;
    Annotate add;
    add.op = Annotate::Op::Add;
    add.position = {1.0f, 2.0f, 3.0f};
    add.label = "m";
    Annotate remove;
    remove.op = Annotate::Op::Remove;
    for (int i = 0; i < kEdits; ++i) {
        if (i % 2 == 0) {
            instructor.annotate(add);
        } else {
            remove.id = uint32_t(i / 2 + 1); // the mark just added (ids count from 1)
            instructor.annotate(remove);
        }
        instructor.poll(0);
    }
    add.label = "last";
    instructor.annotate(add);
    ASSERT_TRUE(listener.serviceUntil([&] {
        instructor.poll(0);
        return listener.lastMarks && listener.lastMarks->list.size() == 1 &&
               listener.lastMarks->list[0].label == "last";
    })) << "the final list arrives; last: "
        << (listener.lastMarks ? listener.lastMarks->list.size() : 999) << " marks, "
        << listener.annotationLists << " lists, refused " << server.annotationsRefused();
    const int lists = listener.annotationLists - before;
    EXPECT_GE(lists, 1);
    EXPECT_LT(lists, kEdits / 4) << "one list per edit is not coalesced";
    server.stop();
}

// The force model and the drill take the unit rotation: a tool state whose quaternion is scaled
// (a norm of 1.25, within what the message allows) feels the force of the unit one. A position
// beyond kMaxToolDistanceMm, or a quaternion near zero, is malformed.
TEST(SessionHostile, AToolStateWithAScaledRotationFeelsTheUnitRotationsForce) {
    Volume sphere = makeSphere(48);
    SessionServer server(sphere, loopbackServerConfig("sphere:48"));
    server.start();
    ClientConfig cc = trephine::testing::namedClientConfig(sphere, "t", Role::Trainee, 64);
    SessionClient client(cc);
    std::vector<HapticModel> models;
    client.setHapticCallback([&](const HapticModel& m, uint64_t) { models.push_back(m); });
    client.connect(loopback(server.port()));
    ASSERT_TRUE(pumpUntil({&client}, [&] { return client.hasFullImage(); }));

    SurfaceSite site = sphereTop(48);
    site.normal = glm::normalize(glm::vec3(0.4f, 0.0f, 1.0f)); // tilted: the shaft matters
    ToolState t = burrState(site, 9, 10, 1000000);
    t.drilling = false; // touch, do not cut
    t.speed = 0.0f;
    client.sendToolState(t);
    ASSERT_TRUE(pumpUntil({&client}, [&] { return models.size() == 1; }));
    ToolState scaled = t;
    scaled.sequence = t.sequence + 1;
    scaled.orientation = t.orientation * 1.25f;
    client.sendToolState(scaled);
    ASSERT_TRUE(pumpUntil({&client}, [&] { return models.size() == 2; }));
    EXPECT_GT(glm::length(models[0].force), 0.1f) << "the burr touches the bone";
    EXPECT_LT(glm::length(models[1].force - models[0].force), 1e-4f)
        << "scaled (" << models[1].force.x << ", " << models[1].force.y << ", " << models[1].force.z
        << ") against unit (" << models[0].force.x << ", " << models[0].force.y << ", "
        << models[0].force.z << ")";

    ToolState far = t;
    far.position.x = 2.0f * kMaxToolDistanceMm;
    ToolState flat = t;
    flat.orientation = glm::quat(0.01f, 0.0f, 0.0f, 0.0f);
    // One serialize() checks both ways: what cannot be written cannot be read.
    for (ToolState bad : {far, flat})
        EXPECT_TRUE(encodeMessage(bad).empty());
    EXPECT_FALSE(encodeMessage(scaled).empty());
    server.stop();
}

// A peer that asks for a view over maxViewPixels anyway (a SessionClient refuses it itself, knowing
// the limit from the welcome): dropped and counted, not malformed; the peer keeps its session.
TEST(SessionHostile, AViewRequestOverTheLimitIsDroppedAndCounted) {
    Volume sphere = makeSphere(24);
    ServerConfig sc = loopbackServerConfig("sphere:24");
    sc.maxViewPixels = 64 * 64;
    SessionServer server(sphere, sc);
    server.start();
    RawPeer c;
    ASSERT_TRUE(c.join(server.port(), "pushy", toViewSpec(cameraPreset("top", sphere, {32, 32}))));
    ViewRequest r;
    r.requestId = 1;
    r.view = toViewSpec(cameraPreset("top", sphere, {100, 100}));
    c.send(Channel::Control, r);
    ASSERT_TRUE(c.serviceUntil([&] { return server.viewsRefused() == 1; }));
    EXPECT_FALSE(c.disconnected);
    EXPECT_EQ(server.malformedTotal(), 0u);
    std::string report = server.reportJson();
    EXPECT_NE(report.find("\"views_refused\": 1"), std::string::npos) << report;
    EXPECT_NE(report.find("\"peers\""), std::string::npos);
    server.stop();
}

// A client switches between DBI and volume sync as fast as it can send. Each switch to volume
// would encode and send the whole volume, and each change of mode a roster to every participant:
// the switches reach the simulation at most every kSyncSwitchIntervalUs and the rosters go out at
// most every kRosterIntervalUs, and the latest mode wins (the client ends on DBI, with a full
// image after its last switch, and the roster says so).
TEST(SessionHostile, ModeSwitchesAsFastAsTheyComeAreCoalesced) {
    Volume sphere = makeSphere(32);
    SessionServer server(sphere, loopbackServerConfig("sphere:32"));
    server.start();
    const ViewSpec view = toViewSpec(cameraPreset("top", sphere, {32, 32}));
    RawPeer listener;
    ASSERT_TRUE(listener.join(server.port(), "listener", view));
    RawPeer switcher;
    ASSERT_TRUE(switcher.join(server.port(), "switcher", view));
    ASSERT_TRUE(listener.serviceUntil(
        [&] { return listener.lastRoster && listener.lastRoster->list.size() == 2; }));
    const int rostersBefore = listener.rosters;

    // A switch every few milliseconds, for about a second: each would reach the simulation on
    // its own.
    constexpr int kSwitches = 300;
    const uint64_t t0 = steadyNowUs();
    for (int i = 0; i < kSwitches; ++i) {
        SyncMode m;
        m.sync = i % 2 == 0 ? Sync::Volume : Sync::Dbi; // the last one (odd) is DBI
        m.volumeCodec = Codec::Lz4;
        switcher.host.send(switcher.peer, Channel::Control, encodeMessage(m));
        switcher.host.flush();
        switcher.serviceUntil([] { return true; }); // 2 ms, and ENet's window moves on
    }
    switcher.host.flush();
    // Everything delivered and applied: the switcher's last image is a full DBI of its view,
    // sent after its last switch reached the simulation.
    ASSERT_TRUE(switcher.serviceUntil([&] {
        listener.serviceUntil([] { return true; });
        return server.idle() && server.modeTotals(Sync::Dbi).clients == 2 &&
               !switcher.images.empty() && switcher.images.back().full &&
               steadyNowUs() - t0 > 2 * kSyncSwitchIntervalUs;
    })) << "the switcher ends on DBI with a full image";
    const double seconds = double(steadyNowUs() - t0) * 1e-6;
    ASSERT_TRUE(listener.serviceUntil([&] {
        return listener.lastRoster && listener.lastRoster->list.size() == 2 &&
               listener.lastRoster->list[1].sync == Sync::Dbi;
    })) << "the roster's last word: the switcher is on DBI";
    listener.serviceUntil([] { return false; }, {}, 0.5); // whatever else was queued for it
    EXPECT_FALSE(switcher.disconnected);
    EXPECT_EQ(server.malformedTotal(), 0u);
    // At most one volume per interval (and one more at each end), far fewer than 500.
    const double intervals = seconds / (double(kSyncSwitchIntervalUs) * 1e-6);
    const uint64_t volumes = server.modeTotals(Sync::Volume).fullUpdates;
    EXPECT_LE(double(volumes), intervals + 2) << seconds << " s, " << volumes << " volumes";
    const int rosters = listener.rosters - rostersBefore;
    EXPECT_LE(double(rosters), seconds / (double(kRosterIntervalUs) * 1e-6) + 2)
        << seconds << " s, " << rosters << " rosters";
    EXPECT_LT(rosters, kSwitches / 4);
    server.stop();
}

// A client sends tool states faster than the simulation takes them (here while it erodes and
// renders a large cut): at most maxQueuedToolStates wait, the rest are dropped and counted, as a
// lossy link would drop them. Every state is either applied or counted, and the client keeps its
// session.
TEST(SessionHostile, ToolStatesBeyondTheQueueBoundAreDroppedAndCounted) {
    Volume sphere = makeSphere(128);
    ServerConfig sc = loopbackServerConfig("sphere:128");
    sc.maxQueuedToolStates = 4;
    sc.hapticModels = false;
    SessionServer server(sphere, sc);
    server.start();
    ClientConfig cc = trephine::testing::namedClientConfig(sphere, "flood", Role::Trainee, 256);
    SessionClient client(cc);
    client.connect(loopback(server.port()));
    ASSERT_TRUE(pumpUntil({&client}, [&] { return client.hasFullImage(); }));

    const SurfaceSite site = sphereTop(128);
    constexpr int kStates = 400;
    server.submitBoxCut(surfaceBox(sphere, 100)); // keeps the simulation busy for a while
    for (int i = 0; i < kStates; ++i) {
        ToolState t = burrState(site, i, kStates, 1000000);
        t.drilling = false; // touching only: every state is cheap to apply
        t.speed = 0.0f;
        client.sendToolState(t);
    }
    client.poll(0);
    ASSERT_TRUE(pumpUntil({&client},
                          [&] {
                              return server.idle() &&
                                     server.toolStatesApplied() + server.toolStatesDropped() ==
                                         uint64_t(kStates);
                          }))
        << server.toolStatesApplied() << " applied, " << server.toolStatesDropped() << " dropped";
    EXPECT_GT(server.toolStatesDropped(), 0u);
    EXPECT_GT(server.toolStatesApplied(), 0u);
    EXPECT_FALSE(client.closed()) << client.closeReason();
    EXPECT_EQ(server.malformedTotal(), 0u);
    EXPECT_NE(server.reportJson().find("\"tool_states_dropped\": "), std::string::npos);
    server.stop();
}

// A mode switch that waits out kSyncSwitchIntervalUs is work still to do: the server is not idle
// until it has reached the simulation and its full image has gone out.
TEST(SessionHostile, AServerWithAPacedModeSwitchWaitingIsNotIdle) {
    Volume sphere = makeSphere(32);
    SessionServer server(sphere, loopbackServerConfig("sphere:32"));
    server.start();
    RawPeer c;
    ASSERT_TRUE(
        c.join(server.port(), "switcher", toViewSpec(cameraPreset("top", sphere, {32, 32}))));
    ASSERT_TRUE(c.serviceUntil([&] { return server.idle(); }));
    SyncMode m;
    m.volumeCodec = Codec::Lz4;
    m.sync = Sync::Volume;
    c.send(Channel::Control, m);
    m.sync = Sync::Dbi; // sooner than kSyncSwitchIntervalUs after the first: it waits
    c.send(Channel::Control, m);
    ASSERT_TRUE(c.serviceUntil(
        [&] { return server.reportJson().find("\"sync_switches\": 2") != std::string::npos; }));
    EXPECT_FALSE(server.idle()) << "the switch back to DBI still waits";
    const size_t images = c.images.size();
    ASSERT_TRUE(c.serviceUntil([&] { return server.idle(); }));
    ASSERT_GT(c.images.size(), images);
    EXPECT_TRUE(c.images.back().full) << "the DBI after the switch back";
    server.stop();
}

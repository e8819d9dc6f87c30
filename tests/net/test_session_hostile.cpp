// A server facing peers that do not play by the rules, end to end: tool states with an
// unnormalised rotation or a position far off, a view over the limit, tool states faster than the
// simulation takes them, a mode switch paced while the server is asked whether it is idle. Server
// and peers in one process over loopback; deadlines only guard against hangs. The rules themselves
// are tested without ENet in test_session_policy.cpp and test_outbox.cpp.
#include "net/enet_host.h"
#include "net/protocol.h"
#include "net/session_client.h"
#include "net/session_server.h"
#include "net/view.h"

#include "libsim/skull.h"

#include "loopback.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <glm/gtx/quaternion.hpp>

#include <chrono>
#include <optional>

using namespace trephine;
using namespace trephine::net;
using trephine::testing::burrState;
using trephine::testing::loopback;
using trephine::testing::loopbackServerConfig;
using trephine::testing::Pumped;
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
            Pumped::pumpAll();
            host.service(1, [&](const ENetEvent& e) {
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

} // namespace

// The force model and the drill take the unit rotation: a tool state whose quaternion is scaled
// (a norm of 1.25, within what the message allows) feels the force of the unit one. A position
// beyond kMaxToolDistanceMm, or a quaternion near zero, is malformed.
TEST(SessionHostile, AToolStateWithAScaledRotationFeelsTheUnitRotationsForce) {
    Volume sphere = makeSphere(48);
    SessionServer server(sphere, loopbackServerConfig("sphere:48"));
    Pumped pumped(server);
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
    Pumped pumped(server);
    RawPeer c;
    ASSERT_TRUE(c.join(server.port(), "pushy", toViewSpec(cameraPreset("top", sphere, {32, 32}))));
    ViewRequest r;
    r.requestId = 1;
    r.view = toViewSpec(cameraPreset("top", sphere, {100, 100}));
    c.send(Channel::Control, r);
    ASSERT_TRUE(c.serviceUntil([&] { return server.viewsRefused() == 1; }));
    EXPECT_FALSE(c.disconnected);
    EXPECT_EQ(server.malformedTotal(), 0u);
    nlohmann::json report = nlohmann::json::parse(server.reportJson());
    EXPECT_EQ(report["views_refused"], 1) << report.dump(2);
    ASSERT_EQ(report["peers"].size(), 1u) << report.dump(2);
    EXPECT_EQ(report["peers"][0]["views_refused"], 1) << report.dump(2);
    EXPECT_EQ(report["peers"][0]["view_requests"], 1) << "refused, but asked for";
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
    Pumped pumped(server);
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
    EXPECT_EQ(nlohmann::json::parse(server.reportJson())["tool_states_dropped"],
              server.toolStatesDropped());
    server.stop();
}

// A mode switch that waits out kSyncSwitchIntervalUs is work still to do: the server is not idle
// until it has reached the simulation and its full image has gone out.
TEST(SessionHostile, AServerWithAPacedModeSwitchWaitingIsNotIdle) {
    Volume sphere = makeSphere(32);
    SessionServer server(sphere, loopbackServerConfig("sphere:32"));
    Pumped pumped(server);
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
    ASSERT_TRUE(c.serviceUntil([&] {
        nlohmann::json report = nlohmann::json::parse(server.reportJson());
        return report["peers"].size() == 1 && report["peers"][0]["sync_switches"] == 2;
    }));
    EXPECT_FALSE(server.idle()) << "the switch back to DBI still waits";
    const size_t images = c.images.size();
    ASSERT_TRUE(c.serviceUntil([&] { return server.idle(); }));
    ASSERT_GT(c.images.size(), images);
    EXPECT_TRUE(c.images.back().full) << "the DBI after the switch back";
    server.stop();
}

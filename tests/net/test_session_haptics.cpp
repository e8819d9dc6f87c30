// Haptics, box cuts and server limits over loopback: a SessionServer (its own threads) and
// poll-driven SessionClients in one process. Deadlines only guard against hangs; nothing asserts
// wall time.
#include "net/force_round_trip.h"
#include "net/session_client.h"
#include "net/session_server.h"
#include "net/tool_model.h"

#include "libsim/force_model.h"
#include "libsim/haptics.h"
#include "libsim/skull.h"
#include "net/view.h"

#include "loopback.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <chrono>
#include <functional>
#include <mutex>
#include <vector>

using namespace trephine;
using namespace trephine::net;

namespace {

using trephine::testing::loopback;
using trephine::testing::Pumped;
using trephine::testing::pumpUntil;

ServerConfig testConfig() {
    ServerConfig c;
    c.port = 0;
    c.volumeName = "sphere:40";
    c.renderThreads = 1;
    return c;
}

ViewSpec topView(const Volume& v, int size = 64) {
    return toViewSpec(cameraPreset("top", v, {size, size}));
}

// The burr's lowest point `depthMm` below the sphere's top (negative: above it).
ToolState burrAt(int n, float depthMm) {
    ToolState t;
    t.toolKind = uint8_t(ToolKind::Burr);
    t.diameterMm = 4.0f;
    t.position = {0.0f, 0.0f, sphereRadiusMm(n) + 2.0f - depthMm};
    t.orientation = glm::quat(1, 0, 0, 0); // shaft along +z
    return t;
}

// A device that holds one pose (the test moves it between steps).
class HoldDevice : public Device {
public:
    std::string name() const override { return "hold"; }
    DeviceState read(double) override { return {pose, 0, true}; }
    void setForce(glm::vec3 f) override { force = f; }
    bool hasForceOutput() const override { return true; }
    ToolPose pose;
    glm::vec3 force{0.0f};
};

} // namespace

TEST(SessionHaptics, EachToolStateIsAnsweredWithTheServersForceModel) {
    Volume sphere = makeSphere(40);
    SessionServer server(sphere, testConfig());
    Pumped pumped(server);
    ClientConfig cc;
    cc.view = topView(sphere);
    SessionClient client(cc);
    std::vector<HapticModel> got;
    std::vector<uint64_t> arrivals;
    client.setHapticCallback([&](const HapticModel& m, uint64_t arrivalUs) {
        got.push_back(m);
        arrivals.push_back(arrivalUs);
    });
    client.connect(loopback(server.port()));
    ASSERT_TRUE(pumpUntil({&client}, [&] { return client.hasFullImage(); }));
    EXPECT_FALSE(client.latestHapticModel().has_value());

    ToolState in = burrAt(40, 1.0f); // pressed 1 mm in: contact
    in.clientTimeUs = steadyNowUs();
    uint32_t seqIn = client.sendToolState(in);
    ASSERT_TRUE(pumpUntil({&client}, [&] { return got.size() == 1; }));
    ToolState out = burrAt(40, -3.0f); // 3 mm above: no contact
    out.clientTimeUs = steadyNowUs();
    uint32_t seqOut = client.sendToolState(out);
    ASSERT_TRUE(pumpUntil({&client}, [&] { return got.size() == 2; }));

    const HapticModel& a = got[0];
    EXPECT_EQ(a.toolSequence, seqIn);
    EXPECT_EQ(a.clientTimeUs, in.clientTimeUs);
    EXPECT_EQ(a.position, in.position);
    EXPECT_LE(a.serverReceivedUs, a.serverSentUs);
    EXPECT_GE(arrivals[0], a.clientTimeUs);
    EXPECT_TRUE(a.contact);
    // The same force the model gives on the server's volume (the volume is unchanged: no drilling).
    ForceResult expect =
        ForceModel(ToolShape::burr(4.0f)).compute(sphere, ToolPose{in.position, in.orientation});
    EXPECT_EQ(a.force, expect.force);
    EXPECT_EQ(a.gradient, expect.gradient);
    EXPECT_GT(a.force.z, 0.0f) << "bone pushes the burr out (up)";

    EXPECT_EQ(got[1].toolSequence, seqOut);
    EXPECT_FALSE(got[1].contact);
    EXPECT_EQ(got[1].force, glm::vec3(0.0f));
    ASSERT_TRUE(client.latestHapticModel().has_value());
    EXPECT_EQ(client.latestHapticModel()->toolSequence, seqOut);
    EXPECT_EQ(client.hapticModelsReceived(), 2u);
    EXPECT_EQ(client.stats().hapticRoundTripUs.totalCount(), 2u);
    EXPECT_EQ(server.hapticModelsSent(), 2u);
    EXPECT_GE(client.stats().totalMessagesIn(Channel::Haptic), 2u);
}

// While drilling, the server's force includes the drilling resistance against the tool's motion,
// its velocity taken from the peer's successive tool states (no caller passed one: the documented
// resistance was never felt). The tool presses into dura, which drilling never removes, so the
// volume the server answers on is the one here.
TEST(SessionHaptics, ADrillingToolFeelsTheResistanceToItsMotion) {
    Volume v = makeSphere(40);
    v.fill(v.bounds(), 0, Material::Air);
    v.fill(Box3i{{0, 0, 0}, {40, 40, 20}}, 255, Material::Dura); // a dura floor at z = 0
    SessionServer server(v, testConfig());
    Pumped pumped(server);
    ClientConfig cc;
    cc.view = topView(v);
    SessionClient client(cc);
    std::vector<HapticModel> got;
    client.setHapticCallback([&](const HapticModel& m, uint64_t) { got.push_back(m); });
    client.connect(loopback(server.port()));
    ASSERT_TRUE(pumpUntil({&client}, [&] { return client.hasFullImage(); }));

    ToolState t;
    t.toolKind = uint8_t(ToolKind::Burr);
    t.diameterMm = 4.0f;
    t.orientation = glm::quat(1, 0, 0, 0); // shaft along +z
    t.drilling = true;
    t.speed = 1.0f;
    t.position = {0.0f, 0.0f, 1.5f}; // the ball's bottom 0.5 mm into the floor
    t.clientTimeUs = 1000000;
    client.sendToolState(t);
    ASSERT_TRUE(pumpUntil({&client}, [&] { return got.size() == 1; }));
    t.position.z -= 0.5f; // 0.5 mm deeper in 10 ms: 50 mm/s down
    t.clientTimeUs += 10000;
    client.sendToolState(t);
    ASSERT_TRUE(pumpUntil({&client}, [&] { return got.size() == 2; }));

    const ForceModel model(ToolShape::burr(4.0f));
    const ToolPose pose{t.position, t.orientation};
    const glm::vec3 resisted = model.compute(v, pose, 1.0f, {0.0f, 0.0f, -50.0f}).force;
    const glm::vec3 still = model.compute(v, pose, 1.0f).force;
    EXPECT_TRUE(got[0].contact);
    EXPECT_EQ(got[1].force, resisted);
    EXPECT_GT(resisted.z, still.z + 0.05f) << "the resistance pushes back up against the feed";
    server.stop();
}

TEST(SessionHaptics, HapticLoopOverLoopbackGetsModelsAndMeasuresTheRoundTrip) {
    Volume sphere = makeSphere(40);
    SessionServer server(sphere, testConfig());
    Pumped pumped(server);
    ClientConfig cc;
    cc.view = topView(sphere);
    SessionClient client(cc);
    client.connect(loopback(server.port()));
    ASSERT_TRUE(pumpUntil({&client}, [&] { return client.hasFullImage(); }));

    // The loop is stepped by hand on a virtual clock (10 ticks per tool state at the default
    // 100 Hz send rate); its sends go out through the client, its models come from the callback.
    HoldDevice device;
    ToolState pressed = burrAt(40, 1.0f);
    device.pose = ToolPose{pressed.position, pressed.orientation};
    std::vector<ToolState> toSend;
    HapticLoop loop(device, {}, [&](const DeviceState& s, double) {
        ToolState t = pressed;
        t.position = s.pose.position;
        t.orientation = s.pose.orientation;
        toSend.push_back(t);
    });
    double now = 0.0;
    client.setHapticCallback(
        [&](const HapticModel& m, uint64_t) { loop.setModel(toModelData(m), now); });
    for (int tick = 0; tick < 200; ++tick) {
        now = tick * 1e-3;
        loop.step(now);
        for (const ToolState& t : toSend)
            client.sendToolState(t);
        toSend.clear();
        // Wait for the answer to what was just sent, so every tick sees the newest model.
        uint64_t want = client.toolStatesSent();
        ASSERT_TRUE(pumpUntil({&client}, [&] { return client.hapticModelsReceived() >= want; }));
    }
    HapticLoopStats st = loop.stats();
    EXPECT_EQ(st.ticks, 200u);
    EXPECT_EQ(st.sent, 20u);
    EXPECT_EQ(client.toolStatesSent(), 20u);
    EXPECT_EQ(client.hapticModelsReceived(), 20u);
    EXPECT_EQ(st.models, 20u);
    EXPECT_EQ(client.stats().hapticRoundTripUs.totalCount(), 20u);
    EXPECT_GT(client.stats().hapticRoundTripUs.percentile(50), 0.0);
    // Pressed into bone: after the blend-in the device feels the server's force.
    ASSERT_TRUE(client.latestHapticModel().has_value());
    glm::vec3 f = client.latestHapticModel()->force;
    EXPECT_GT(f.z, 0.0f);
    EXPECT_NEAR(device.force.z, f.z, 1e-3f);
}

TEST(SessionHaptics, ForceRoundTripHelperMeasuresAgainstARealServer) {
    Volume sphere = makeSphere(40);
    SessionServer server(sphere, testConfig());
    server.start(); // the helper blocks: the server runs on its own threads
    ForceRoundTripConfig fc;
    ToolState t = burrAt(40, 1.0f);
    fc.shape = ToolShape::burr(4.0f);
    fc.pose = ToolPose{t.position, t.orientation};
    fc.samples = 30;
    fc.warmup = 2;
    fc.rateHz = 0; // back to back
    ForceRoundTripResult r = measureForceRoundTrip(loopback(server.port()), fc);
    EXPECT_EQ(r.samples, 30);
    EXPECT_EQ(r.contacts, 30);
    EXPECT_EQ(r.lost, 0);
    EXPECT_GT(r.p50Us, 0.0);
    EXPECT_LE(r.p50Us, r.p99Us);
}

TEST(SessionHaptics, UpdateCallbackReportsEachAppliedRectangle) {
    Volume sphere = makeSphere(40);
    SessionServer server(sphere, testConfig());
    Pumped pumped(server);
    ClientConfig cc;
    cc.codec = Codec::Raw;
    cc.view = topView(sphere);
    SessionClient client(cc);
    std::vector<std::pair<PixelRect, bool>> rects;
    std::vector<uint32_t> sequences;
    client.setUpdateCallback([&](const ImageUpdate& u, const PixelRect& r, bool full) {
        rects.push_back({r, full});
        sequences.push_back(u.sequence);
        // Called after the rectangle is in the DBI.
        EXPECT_EQ(client.lastUpdateSequence(), u.sequence);
    });
    client.connect(loopback(server.port()));
    ASSERT_TRUE(pumpUntil({&client}, [&] { return client.hasFullImage(); }));
    ASSERT_EQ(rects.size(), 1u);
    EXPECT_TRUE(rects[0].second);
    EXPECT_EQ(rects[0].first.w, 64);
    EXPECT_EQ(rects[0].first.h, 64);

    // A box cut at the top of the sphere: the client gets a partial rectangle inside its window.
    glm::ivec3 d = sphere.dims();
    server.submitBoxCut(
        Box3i::fromMinMax({d.x / 2 - 4, d.y / 2 - 4, d.z - 12}, {d.x / 2 + 4, d.y / 2 + 4, d.z}));
    ASSERT_TRUE(pumpUntil({&client}, [&] { return rects.size() >= 2 && server.idle(); }));
    EXPECT_FALSE(rects[1].second);
    PixelRect r = rects[1].first;
    EXPECT_GT(r.w, 0);
    EXPECT_LT(r.w, 64);
    EXPECT_LE(r.x + r.w, 64);
    EXPECT_LE(r.y + r.h, 64);
    EXPECT_EQ(rects.size(), client.updatesApplied());
    // The cut is in the server's volume and in the client's picture.
    Volume after = server.volumeSnapshot();
    EXPECT_EQ(after.density(d.x / 2, d.y / 2, d.z - 6), 0);
    EXPECT_EQ(after.material(d.x / 2, d.y / 2, d.z - 6), Material::Air);
    ASSERT_TRUE(pumpUntil({&client}, [&] {
        return server.idle() && compare(client.dbi(), server.renderView(client.view())).identical();
    }));
    EXPECT_GT(client.stats().updateLatencyUs.totalCount(), 0u);
}

TEST(SessionLimits, OneClientTooManyIsRefusedServerFull) {
    Volume sphere = makeSphere(24);
    ServerConfig sc = testConfig();
    sc.maxClients = 2;
    SessionServer server(sphere, sc);
    Pumped pumped(server);
    std::vector<std::unique_ptr<SessionClient>> clients;
    std::vector<SessionClient*> all;
    for (int i = 0; i < 3; ++i) {
        ClientConfig cc;
        cc.view = topView(sphere, 16);
        clients.push_back(std::make_unique<SessionClient>(cc));
        all.push_back(clients.back().get());
        clients.back()->connect(loopback(server.port()));
        if (i < 2) {
            ASSERT_TRUE(pumpUntil(all, [&] { return clients.back()->hasFullImage(); }));
        }
    }
    ASSERT_TRUE(pumpUntil(all, [&] { return clients[2]->closed(); }));
    EXPECT_EQ(clients[2]->closeReason(), refuseReasonText(uint32_t(RefuseReason::ServerFull)));
    EXPECT_FALSE(clients[2]->welcomed());
    EXPECT_EQ(server.refusedFull(), 1u);
    EXPECT_EQ(server.clientCount(), 2u);
    EXPECT_FALSE(clients[0]->closed());
    // A place comes free: the next one gets in.
    clients[0]->disconnect();
    ASSERT_TRUE(pumpUntil(all, [&] { return server.clientCount() == 1; }));
    ClientConfig cc;
    cc.view = topView(sphere, 16);
    SessionClient late(cc);
    late.connect(loopback(server.port()));
    ASSERT_TRUE(pumpUntil({&late, all[1]}, [&] { return late.hasFullImage(); }));
}

TEST(SessionLimits, OversizedViewsAreRefused) {
    Volume sphere = makeSphere(24);
    ServerConfig sc = testConfig();
    sc.maxViewPixels = 64 * 64;
    SessionServer server(sphere, sc);
    Pumped pumped(server);
    // A hello with too large a view: refused BadHello.
    ClientConfig big;
    big.view = topView(sphere, 65);
    SessionClient refused(big);
    refused.connect(loopback(server.port()));
    ASSERT_TRUE(pumpUntil({&refused}, [&] { return refused.closed(); }));
    EXPECT_EQ(refused.closeReason(), refuseReasonText(uint32_t(RefuseReason::BadHello)));
    // A view request too large: the client knows the limit from the welcome and refuses it
    // itself; it keeps its view and its session (the server's own drop of such a request, from a
    // peer that sends it anyway: SessionHostile.AViewRequestOverTheLimitIsDroppedAndCounted).
    ClientConfig ok;
    ok.view = topView(sphere, 32);
    SessionClient client(ok);
    client.connect(loopback(server.port()));
    ASSERT_TRUE(pumpUntil({&client}, [&] { return client.hasFullImage(); }));
    EXPECT_EQ(client.requestView(topView(sphere, 100)), 0u);
    EXPECT_EQ(client.viewsRefused(), 1u);
    for (int i = 0; i < 50; ++i)
        trephine::testing::pollAll({&client});
    EXPECT_FALSE(client.closed());
    EXPECT_EQ(client.view().width, 32);
    EXPECT_EQ(server.malformedTotal(), 0u);
    EXPECT_EQ(server.viewsRefused(), 0u);
}

TEST(SessionLimits, ServerReportCountsMalformedPerPeer) {
    Volume sphere = makeSphere(24);
    SessionServer server(sphere, testConfig());
    Pumped pumped(server);
    ClientConfig cc;
    cc.name = "noisy";
    cc.view = topView(sphere, 16);
    SessionClient client(cc);
    client.connect(loopback(server.port()));
    ASSERT_TRUE(pumpUntil({&client}, [&] { return client.hasFullImage(); }));
    std::vector<uint8_t> junk = {uint8_t(MessageType::ToolState), 1, 2};
    for (int i = 0; i < 3; ++i)
        client.sendRaw(Channel::ToolState, junk);
    ASSERT_TRUE(pumpUntil({&client}, [&] { return server.malformedTotal() == 3; }));
    nlohmann::json report = nlohmann::json::parse(server.reportJson());
    ASSERT_EQ(report["peers"].size(), 1u) << report.dump(2);
    EXPECT_EQ(report["peers"][0]["name"], "noisy") << report.dump(2);
    EXPECT_EQ(report["peers"][0]["malformed"], 3) << report.dump(2);
    EXPECT_EQ(report["malformed_dropped"], 3) << report.dump(2);
    EXPECT_EQ(report["channels"]["tool"]["messages_in"], 3) << report.dump(2);
}

// A perforator through a bone block until its clutch stops it, then released (tool states that
// do not drill), lifted out and pressed onto the bone beside the first hole: it cut nothing there,
// since the clutch re-engaged only while drilling, and the first drilling step at the new site
// already found bone around the tip. Lifted without drilling, it now re-engages.
TEST(SessionHaptics, APerforatorReleasedAndLiftedCutsTheNextHole) {
    const Volume box = makeBox(48); // solid from -12 to +12 mm on every axis
    ServerConfig sc = testConfig();
    sc.volumeName = "box:48";
    SessionServer server(box, sc);
    Pumped pumped(server);
    ClientConfig cc;
    cc.view = topView(box);
    SessionClient client(cc);
    client.connect(loopback(server.port()));
    ASSERT_TRUE(pumpUntil({&client}, [&] { return client.hasFullImage(); }));

    ToolState t;
    t.toolKind = uint8_t(ToolKind::Perforator);
    t.diameterMm = 9.0f;
    t.orientation = glm::quat(1, 0, 0, 0); // the axis along +z, the tip at the position
    t.speed = 1.0f;
    t.clientTimeUs = 1000000;
    uint64_t sent = 0;
    auto send = [&](glm::vec3 at, bool drilling) {
        t.position = at;
        t.drilling = drilling;
        t.clientTimeUs += 50000; // each state a 50 ms step (the server's longest)
        client.sendToolState(t);
        ++sent;
        client.poll(0);
    };
    auto settle = [&] { // every state sent has been applied
        return pumpUntil({&client},
                         [&] { return server.toolStatesApplied() >= sent && server.idle(); });
    };
    // Down through the block, 12 steps (0.6 s: solid cortical) every 0.25 mm.
    for (float z = 12.5f; z > -14.0f; z -= 0.25f) {
        for (int i = 0; i < 12; ++i)
            send({0.0f, 0.0f, z}, true);
        ASSERT_TRUE(settle());
    }
    const Volume through = server.volumeSnapshot();
    ASSERT_EQ(through.material(24, 24, 24), Material::Air) << "the first hole was cut";
    // Released, lifted clear, moved beside the hole and pressed 1 mm into the bone for 1 s.
    for (int i = 0; i < 5; ++i)
        send({0.0f, 0.0f, 12.0f + 4.0f * float(i)}, false);
    send({7.0f, 7.0f, 30.0f}, false);
    send({7.0f, 7.0f, 13.0f}, false);
    for (int i = 0; i < 20; ++i)
        send({7.0f, 7.0f, 11.0f}, true);
    ASSERT_TRUE(settle());
    EXPECT_EQ(server.toolStatesDropped(), 0u);
    const Volume after = server.volumeSnapshot();
    int64_t cut = 0;
    for (size_t i = 0; i < after.voxelCount(); ++i)
        cut += after.densityData()[i] < through.densityData()[i];
    EXPECT_GT(cut, 0) << "the perforator cut nothing at the second site";
    server.stop();
}

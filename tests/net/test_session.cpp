// The networked session over loopback: a SessionServer and poll-driven SessionClients pumped in
// the test's thread (one test keeps the server's own threads). Deadlines only guard against hangs;
// nothing asserts wall time.
#include "net/marks_file.h"
#include "net/session_client.h"
#include "net/session_server.h"

#include "libsim/drill.h"
#include "libsim/error.h"
#include "libsim/skull.h"
#include "libsim/tool.h"
#include "libsim/volume_io.h"
#include "net/codec.h"
#include "net/view.h"

#include "loopback.h"
#include "test_support.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <glm/gtx/quaternion.hpp>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <functional>
#include <random>
#include <thread>
#include <unistd.h>

using namespace trephine;
using namespace trephine::net;

namespace {

using trephine::testing::burrState;
using trephine::testing::loopback;
using trephine::testing::pollAll;
using trephine::testing::Pumped;
using trephine::testing::pumpUntil;
using trephine::testing::ScopedEnv;
using trephine::testing::sphereTop;
using trephine::testing::TempDir;

constexpr int kWindow = 160;

ServerConfig testConfig(const std::string& name) {
    ServerConfig c;
    c.port = 0;
    c.volumeName = name;
    c.renderThreads = 2;
    return c;
}

ViewSpec presetView(const Volume& v, const char* name) {
    return toViewSpec(cameraPreset(name, v, {kWindow, kWindow}));
}

// A client looking at `v` from the top in a small square window.
ClientConfig topViewClient(const Volume& v, uint16_t window) {
    ClientConfig cfg;
    cfg.view = presetView(v, "top");
    cfg.view.width = cfg.view.height = window;
    return cfg;
}

// The client's DBI equals a fresh full render of the server's volume for its view.
bool converged(SessionServer& server, SessionClient& client) {
    if (!client.hasFullImage() || !server.idle())
        return false;
    return compare(client.dbi(), server.renderView(client.view())).identical();
}

bool waitConverged(SessionServer& server, std::vector<SessionClient*> clients) {
    int polls = 0;
    return pumpUntil(clients, [&] {
        if (++polls % 10)
            return false; // render the reference only now and then
        for (SessionClient* c : clients)
            if (!converged(server, *c))
                return false;
        return true;
    });
}

void drill(SessionClient& driller, std::vector<SessionClient*> all, const SurfaceSite& site,
           int count, uint64_t baseUs, int firstSequence = 0) {
    for (int i = 0; i < count; ++i) {
        ToolState t = burrState(site, i, count, baseUs);
        t.sequence += uint32_t(firstSequence);
        driller.sendToolState(t);
        pollAll(all);
    }
}

bool connectAll(std::vector<SessionClient*> clients) {
    return pumpUntil(clients, [&] {
        for (SessionClient* c : clients)
            if (!c->welcomed() || !c->hasFullImage())
                return false;
        return true;
    });
}

// Largest eye-distance error (mm) between two DBIs of one camera, and whether colours match.
struct DepthCheck {
    double maxErrorMm = 0;
    bool colorsEqual = true;
    bool backgroundEqual = true;
};
DepthCheck compareDepthMm(const Dbi& a, const Dbi& b, const Camera& cam) {
    DepthCheck r;
    for (int y = 0; y < a.height(); ++y)
        for (int x = 0; x < a.width(); ++x) {
            for (int c = 0; c < 3; ++c)
                r.colorsEqual &= a.color(x, y)[c] == b.color(x, y)[c];
            float da = a.depth(x, y), db = b.depth(x, y);
            if ((da == kBackgroundDepth) != (db == kBackgroundDepth)) {
                r.backgroundEqual = false;
                continue;
            }
            if (da == kBackgroundDepth)
                continue;
            double e = std::abs(eyeZFromWindowDepth(cam, da) - eyeZFromWindowDepth(cam, db));
            r.maxErrorMm = std::max(r.maxErrorMm, e);
        }
    return r;
}

// In one folder for the whole run, removed at its end with the marks and scene files beside
// each saved volume.
std::string tempPath(const std::string& name) {
    static const TempDir dir;
    return dir / name;
}

} // namespace

TEST(Session, RawClientConvergesBitForBitAfterBurrHoleOnSkull) {
    Volume skull = makeSkull(64);
    SurfaceSite site = defaultBurrSite(skull);
    ViewSpec view = presetView(skull, "working");
    SessionServer server(skull, testConfig("skull:64"));
    Pumped pumped(server);
    ClientConfig cc;
    cc.codec = Codec::Raw;
    cc.view = view;
    SessionClient client(cc);
    client.connect(loopback(server.port()));
    ASSERT_TRUE(connectAll({&client}));
    Dbi before = client.dbi();
    drill(client, {&client}, site, 60, 1000000);
    ASSERT_TRUE(pumpUntil({&client}, [&] { return server.toolStatesApplied() == 60; }));
    ASSERT_TRUE(waitConverged(server, {&client}));
    EXPECT_FALSE(compare(before, client.dbi()).identical()) << "the drilling shows";
    EXPECT_GT(client.updatesApplied(), 1u);
    EXPECT_EQ(client.stats().malformed(), 0u);
    EXPECT_GT(client.stats().updateLatencyUs.totalCount(), 0u);
}

TEST(Session, QuantisedCodecsConvergeWithinTheDocumentedDepthError) {
    Volume sphere = makeSphere(48);
    ViewSpec view = presetView(sphere, "top");
    SessionServer server(sphere, testConfig("sphere:48"));
    Pumped pumped(server);
    std::vector<std::unique_ptr<SessionClient>> clients;
    for (Codec codec : {Codec::Lz4, Codec::Zstd}) {
        ClientConfig cc;
        cc.codec = codec;
        cc.view = view;
        clients.push_back(std::make_unique<SessionClient>(cc));
        clients.back()->connect(loopback(server.port()));
    }
    std::vector<SessionClient*> all = {clients[0].get(), clients[1].get()};
    ASSERT_TRUE(connectAll(all));
    drill(*clients[0], all, sphereTop(48), 40, 1000000);
    ASSERT_TRUE(pumpUntil(all, [&] { return server.toolStatesApplied() == 40; }));
    Camera cam = toCamera(view);
    double bound = DepthQuantizer(cam).stepMm() * 1.001 + 1e-6;
    ASSERT_TRUE(pumpUntil(all, [&] {
        if (!server.idle())
            return false;
        Dbi ref = server.renderView(view);
        for (SessionClient* c : all) {
            DepthCheck d = compareDepthMm(c->dbi(), ref, cam);
            if (!d.colorsEqual || !d.backgroundEqual || d.maxErrorMm > bound)
                return false;
        }
        return true;
    }));
}

TEST(Session, TwoViewsLateJoinerAndViewChangeConverge) {
    Volume sphere = makeSphere(48);
    SessionServer server(sphere, testConfig("sphere:48"));
    Pumped pumped(server);
    ClientConfig a;
    a.codec = Codec::Raw;
    a.view = presetView(sphere, "top");
    ClientConfig b = a;
    b.view = presetView(sphere, "front");
    SessionClient ca(a), cb(b);
    ca.connect(loopback(server.port()));
    cb.connect(loopback(server.port()));
    ASSERT_TRUE(connectAll({&ca, &cb}));
    drill(ca, {&ca, &cb}, sphereTop(48), 40, 1000000);
    ASSERT_TRUE(pumpUntil({&ca, &cb}, [&] { return server.toolStatesApplied() == 40; }));
    ASSERT_TRUE(waitConverged(server, {&ca, &cb}));

    // A late joiner sharing A's view gets the drilled skull in its first full image.
    ClientConfig c = a;
    c.name = "late";
    c.codec = Codec::Zstd;
    SessionClient late(c);
    late.connect(loopback(server.port()));
    ASSERT_TRUE(connectAll({&ca, &cb, &late}));
    Camera cam = toCamera(c.view);
    DepthCheck d = compareDepthMm(late.dbi(), server.renderView(c.view), cam);
    EXPECT_TRUE(d.colorsEqual && d.backgroundEqual);
    EXPECT_LE(d.maxErrorMm, DepthQuantizer(cam).stepMm() * 1.001 + 1e-6);

    // B changes its view, and drilling continues on the side.
    ViewSpec left = presetView(sphere, "left");
    uint32_t id = cb.requestView(left);
    ASSERT_TRUE(pumpUntil({&ca, &cb, &late}, [&] { return cb.viewId() == id; }));
    EXPECT_EQ(cb.view(), left);
    SurfaceSite side{{sphereRadiusMm(48), 0.0f, 0.0f}, {1.0f, 0.0f, 0.0f}};
    drill(ca, {&ca, &cb, &late}, side, 40, 3000000, 40);
    ASSERT_TRUE(pumpUntil({&ca, &cb}, [&] { return server.toolStatesApplied() == 80; }));
    ASSERT_TRUE(waitConverged(server, {&ca, &cb}));
}

// A view request past the session's pixel total is answered, not dropped: the client keeps the
// view it has, says what the server had free, and a smaller request is served.
TEST(Session, AViewPastTheSessionsTotalIsRefusedAndTheViewHeldStays) {
    Volume sphere = makeSphere(32);
    ServerConfig sc = testConfig("sphere:32");
    sc.maxTotalViewPixels = 2 * 64 * 64 + 100;
    SessionServer server(sphere, sc);
    Pumped pumped(server);
    ClientConfig cfg = topViewClient(sphere, 64);
    SessionClient a(cfg), b(cfg);
    a.connect(loopback(server.port()));
    b.connect(loopback(server.port()));
    ASSERT_TRUE(connectAll({&a, &b}));
    const uint32_t held = b.viewId();

    ViewSpec wide = cfg.view;
    wide.width = wide.height = 96;
    EXPECT_NE(b.requestView(wide), 0u);
    ASSERT_TRUE(pumpUntil({&a, &b}, [&] { return b.viewRefusal().has_value(); }));
    EXPECT_EQ(*b.viewRefusal(), (ViewRefusal{96, 96, 64 * 64 + 100}));
    EXPECT_EQ(b.viewsRefused(), 1u);
    EXPECT_EQ(b.viewId(), held);
    EXPECT_TRUE(b.hasFullImage());
    EXPECT_EQ(b.dbi().width(), 64);

    ViewSpec smaller = cfg.view;
    smaller.width = smaller.height = 48;
    const uint32_t id = b.requestView(smaller);
    EXPECT_FALSE(b.viewRefusal().has_value());
    ASSERT_TRUE(pumpUntil({&a, &b}, [&] { return b.viewId() == id && b.hasFullImage(); }));
    EXPECT_EQ(b.dbi().width(), 48);
    EXPECT_EQ(b.viewsRefused(), 1u);
}

// In volume sync a view is the client's at once; refused by the server, it gives way to the view
// the server holds, so a switch to DBI completes with that view's picture.
TEST(Session, AVolumeClientsRefusedViewGivesWayToTheOneTheServerHolds) {
    Volume sphere = makeSphere(32);
    ServerConfig sc = testConfig("sphere:32");
    sc.maxTotalViewPixels = 64 * 64 + 100;
    SessionServer server(sphere, sc);
    Pumped pumped(server);
    ClientConfig cfg = topViewClient(sphere, 64);
    cfg.sync = Sync::Volume;
    cfg.volumeCodec = Codec::Zstd;
    SessionClient c(cfg);
    c.connect(loopback(server.port()));
    ASSERT_TRUE(pumpUntil({&c}, [&] { return c.localVolume() && c.hasFullImage(); }));
    const uint32_t held = c.viewId();

    ViewSpec wide = cfg.view;
    wide.width = wide.height = 96;
    EXPECT_NE(c.requestView(wide), 0u);
    EXPECT_EQ(c.view(), wide) << "rendered here at once";
    ASSERT_TRUE(pumpUntil({&c}, [&] { return c.viewRefusal().has_value(); }));
    EXPECT_EQ(c.view(), cfg.view);
    EXPECT_EQ(c.viewId(), held);
    EXPECT_EQ(c.viewAskedFor(), cfg.view);

    c.requestSync(Sync::Dbi);
    ASSERT_TRUE(pumpUntil({&c}, [&] { return c.sync() == Sync::Dbi && c.hasFullImage(); }));
    EXPECT_EQ(c.dbi().width(), 64);
}

TEST(Session, EveryToolPoseReachesTheOtherClients) {
    Volume sphere = makeSphere(32);
    SessionServer server(sphere, testConfig("sphere:32"));
    Pumped pumped(server);
    ClientConfig cfg = topViewClient(sphere, 32);
    SessionClient a(cfg), b(cfg), c(cfg);
    for (SessionClient* x : {&a, &b, &c})
        x->connect(loopback(server.port()));
    ASSERT_TRUE(connectAll({&a, &b, &c}));
    // A relay of an id the newest roster does not list is not kept (relays and rosters travel on
    // different channels): wait until b and c know a.
    const uint16_t aId = a.welcome().clientId;
    auto lists = [&](const SessionClient& x) { return x.participants().count(aId) > 0; };
    ASSERT_TRUE(pumpUntil({&a, &b, &c}, [&] { return lists(b) && lists(c); }));
    SurfaceSite site = sphereTop(32);
    for (int i = 0; i < 50; ++i) {
        ToolState t = burrState(site, i, 50, 1000);
        t.drilling = false;
        a.sendToolState(t);
        pollAll({&a, &b, &c});
    }
    ASSERT_TRUE(pumpUntil({&a, &b, &c},
                          [&] { return b.relaysReceived() == 50 && c.relaysReceived() == 50; }));
    ASSERT_TRUE(b.others().count(aId));
    EXPECT_EQ(b.others().at(aId).sequence, 50u);
    EXPECT_EQ(c.others().at(aId).position, burrState(site, 49, 50, 1000).position);
    EXPECT_EQ(a.relaysReceived(), 0u) << "a client is not sent its own tool";
}

// A raw image of the largest view (2048 x 2048: 33.5 MB at 8 bytes a pixel) is more than ENet
// delivers in one message: the server sends it lz4-coded, and the client shows it (its preview
// first, then the exact frame: docs/session.md, "Progressive first pictures").
TEST(Session, ARawClientOfTheLargestViewGetsItsPictureCoded) {
    Volume sphere = makeSphere(48);
    SessionServer server(sphere, testConfig("sphere:48"));
    Pumped pumped(server);
    ClientConfig cfg;
    cfg.codec = Codec::Raw;
    cfg.view = toViewSpec(cameraPreset("top", sphere, {2048, 2048}));
    ASSERT_EQ(int64_t(cfg.view.width) * cfg.view.height, ServerConfig{}.maxViewPixels);
    SessionClient client(cfg);
    client.connect(loopback(server.port()));
    ASSERT_TRUE(connectAll({&client}));
    ASSERT_TRUE(pumpUntil({&client}, [&] { return client.fullUpdates() >= 2; }));
    const Camera cam = toCamera(cfg.view);
    DepthCheck d = compareDepthMm(client.dbi(), server.renderView(cfg.view), cam);
    EXPECT_TRUE(d.colorsEqual && d.backgroundEqual);
    EXPECT_LE(d.maxErrorMm, DepthQuantizer(cam).stepMm() * 1.001 + 1e-6);
    EXPECT_LT(client.stats().updateBytes.max(), double(kMaxSentMessageBytes));
    EXPECT_EQ(client.stats().malformed(), 0u);
}

TEST(Session, AServerRefusesToServeViewsTooLargeForOneMessage) {
    ServerConfig cfg = testConfig("sphere:8");
    cfg.maxViewPixels = kMaxServedViewPixels + 1;
    try {
        SessionServer server(makeSphere(8), cfg);
        FAIL() << "expected an error";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("largest view"), std::string::npos) << e.what();
    }
    cfg.maxViewPixels = kMaxServedViewPixels;
    EXPECT_NO_THROW(SessionServer(makeSphere(8), cfg));
}

TEST(Session, MalformedInputIsDroppedCountedAndAPersistentOffenderDisconnected) {
    Volume sphere = makeSphere(48);
    SessionServer server(sphere, testConfig("sphere:48"));
    Pumped pumped(server);
    ClientConfig cfg;
    cfg.codec = Codec::Raw;
    cfg.view = presetView(sphere, "top");
    SessionClient good(cfg), bad(cfg);
    good.connect(loopback(server.port()));
    bad.connect(loopback(server.port()));
    ASSERT_TRUE(connectAll({&good, &bad}));

    Ping ping{42};
    std::vector<uint8_t> truncated = encodeMessage(ping);
    truncated.pop_back();
    std::vector<uint8_t> oversized = encodeMessage(ping);
    oversized.push_back(0);
    Welcome w;
    std::vector<uint8_t> wrongType = encodeMessage(w); // only the server sends a welcome
    std::vector<uint8_t> unknown = {200, 1, 2, 3};
    std::vector<uint8_t> empty;
    ToolState hugeTool;
    hugeTool.toolKind = uint8_t(ToolKind::Burr);
    hugeTool.diameterMm = 12.0f; // on the wire range, but no burr is that large
    std::vector<uint8_t> badTool = encodeMessage(hugeTool);
    ASSERT_FALSE(badTool.empty());
    std::vector<std::vector<uint8_t>> bads = {truncated, oversized, wrongType, unknown, badTool};
    std::mt19937 rng(7);
    for (int i = 0; i < 5; ++i) {
        std::vector<uint8_t> r(1 + rng() % 64);
        for (auto& byte : r)
            byte = uint8_t(rng());
        r[0] = uint8_t(1 + rng() % 12); // a known type with garbage after it
        if (r[0] == uint8_t(MessageType::Ping) && r.size() == 9)
            r.push_back(0);
        bads.push_back(r);
    }
    for (auto& m : bads)
        bad.sendRaw(Channel::Control, m);
    ASSERT_TRUE(pumpUntil({&good, &bad}, [&] { return server.malformedTotal() == bads.size(); }));
    EXPECT_FALSE(bad.closed()) << "a few bad packets are only dropped";

    for (int i = 0; i < 60 && bad.connected(); ++i) {
        bad.sendRaw(Channel::Control, unknown);
        pollAll({&bad});
    }
    ASSERT_TRUE(pumpUntil({&good, &bad}, [&] { return bad.closed(); }));
    EXPECT_NE(bad.closeReason().find("malformed"), std::string::npos) << bad.closeReason();
    EXPECT_EQ(server.disconnectedForMalformed(), 1u);

    drill(good, {&good}, sphereTop(48), 30, 1000000);
    ASSERT_TRUE(pumpUntil({&good}, [&] { return server.toolStatesApplied() == 30; }));
    ASSERT_TRUE(waitConverged(server, {&good}));
}

TEST(Session, ClientRejectsOutOfWindowRectanglesAndCorruptPayloads) {
    // A fake server: a raw ENet host that welcomes the client and sends bad updates.
    trephine::testing::FakeServer fake;
    ClientConfig cfg;
    cfg.codec = Codec::Raw;
    cfg.view.width = 64;
    cfg.view.height = 48;
    SessionClient client(cfg);
    client.connect(loopback(fake.port()));
    auto pumpBoth = [&](const std::function<bool()>& pred) { return fake.pumpWith(client, pred); };
    ASSERT_TRUE(pumpBoth([&] { return fake.peer && client.connected(); }));

    Dbi patch(16, 16);
    auto update = [&](uint16_t x, uint16_t y, uint16_t w, uint16_t h, bool corrupt) {
        ImageUpdate u;
        u.x = x;
        u.y = y;
        u.width = w;
        u.height = h;
        u.codec = Codec::Raw;
        EncodedImage e = encodeImage(Dbi(w, h), Codec::Raw, toCamera(cfg.view));
        u.rawBytes = e.rawBytes;
        u.payload = std::move(e.payload);
        if (corrupt)
            u.payload.resize(u.payload.size() / 2);
        return encodeMessage(u);
    };
    fake.send(Channel::Image, update(60, 0, 16, 16, false)); // past the right edge
    fake.send(Channel::Image, update(0, 40, 16, 16, false)); // past the top
    fake.send(Channel::Image, update(0, 0, 16, 16, true));   // payload too short
    fake.send(Channel::Image, update(8, 8, 16, 16, false));  // fine
    ASSERT_TRUE(
        pumpBoth([&] { return client.stats().malformed() + client.updatesApplied() == 4; }));
    EXPECT_EQ(client.stats().malformed(), 3u);
    EXPECT_EQ(client.updatesRejected(), 3u);
    EXPECT_EQ(client.updatesApplied(), 1u);
}

TEST(Session, ProtocolVersionMismatchIsRefusedWithAReadableReason) {
    Volume sphere = makeSphere(16);
    SessionServer server(sphere, testConfig("sphere:16"));
    Pumped pumped(server);
    Host raw = Host::client();
    ENetPeer* peer = raw.connect(loopback(server.port()), kProtocolVersion + 1);
    ASSERT_NE(peer, nullptr);
    std::string reason;
    auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(20);
    while (reason.empty() && std::chrono::steady_clock::now() < deadline) {
        Pumped::pumpAll();
        raw.service(1, [&](const ENetEvent& e) {
            if (e.type == ENET_EVENT_TYPE_DISCONNECT)
                reason = refuseReasonText(e.data);
        });
    }
    EXPECT_NE(reason.find("protocol version " + std::to_string(kProtocolVersion)),
              std::string::npos)
        << reason;

    // The session client prints the same sentence.
    ClientConfig cfg;
    cfg.protocolVersion = 99;
    SessionClient client(cfg);
    client.connect(loopback(server.port()));
    ASSERT_TRUE(pumpUntil({&client}, [&] { return client.closed(); }));
    EXPECT_NE(client.closeReason().find("same Trephine build"), std::string::npos);
}

TEST(Session, StopWritesSaveOnExitWithEveryAppliedDrilling) {
    Volume sphere = makeSphere(48);
    std::string path = tempPath("final.nrrd");
    ServerConfig config = testConfig("sphere:48");
    config.saveOnExit = path;
    auto server = std::make_unique<SessionServer>(sphere, config);
    Pumped pumped(*server);
    ClientConfig cfg = topViewClient(sphere, 64);
    SessionClient client(cfg);
    client.connect(loopback(server->port()));
    ASSERT_TRUE(connectAll({&client}));
    drill(client, {&client}, sphereTop(48), 40, 1000000);
    ASSERT_TRUE(pumpUntil({&client}, [&] { return server->toolStatesApplied() == 40; }));
    server->stop();
    Volume saved = loadVolume(path);
    EXPECT_TRUE(saved == server->volumeSnapshot());
    EXPECT_FALSE(saved == sphere) << "the drilling is in the file";
    // Every tool state applied, in order, with dt from the client's stamps: a local replay.
    Volume replay = sphere;
    Driller driller(ToolShape::burr(5.0f));
    for (int i = 1; i < 40; ++i) {
        ToolState t = burrState(sphereTop(48), i, 40, 1000000);
        driller.drill(replay, ToolPose{t.position, t.orientation}, t.speed, 0.01f);
    }
    EXPECT_TRUE(saved == replay) << "no applied drilling is lost";
    ASSERT_TRUE(pumpUntil({&client}, [&] { return client.closed(); }));
    EXPECT_NE(client.closeReason().find("shutting down"), std::string::npos);
    std::filesystem::remove(path);
    std::filesystem::remove(marksPathFor(path));
}

// A volume wider than the welcome carries (files load up to 2^20 voxels an axis) went silently
// unwelcomed: every client waited, then heard "is `trephine server` running?". A volume name over
// what the welcome carries was cut, and named another file. Both are refused when the server is
// made.
TEST(Session, AVolumeOrNameTheSessionCannotCarryIsRefusedAtOnce) {
    ServerConfig config = testConfig("wide");
    try {
        SessionServer server(Volume(glm::ivec3(kMaxVolumeDim + 1, 2, 2), glm::vec3(1.0f)), config);
        ADD_FAILURE() << "a 4097-voxel axis was accepted";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("4097 voxels along x"), std::string::npos) << e.what();
    }
    EXPECT_NO_THROW(
        SessionServer(Volume(glm::ivec3(2, 2, kMaxVolumeDim), glm::vec3(1.0f)), config));
    config.volumeName = std::string(kMaxVolumeNameBytes + 1, 'a') + ".nrrd";
    EXPECT_THROW(SessionServer(makeSphere(16), config), Error);
    config.volumeName = std::string(kMaxVolumeNameBytes, 'a');
    EXPECT_NO_THROW(SessionServer(makeSphere(16), config));
}

// A volume client of a server whose volume cannot go in one VolumeUpdate is refused before the
// volume is built and compressed (a 1024^3 volume took 4 GiB and seconds of the simulation thread
// per join, only to be refused): the bound is checked on the box's size.
TEST(Session, AVolumeTooLargeForAnUpdateIsKnownBeforeItIsCoded) {
    EXPECT_TRUE(fitsVolumeUpdate(glm::ivec3(512), true));
    EXPECT_FALSE(fitsVolumeUpdate(glm::ivec3(513, 512, 512), true));
    EXPECT_TRUE(fitsVolumeUpdate(glm::ivec3(1024, 512, 512), false));
    EXPECT_FALSE(fitsVolumeUpdate(glm::ivec3(1024), false));
    EXPECT_FALSE(fitsVolumeUpdate(glm::ivec3(4096), true)); // no 32-bit overflow
    EXPECT_TRUE(fitsVolumeUpdate(glm::ivec3(0), true));
}

// --save-on-exit is checked when the server is made, not when the session ends; and should the
// save fail at the end all the same (the folder gone meanwhile), the drilled volume goes to an
// emergency copy in the temporary folder instead of being lost.
TEST(Session, ASaveOnExitThatCannotBeWrittenIsRefusedAtOnceOrSavedElsewhere) {
    Volume sphere = makeSphere(32);
    ServerConfig config = testConfig("sphere:32");
    config.saveOnExit = tempPath("no-such-folder/final.nrrd");
    EXPECT_THROW(SessionServer(sphere, config), Error);
    config.saveOnExit = tempPath("final.txt");
    EXPECT_THROW(SessionServer(sphere, config), Error);
    // Where the marks would go is a folder.
    std::filesystem::create_directories(tempPath("blocked.nrrd.marks"));
    config.saveOnExit = tempPath("blocked.nrrd");
    EXPECT_THROW(SessionServer(sphere, config), Error);
    std::filesystem::remove(tempPath("blocked.nrrd.marks"));

    const std::filesystem::path folder = tempPath("going");
    std::filesystem::create_directories(folder);
    config.saveOnExit = (folder / "final.nrrd").string();
    auto server = std::make_unique<SessionServer>(sphere, config);
    Pumped pumped(*server);
    server->submitBoxCut(surfaceBox(sphere, 6));
    ASSERT_TRUE(pumpUntil({}, [&] { return server->idle(); }));
    std::filesystem::remove_all(folder);
    std::filesystem::create_directories(tempPath("tmp"));
    const ScopedEnv tmp("TMPDIR", tempPath("tmp")); // the emergency copy goes there
    server->stop();
    EXPECT_NE(server->saveError().find("final.nrrd"), std::string::npos) << server->saveError();
    ASSERT_FALSE(server->savedTo().empty());
    EXPECT_NE(server->savedTo(), config.saveOnExit);
    EXPECT_TRUE(loadVolume(server->savedTo()) == server->volumeSnapshot())
        << "the drilled volume is in the emergency copy";
    EXPECT_FALSE(server->volumeSnapshot() == sphere);
    EXPECT_EQ(std::filesystem::path(server->savedTo()).parent_path(), tempPath("tmp"));
    EXPECT_TRUE(std::filesystem::is_regular_file(marksPathFor(server->savedTo())))
        << "the marks beside it";
}

// A server stopped with clients still connected says goodbye to them, and its report lists them
// as gone: they were left "connected": true and counted per mode beside "clients": 0.
// A client that connects while the server says goodbye (up to 200 ms while other goodbyes are
// unacknowledged) was left connected, unwelcomed, until ENet's timeout, then read "the connection
// was lost"; it is told the server is shutting down. A server started after its stop stays
// stopped (its threads ended at once, unjoined, and the destructor terminated the program).
TEST(Session, AClientArrivingDuringTheGoodbyesIsToldTheServerIsShuttingDown) {
    Volume sphere = makeSphere(24);
    auto server = std::make_unique<SessionServer>(
        sphere, trephine::testing::loopbackServerConfig("sphere:24"));
    server->start();
    ClientConfig cc;
    cc.view = toViewSpec(cameraPreset("top", sphere, {32, 32}));
    SessionClient early(cc);
    early.connect(loopback(server->port()));
    ASSERT_TRUE(pumpUntil({&early}, [&] { return early.hasFullImage(); }));
    // `early` is not serviced from here: its goodbye stays unacknowledged for the whole 200 ms.
    std::thread stopper([&] { server->stop(); });
    std::this_thread::sleep_for(std::chrono::milliseconds(40));
    SessionClient late(cc);
    late.connect(loopback(server->port()));
    const bool closed = pumpUntil(
        {&late}, [&] { return late.closed(); }, 3.0);
    stopper.join();
    ASSERT_TRUE(closed) << "still waiting for a welcome";
    EXPECT_EQ(late.closeReason(), refuseReasonText(uint32_t(RefuseReason::Shutdown)));

    server->start(); // after stop: nothing starts
    EXPECT_TRUE(server->idle());
    server.reset();
}

TEST(Session, TheReportAfterAStopListsNoClientAsConnected) {
    Volume sphere = makeSphere(24);
    SessionServer server(sphere, trephine::testing::loopbackServerConfig("sphere:24"));
    Pumped pumped(server);
    ClientConfig cc;
    cc.view = toViewSpec(cameraPreset("top", sphere, {32, 32}));
    SessionClient client(cc);
    client.connect(loopback(server.port()));
    ASSERT_TRUE(pumpUntil({&client}, [&] { return client.hasFullImage(); }));
    nlohmann::json before = nlohmann::json::parse(server.reportJson());
    ASSERT_EQ(before["peers"].size(), 1u) << before.dump(2);
    EXPECT_EQ(before["peers"][0]["connected"], true);
    EXPECT_EQ(before["clients"], 1);
    EXPECT_EQ(before["modes"]["dbi"]["clients"], 1);
    server.stop(); // the client is not serviced: its goodbye is never acknowledged
    nlohmann::json report = nlohmann::json::parse(server.reportJson());
    EXPECT_EQ(report["clients"], 0) << report.dump(2);
    ASSERT_EQ(report["peers"].size(), 1u) << report.dump(2);
    EXPECT_EQ(report["peers"][0]["connected"], false) << report.dump(2);
    for (const char* mode : {"dbi", "volume"})
        EXPECT_EQ(report["modes"][mode]["clients"], 0) << "no mode counts it: " << report.dump(2);
}

// A pumped server's time is the one it is given: starting its threads too, whose clock is the
// steady one, would take it back, so it is refused. Two servers pumped in one thread each judge
// their own datagrams (ENet's intercept is pointed at the server being serviced), stopping one
// included.
TEST(Session, TwoServersPumpedInOneThreadServeTheirOwnClientsAndNeitherCanStart) {
    Volume sphere = makeSphere(24);
    auto first = std::make_unique<SessionServer>(sphere, testConfig("sphere:24"));
    auto pumpedFirst = std::make_unique<Pumped>(*first);
    SessionServer second(sphere, testConfig("sphere:24"));
    Pumped pumpedSecond(second);
    ClientConfig cc = topViewClient(sphere, 32);
    cc.codec = Codec::Raw; // bit for bit
    SessionClient a(cc), b(cc);
    a.connect(loopback(first->port()));
    b.connect(loopback(second.port()));
    ASSERT_TRUE(connectAll({&a, &b}));
    EXPECT_THROW(second.start(), Error);
    first->stop(); // says goodbye through its own gate, not the one pumped last
    pumpedFirst.reset();
    first.reset();
    ASSERT_TRUE(pumpUntil({&a, &b}, [&] { return a.closed(); }));
    EXPECT_EQ(a.closeReason(), refuseReasonText(uint32_t(RefuseReason::Shutdown)));
    drill(b, {&b}, sphereTop(24), 10, 1000000);
    ASSERT_TRUE(pumpUntil({&b}, [&] { return second.toolStatesApplied() == 10; }));
    EXPECT_FALSE(b.closed());
    EXPECT_EQ(second.security().spoofed, 0u);
    ASSERT_TRUE(waitConverged(second, {&b}));
}

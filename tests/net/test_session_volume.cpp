// The replicated-volume baseline over loopback: volume clients beside DBI clients on one server,
// live switches between the two, the paper's 1-byte-per-voxel boxes, and bad volume input.
// Deadlines only guard against hangs; nothing asserts wall time.
#include "net/session_client.h"
#include "net/session_server.h"

#include "libsim/skull.h"
#include "libsim/tool.h"
#include "net/codec.h"
#include "net/view.h"

#include "loopback.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <glm/gtx/quaternion.hpp>

#include <chrono>
#include <functional>
#include <random>

using namespace trephine;
using namespace trephine::net;

namespace {

using trephine::testing::burrState;
using trephine::testing::loopback;
using trephine::testing::loopbackServerConfig;
using trephine::testing::Pumped;
using trephine::testing::pumpUntil;
using trephine::testing::sphereTop;

constexpr int kWindow = 128;

ViewSpec presetView(const Volume& v, const char* name) {
    return toViewSpec(cameraPreset(name, v, {kWindow, kWindow}));
}

// Sends tool states [first, first + count) of a `total`-state stroke, polling everyone.
void drill(SessionClient& driller, const std::vector<SessionClient*>& all, const SurfaceSite& site,
           int first, int count, int total) {
    for (int i = first; i < first + count; ++i) {
        driller.sendToolState(burrState(site, i, total, 1000000));
        trephine::testing::pollAll(all);
    }
}

ClientConfig clientConfig(const ViewSpec& view, Sync sync, Codec volumeCodec = Codec::Raw) {
    ClientConfig cc;
    cc.codec = Codec::Raw;
    cc.view = view;
    cc.sync = sync;
    cc.volumeCodec = volumeCodec;
    cc.renderThreads = 2;
    return cc;
}

bool connectAll(const std::vector<SessionClient*>& clients) {
    return pumpUntil(clients, [&] {
        for (SessionClient* c : clients)
            if (!c->welcomed() || !c->hasFullImage())
                return false;
        return true;
    });
}

// The client shows, in the mode it asked for, exactly the server's fresh render of its view;
// a volume client also holds exactly the server's voxels.
bool converged(SessionServer& server, SessionClient& c) {
    if (!c.hasFullImage() || c.switchingSync() || !server.idle())
        return false;
    if (c.sync() == Sync::Volume &&
        (!c.localVolume() || !(*c.localVolume() == server.volumeSnapshot())))
        return false;
    return compare(c.dbi(), server.renderView(c.view())).identical();
}

bool waitConverged(SessionServer& server, const std::vector<SessionClient*>& clients) {
    int polls = 0;
    return pumpUntil(clients, [&] {
        if (++polls % 10)
            return false;
        for (SessionClient* c : clients)
            if (!converged(server, *c))
                return false;
        return true;
    });
}

// A 10^3 box just under the top of a 48^3 sphere (radius 16.8 voxels about the centre).
Box3i topBox(int lo = 19) {
    return {{lo, lo, 36}, {lo + 10, lo + 10, 46}};
}

} // namespace

TEST(SessionVolume, VolumeClientRendersBitForBitAfterBoxCutsAndDrilling) {
    Volume sphere = makeSphere(48);
    SessionServer server(sphere, loopbackServerConfig("sphere:48", 2));
    Pumped pumped(server);
    SessionClient client(clientConfig(presetView(sphere, "top"), Sync::Volume));
    client.connect(loopback(server.port()));
    ASSERT_TRUE(connectAll({&client}));
    EXPECT_EQ(client.sync(), Sync::Volume);
    ASSERT_NE(client.localVolume(), nullptr);
    EXPECT_TRUE(*client.localVolume() == sphere) << "the full volume at join";
    Dbi before = client.dbi();
    const uint8_t* const pixels = client.dbi().color();

    server.submitBoxCut(topBox());
    drill(client, {&client}, sphereTop(48), 0, 40, 40);
    ASSERT_TRUE(pumpUntil({&client}, [&] { return server.toolStatesApplied() == 40; }));
    ASSERT_TRUE(waitConverged(server, {&client}));
    EXPECT_FALSE(compare(before, client.dbi()).identical()) << "the cut and the drilling show";
    // Re-rendered into the same picture, as the DBI server renders into its view's frame (a new
    // frame each update was allocated, cleared and filled inside the baseline's render time).
    EXPECT_EQ(client.dbi().color(), pixels);
    // The re-renders after erosion resumed each ray at its cached first hit, as the DBI
    // server's do, and the picture is still bit for bit the server's.
    EXPECT_GT(client.localHitCache().resumed(), 0);
    EXPECT_GE(client.volumeUpdatesApplied(), 2u) << "the full volume, then boxes (coalesced)";
    EXPECT_EQ(client.stats().malformed(), 0u);
    const ModeStats& vm = client.stats().modes[size_t(Sync::Volume)];
    EXPECT_EQ(vm.fullUpdates, 1u);
    EXPECT_GT(vm.latencyUs.totalCount(), 0u);
    EXPECT_GT(vm.clientRenderUs.totalCount(), 0u);
    EXPECT_EQ(client.stats().modes[size_t(Sync::Dbi)].updates, 0u)
        << "no image for a volume client";
    ModeTotals sent = server.modeTotals(Sync::Volume);
    EXPECT_EQ(sent.clients, 1u);
    EXPECT_EQ(sent.updates, client.volumeUpdatesApplied());
    EXPECT_EQ(server.modeTotals(Sync::Dbi).updates, 0u);
}

TEST(SessionVolume, RawBoxPayloadIsOneBytePerVoxelAndTheCompressedVariantIsReportedApart) {
    Volume sphere = makeSphere(48);
    SessionServer server(sphere, loopbackServerConfig("sphere:48", 2));
    Pumped pumped(server);
    ViewSpec view = presetView(sphere, "top");
    SessionClient raw(clientConfig(view, Sync::Volume, Codec::Raw));
    SessionClient packed(clientConfig(view, Sync::Volume, Codec::Lz4));
    raw.connect(loopback(server.port()));
    packed.connect(loopback(server.port()));
    ASSERT_TRUE(connectAll({&raw, &packed}));
    for (SessionClient* c : {&raw, &packed})
        c->clearUpdateRecords();
    const int kN = 10;
    server.submitBoxCut(topBox());
    ASSERT_TRUE(pumpUntil({&raw, &packed}, [&] {
        return raw.updateRecords().size() == 1 && packed.updateRecords().size() == 1;
    }));
    const UpdateRecord& r = raw.updateRecords().back();
    EXPECT_EQ(r.mode, Sync::Volume);
    EXPECT_FALSE(r.full);
    EXPECT_EQ(r.box, glm::ivec3(kN));
    EXPECT_EQ(r.rawBytes, uint32_t(kN * kN * kN));
    EXPECT_EQ(r.bytes, uint32_t(kN * kN * kN)) << "the paper's N^3 bytes";
    EXPECT_GE(r.latencyUs, 0.0);
    const UpdateRecord& p = packed.updateRecords().back();
    EXPECT_EQ(p.rawBytes, uint32_t(kN * kN * kN));
    EXPECT_LT(p.bytes, p.rawBytes) << "a box cut to air compresses";
    ASSERT_TRUE(waitConverged(server, {&raw, &packed}));
}

TEST(SessionVolume, DbiAndVolumeClientsOnOneServerBothConverge) {
    Volume sphere = makeSphere(48);
    SessionServer server(sphere, loopbackServerConfig("sphere:48", 2));
    Pumped pumped(server);
    SessionClient dbi(clientConfig(presetView(sphere, "top"), Sync::Dbi));
    SessionClient vol(clientConfig(presetView(sphere, "front"), Sync::Volume, Codec::Zstd));
    dbi.connect(loopback(server.port()));
    vol.connect(loopback(server.port()));
    ASSERT_TRUE(connectAll({&dbi, &vol}));
    server.submitBoxCut(topBox(14));
    drill(dbi, {&dbi, &vol}, sphereTop(48), 0, 30, 30);
    ASSERT_TRUE(pumpUntil({&dbi, &vol}, [&] { return server.toolStatesApplied() == 30; }));
    ASSERT_TRUE(waitConverged(server, {&dbi, &vol}));
    EXPECT_EQ(dbi.sync(), Sync::Dbi);
    EXPECT_EQ(dbi.localVolume(), nullptr);
    EXPECT_EQ(vol.sync(), Sync::Volume);
    EXPECT_GT(dbi.stats().modes[size_t(Sync::Dbi)].updates, 1u);
    EXPECT_GT(vol.stats().modes[size_t(Sync::Volume)].updates, 1u);
    EXPECT_EQ(server.modeTotals(Sync::Dbi).clients, 1u);
    EXPECT_EQ(server.modeTotals(Sync::Volume).clients, 1u);
    // A volume client's own view change is rendered locally and matches the server's render.
    vol.requestView(presetView(sphere, "left"));
    EXPECT_EQ(vol.view(), presetView(sphere, "left"));
    ASSERT_TRUE(waitConverged(server, {&dbi, &vol}));
}

// A switch and a view asked for before the connection is up are made once it is: the hello
// carries the mode and the view request is sent again after it.
TEST(SessionVolume, ASwitchAndAViewAskedBeforeConnectingAreMade) {
    Volume sphere = makeSphere(48);
    SessionServer server(sphere, loopbackServerConfig("sphere:48", 2));
    Pumped pumped(server);
    SessionClient client(clientConfig(presetView(sphere, "top"), Sync::Dbi));
    client.requestSync(Sync::Volume);
    client.requestView(presetView(sphere, "front"));
    client.connect(loopback(server.port()));
    ASSERT_TRUE(pumpUntil({&client},
                          [&] {
                              return client.sync() == Sync::Volume &&
                                     client.localVolume() != nullptr &&
                                     client.view() == presetView(sphere, "front");
                          }))
        << "sync " << int(client.sync())
        << ", view is the front one: " << (client.view() == presetView(sphere, "front"));
    ASSERT_TRUE(waitConverged(server, {&client}));
}

// A client repeating the mode and codec it already has costs the server nothing: no whole
// volume is encoded and sent again (each one is a full pass over the volume on the simulation
// thread, which every other client waits for).
TEST(SessionVolume, ARepeatedSyncModeIsANoOp) {
    Volume sphere = makeSphere(48);
    SessionServer server(sphere, loopbackServerConfig("sphere:48", 2));
    Pumped pumped(server);
    SessionClient vol(clientConfig(presetView(sphere, "top"), Sync::Volume, Codec::Zstd));
    vol.connect(loopback(server.port()));
    ASSERT_TRUE(connectAll({&vol}));
    ASSERT_TRUE(waitConverged(server, {&vol}));
    const uint64_t fullBefore = server.modeTotals(Sync::Volume).fullUpdates;
    EXPECT_EQ(fullBefore, 1u);
    SyncMode same{Sync::Volume, Codec::Zstd};
    for (int i = 0; i < 5; ++i)
        ASSERT_TRUE(vol.sendRaw(Channel::Control, encodeMessage(same)));
    server.submitBoxCut(topBox()); // something after the requests, to know they were handled
    ASSERT_TRUE(waitConverged(server, {&vol}));
    EXPECT_EQ(server.modeTotals(Sync::Volume).fullUpdates, fullBefore);
    EXPECT_EQ(vol.stats().malformed(), 0u);
    // Another codec is a real request: the whole volume again, in it.
    SyncMode other{Sync::Volume, Codec::Lz4};
    ASSERT_TRUE(vol.sendRaw(Channel::Control, encodeMessage(other)));
    ASSERT_TRUE(pumpUntil(
        {&vol}, [&] { return server.modeTotals(Sync::Volume).fullUpdates == fullBefore + 1; }));
}

// An update too large to go through ENet in one message (voxels written over the whole of a
// 256^3 volume: a raw box with its materials, 33.5 MB, over kMaxSentMessageBytes) goes as the
// whole volume, compressed, instead of being dropped without a word (the client kept a stale copy
// while the server counted the update as sent).
TEST(SessionVolume, AnUpdateTooLargeForOneMessageGoesAsTheWholeVolume) {
    const Volume sphere = makeSphere(256);
    SessionServer server(sphere, loopbackServerConfig("sphere:256", 2));
    Pumped pumped(server);
    SessionClient vol(clientConfig(presetView(sphere, "top"), Sync::Volume, Codec::Raw));
    vol.connect(loopback(server.port()));
    ASSERT_TRUE(pumpUntil({&vol}, [&] { return vol.localVolume() != nullptr || vol.closed(); }))
        << vol.closeReason();
    Volume changed = sphere;
    changed.fill({{0, 0, 0}, {256, 256, 128}}, 0, Material::Air); // the lower half cut away
    const size_t n = changed.voxelCount();
    server.submitVoxels(changed.bounds(), {changed.densityData(), changed.densityData() + n},
                        {changed.materialData(), changed.materialData() + n});
    ASSERT_TRUE(pumpUntil({&vol}, [&] { return vol.volumeUpdatesApplied() >= 2 || vol.closed(); }))
        << vol.closeReason();
    EXPECT_TRUE(*vol.localVolume() == changed);
    EXPECT_EQ(vol.stats().modes[size_t(Sync::Volume)].fullUpdates, 2u) << "the join's and this";
    EXPECT_EQ(vol.stats().malformed(), 0u);
}

// A whole volume too large for a message even compressed (noise: 330^3 voxels, ~45 MB in zstd,
// over the 30 MiB ENet can deliver: kMaxSentMessageBytes) cannot be sent: the client is told so,
// not left waiting (ENet would have resent fragments until the connection timed out).
TEST(SessionVolume, AWholeVolumeTooLargeForAMessageRefusesVolumeSyncWithAReason) {
    const Volume noise = trephine::testing::incompressibleVolume();
    SessionServer server(noise, loopbackServerConfig("noise", 2));
    Pumped pumped(server);
    SessionClient vol(clientConfig(presetView(noise, "top"), Sync::Volume, Codec::Zstd));
    vol.connect(loopback(server.port()));
    ASSERT_TRUE(pumpUntil({&vol}, [&] { return vol.closed(); }));
    EXPECT_EQ(vol.closeReason(), refuseReasonText(uint32_t(RefuseReason::VolumeTooLarge)));
    EXPECT_EQ(vol.localVolume(), nullptr);
    EXPECT_EQ(server.modeTotals(Sync::Volume).fullUpdates, 0u) << "nothing counted as sent";
}

// Voxels put back after a cut raise densities inside bricks that still hold surface, where the
// renderer's safety net cannot see it: the volume client's hit cache must not survive that, or
// its rays resume too deep (a crash or a wrong picture). A narrow box keeps every brick occupied.
TEST(SessionVolume, VoxelsPutBackRestartTheVolumeClientsHitCache) {
    Volume sphere = makeSphere(48);
    SessionServer server(sphere, loopbackServerConfig("sphere:48", 2));
    Pumped pumped(server);
    SessionClient vol(clientConfig(presetView(sphere, "top"), Sync::Volume));
    vol.connect(loopback(server.port()));
    ASSERT_TRUE(connectAll({&vol}));
    const Box3i box{{22, 22, 36}, {26, 26, 46}};
    std::vector<uint8_t> density, material;
    sphere.copyBox(box, density, material);
    const Dbi intact = vol.dbi();
    for (int round = 0; round < 3; ++round) {
        server.submitBoxCut(box);
        ASSERT_TRUE(waitConverged(server, {&vol}));
        EXPECT_FALSE(compare(intact, vol.dbi()).identical()) << "the cut shows";
        server.submitVoxels(box, density, material);
        ASSERT_TRUE(waitConverged(server, {&vol}));
        EXPECT_EQ(compare(intact, vol.dbi()).maxColorError, 0) << "the bone is back";
    }
}

// With only volume clients the server leaves its brick grid (DBI rendering data) behind and
// brings it up to date before its next render: a DBI client joining after a cut, a plate of
// bone set in the air (a rise in density) and another cut gets the right picture, and so does
// the cut after it.
TEST(SessionVolume, AServerWithoutDbiClientsCatchesItsRenderingDataUpOnAJoin) {
    Volume sphere = makeSphere(48);
    SessionServer server(sphere, loopbackServerConfig("sphere:48", 2));
    Pumped pumped(server);
    SessionClient vol(clientConfig(presetView(sphere, "front"), Sync::Volume));
    vol.connect(loopback(server.port()));
    ASSERT_TRUE(connectAll({&vol}));
    server.submitBoxCut(topBox(14));
    // A plate of bone in the air above the sphere: densities rise where no brick held surface.
    const Box3i plate{{12, 12, 46}, {30, 30, 47}};
    server.submitVoxels(plate, std::vector<uint8_t>(size_t(plate.count()), 255),
                        std::vector<uint8_t>(size_t(plate.count()), uint8_t(Material::Cortical)));
    server.submitBoxCut(topBox(8));
    ASSERT_TRUE(pumpUntil({&vol}, [&] { return server.idle(); }));

    SessionClient dbi(clientConfig(presetView(sphere, "top"), Sync::Dbi));
    dbi.connect(loopback(server.port()));
    ASSERT_TRUE(connectAll({&vol, &dbi}));
    ASSERT_TRUE(waitConverged(server, {&vol, &dbi}));
    // The volume as it is now, rendered by a renderer that never saw the changes.
    const Dbi fresh = Renderer(server.volumeSnapshot()).render(toCamera(presetView(sphere, "top")));
    EXPECT_EQ(compare(dbi.dbi(), fresh).maxColorError, 0);
    server.submitBoxCut(topBox(20));
    ASSERT_TRUE(waitConverged(server, {&vol, &dbi}));
    const Dbi after = Renderer(server.volumeSnapshot()).render(toCamera(presetView(sphere, "top")));
    EXPECT_EQ(compare(dbi.dbi(), after).maxColorError, 0);
    EXPECT_GT(compare(fresh, after).differingPixels, 0) << "the last cut shows";
}

TEST(SessionVolume, SwitchingLiveWhileDrillingKeepsTheSessionConsistent) {
    Volume sphere = makeSphere(48);
    SessionServer server(sphere, loopbackServerConfig("sphere:48", 2));
    Pumped pumped(server);
    SessionClient client(clientConfig(presetView(sphere, "top"), Sync::Dbi));
    SessionClient watcher(clientConfig(presetView(sphere, "front"), Sync::Dbi));
    client.connect(loopback(server.port()));
    watcher.connect(loopback(server.port()));
    std::vector<SessionClient*> all = {&client, &watcher};
    ASSERT_TRUE(connectAll(all));
    const int kTotal = 80;
    drill(client, all, sphereTop(48), 0, 20, kTotal);
    // dbi -> volume while the drilling goes on: no wait between the request and the next states.
    client.requestSync(Sync::Volume);
    EXPECT_TRUE(client.switchingSync());
    drill(client, all, sphereTop(48), 20, 20, kTotal);
    ASSERT_TRUE(pumpUntil(all, [&] { return client.sync() == Sync::Volume; }));
    drill(client, all, sphereTop(48), 40, 20, kTotal);
    ASSERT_TRUE(waitConverged(server, all));
    // volume -> dbi, again mid-stroke, and the view changes during the switch too.
    client.requestSync(Sync::Dbi);
    drill(client, all, sphereTop(48), 60, 10, kTotal);
    client.requestView(presetView(sphere, "front"));
    drill(client, all, sphereTop(48), 70, 10, kTotal);
    ASSERT_TRUE(pumpUntil(all, [&] { return server.toolStatesApplied() == uint64_t(kTotal); }));
    ASSERT_TRUE(waitConverged(server, all));
    EXPECT_EQ(client.sync(), Sync::Dbi);
    EXPECT_EQ(client.localVolume(), nullptr);
    EXPECT_EQ(client.view(), presetView(sphere, "front"));
    EXPECT_GE(client.stats().modes[size_t(Sync::Volume)].fullUpdates, 1u);
    EXPECT_GE(client.stats().modes[size_t(Sync::Dbi)].fullUpdates, 2u);
    EXPECT_EQ(client.stats().malformed(), 0u);
    // And back to volume once more: the full volume holds everything drilled meanwhile.
    client.requestSync(Sync::Volume);
    server.submitBoxCut(topBox(24));
    ASSERT_TRUE(waitConverged(server, all));
    EXPECT_EQ(client.sync(), Sync::Volume);
}

// A switch to volume and back: the server kept the DBI view meanwhile (docs/session.md, "Kept
// views"), so the switch back takes it up, renders what the drilling changed, and the client's
// picture is the fresh render of its view bit for bit.
TEST(SessionVolume, ASwitchBackToDbiTakesUpTheViewTheServerKept) {
    Volume sphere = makeSphere(48);
    SessionServer server(sphere, loopbackServerConfig("sphere:48", 2));
    Pumped pumped(server);
    SessionClient client(clientConfig(presetView(sphere, "top"), Sync::Dbi));
    client.connect(loopback(server.port()));
    ASSERT_TRUE(connectAll({&client}));
    const Dbi before = client.dbi();
    client.requestSync(Sync::Volume);
    ASSERT_TRUE(pumpUntil({&client}, [&] { return client.sync() == Sync::Volume; }));
    drill(client, {&client}, sphereTop(48), 0, 20, 20);
    ASSERT_TRUE(pumpUntil({&client}, [&] { return server.toolStatesApplied() == 20u; }));
    client.requestSync(Sync::Dbi);
    ASSERT_TRUE(waitConverged(server, {&client}));
    EXPECT_EQ(client.sync(), Sync::Dbi);
    EXPECT_FALSE(compare(before, client.dbi()).identical()) << "the drilling shows";
    EXPECT_EQ(nlohmann::json::parse(server.reportJson()).at("views_reused").get<int>(), 1);
}

TEST(SessionVolume, MalformedSyncModeIsDroppedAndCountedByTheServer) {
    Volume sphere = makeSphere(32);
    SessionServer server(sphere, loopbackServerConfig("sphere:32", 1));
    Pumped pumped(server);
    ViewSpec view = presetView(sphere, "top");
    SessionClient client(clientConfig(view, Sync::Dbi));
    client.connect(loopback(server.port()));
    ASSERT_TRUE(connectAll({&client}));
    SyncMode m{Sync::Volume, Codec::Raw};
    std::vector<uint8_t> ok = encodeMessage(m);
    std::vector<uint8_t> truncated(ok.begin(), ok.end() - 1);
    std::vector<uint8_t> trailing = ok;
    trailing.push_back(0);
    std::vector<uint8_t> badMode = ok;
    badMode[1] = 7; // no such sync mode
    std::vector<uint8_t> badCodec = ok;
    badCodec[2] = 9;
    VolumeUpdate vu; // only the server sends voxels
    vu.sizeX = vu.sizeY = vu.sizeZ = 1;
    vu.rawBytes = 1;
    vu.payload = {0};
    std::vector<uint8_t> fromClient = encodeMessage(vu);
    ASSERT_FALSE(fromClient.empty());
    std::vector<std::vector<uint8_t>> bads = {truncated, trailing, badMode, badCodec, fromClient};
    for (auto& b : bads)
        client.sendRaw(Channel::Control, b);
    ASSERT_TRUE(pumpUntil({&client}, [&] { return server.malformedTotal() == bads.size(); }));
    EXPECT_EQ(client.sync(), Sync::Dbi);
    EXPECT_FALSE(client.closed());
    EXPECT_EQ(server.modeTotals(Sync::Volume).updates, 0u) << "no bad switch took effect";
}

TEST(SessionVolume, ClientDropsAndCountsMalformedVolumeUpdates) {
    // A fake server: a raw ENet host that welcomes the client with a 16^3 volume and sends voxels.
    trephine::testing::FakeServer fake;
    ClientConfig cfg = clientConfig(ViewSpec{}, Sync::Volume);
    cfg.view.width = cfg.view.height = 32;
    cfg.renderThreads = 1;
    SessionClient client(cfg);
    client.connect(loopback(fake.port()));
    auto pumpBoth = [&](const std::function<bool()>& pred) { return fake.pumpWith(client, pred); };
    ASSERT_TRUE(pumpBoth([&] { return fake.peer && client.connected(); }));

    Volume v = makeSphere(16);
    auto full = [&](bool corrupt) {
        VolumeUpdate u;
        u.full = true;
        u.materials = true;
        u.sizeX = u.sizeY = u.sizeZ = 16;
        EncodedVolume e = encodeVolumeFull(v, Codec::Lz4);
        u.codec = e.codec;
        u.rawBytes = e.rawBytes;
        u.payload = std::move(e.payload);
        if (corrupt)
            u.payload.resize(u.payload.size() / 2);
        return encodeMessage(u);
    };
    auto box = [&](uint16_t x, uint16_t n, size_t payloadBytes, uint32_t sequence) {
        VolumeUpdate u;
        u.sequence = sequence;
        u.x = x;
        u.sizeX = u.sizeY = u.sizeZ = n;
        u.codec = Codec::Raw;
        u.rawBytes = uint32_t(n) * n * n;
        u.payload.assign(payloadBytes, 0);
        return encodeMessage(u);
    };
    // The volume channel is not ordered with the control channel: a full volume that overtakes
    // the welcome is held, and placed once the welcome gives the dims.
    fake.send(Channel::Volume, full(false));
    fake.pumpWith(
        client, [] { return false; }, 0.2);
    EXPECT_EQ(client.localVolume(), nullptr);
    EXPECT_EQ(client.stats().malformed(), 0u);
    Welcome w;
    w.clientId = 1;
    w.volumeDims = v.dims();
    w.spacing = v.spacing();
    w.volumeName = "sphere:16";
    fake.send(Channel::Control, encodeMessage(w));
    ASSERT_TRUE(pumpBoth([&] { return client.welcomed() && client.localVolume() != nullptr; }));
    EXPECT_TRUE(*client.localVolume() == v);
    EXPECT_EQ(client.volumeUpdatesApplied(), 1u);
    fake.send(Channel::Volume, full(true));              // corrupt compression
    fake.send(Channel::Volume, full(false));             // fine
    fake.send(Channel::Volume, box(12, 8, 512, 2));      // past the volume's x edge
    fake.send(Channel::Volume, box(0, 4, 63, 3));        // payload one byte short
    fake.send(Channel::Volume, std::vector<uint8_t>{8}); // type byte only
    fake.send(Channel::Volume, box(4, 4, 64, 4));        // fine: cuts a 4^3 box to air
    ASSERT_TRUE(pumpBoth([&] { return client.stats().malformed() == 4; }));
    ASSERT_TRUE(pumpBoth([&] { return client.volumeUpdatesApplied() == 3; }));
    EXPECT_EQ(client.updatesRejected(), 3u);
    ASSERT_NE(client.localVolume(), nullptr);
    Volume expected = v;
    expected.fill(Box3i::fromMinMax({4, 0, 0}, {8, 4, 4}), 0, Material::Air);
    EXPECT_TRUE(*client.localVolume() == expected);
}

// A switch made before any update of the mode it leaves has arrived takes the new mode's first
// full update whatever the server's sequence counter, even past 2^31 (a signed comparison with
// the initial 0 took it for stale, and the client waited for ever).
TEST(SessionVolume, AFirstFullUpdatePastTwoToTheThirtyFirstIsNotStale) {
    trephine::testing::FakeServer fake;
    ClientConfig cfg = clientConfig(ViewSpec{}, Sync::Dbi);
    cfg.view.width = cfg.view.height = 32;
    cfg.renderThreads = 1;
    SessionClient client(cfg);
    client.requestSync(Sync::Volume); // before any image: the hello asks for volume
    client.connect(loopback(fake.port()));
    auto pumpBoth = [&](const std::function<bool()>& pred) { return fake.pumpWith(client, pred); };
    ASSERT_TRUE(pumpBoth([&] { return fake.peer && client.connected(); }));
    Volume v = makeSphere(16);
    Welcome w;
    w.clientId = 1;
    w.volumeDims = v.dims();
    w.spacing = v.spacing();
    w.volumeName = "sphere:16";
    fake.send(Channel::Control, encodeMessage(w));
    VolumeUpdate u;
    u.sequence = 0x80000010u;
    u.full = true;
    u.materials = true;
    u.sizeX = u.sizeY = u.sizeZ = 16;
    EncodedVolume e = encodeVolumeFull(v, Codec::Lz4);
    u.codec = e.codec;
    u.rawBytes = e.rawBytes;
    u.payload = std::move(e.payload);
    fake.send(Channel::Volume, encodeMessage(u));
    ASSERT_TRUE(pumpBoth([&] { return client.sync() == Sync::Volume; }))
        << "sync " << int(client.sync()) << ", applied " << client.volumeUpdatesApplied();
    EXPECT_TRUE(*client.localVolume() == v);
}

TEST(VolumeCodec, BoxDensitiesDeriveMaterialsAsErosionLeavesThem) {
    Volume v = makeSkull(32);
    Volume target = v;
    // Erode a box partly: some voxels to 0 (Air), some only thinner (material kept).
    Box3i box{{8, 8, 20}, {24, 24, 32}};
    for (int z = box.lo.z; z < box.hi.z; ++z)
        for (int y = box.lo.y; y < box.hi.y; ++y)
            for (int x = box.lo.x; x < box.hi.x; ++x) {
                uint8_t d = target.density(x, y, z);
                uint8_t nd = (x + y) % 2 ? 0 : uint8_t(d / 2);
                target.set(x, y, z, nd, nd ? target.material(x, y, z) : Material::Air);
            }
    for (Codec codec : {Codec::Raw, Codec::Lz4, Codec::Zstd}) {
        EncodedVolume e = encodeVolumeBox(target, box, codec);
        EXPECT_EQ(e.rawBytes, uint32_t(box.count()));
        std::vector<uint8_t> densities;
        ASSERT_TRUE(decompressBytes(e.payload, e.codec, e.rawBytes, densities));
        Volume local = v;
        ASSERT_TRUE(applyVolumeBox(local, box, densities));
        EXPECT_TRUE(local == target) << codecName(codec);
        EXPECT_FALSE(applyVolumeBox(local, Box3i{{30, 0, 0}, {33, 2, 2}}, densities));
    }
    EncodedVolume f = encodeVolumeFull(target, Codec::Raw);
    EXPECT_EQ(f.codec, Codec::Zstd) << "a full volume always travels compressed";
    Volume back;
    ASSERT_TRUE(
        decodeVolumeFull(f.payload, f.rawBytes, f.codec, target.dims(), target.spacing(), back));
    EXPECT_TRUE(back == target);
    EXPECT_FALSE(
        decodeVolumeFull(f.payload, f.rawBytes, f.codec, {32, 32, 31}, target.spacing(), back));
}

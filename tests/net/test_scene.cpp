// The scene a server sends after its welcome (net/scene.h): what it holds, that it reads back
// whole and refuses damage, that a client gets it with nothing volumetric, and that a preset names
// the same camera before and after a save and restart.
#include "net/scene.h"

#include "libsim/camera.h"
#include "libsim/error.h"
#include "libsim/skull.h"
#include "libsim/volume_io.h"
#include "net/session_client.h"
#include "net/session_server.h"
#include "net/view.h"

#include "loopback.h"
#include "test_support.h"

#include <gtest/gtest.h>

#include <sys/inotify.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <thread>

using namespace trephine;
using namespace trephine::net;
using trephine::testing::Pumped;

namespace {

std::vector<uint8_t> encoded(Scene s) {
    return encodeMessage(s);
}

} // namespace

TEST(Scene, HoldsTheExtentPresetsSiteLandmarksAndFieldOfTheVolume) {
    const Volume skull = makeSkull(64);
    const Scene s = buildScene(skull);
    EXPECT_EQ(s.dims, skull.dims());
    EXPECT_EQ(s.spacing, skull.spacing());
    EXPECT_EQ(s.extentMm, skull.extentMm());
    // Every preset libsim names, each the camera cameraPreset gives a square window.
    ASSERT_EQ(s.presets.size(), cameraPresetNames().size());
    for (const std::string& name : cameraPresetNames()) {
        const auto c = presetCamera(s, name, {kScenePresetSizePx, kScenePresetSizePx});
        ASSERT_TRUE(c) << name;
        EXPECT_EQ(*c, cameraPreset(name, skull, {kScenePresetSizePx, kScenePresetSizePx})) << name;
    }
    const SceneSite* site = findSite(s, kDefaultSiteName);
    ASSERT_NE(site, nullptr);
    const SurfaceSite want = defaultBurrSite(skull);
    EXPECT_EQ(site->position, want.position);
    EXPECT_NEAR(glm::length(site->normal - want.normal), 0.0f, 1e-6f);
    ASSERT_EQ(s.landmarks.size(), 3u);
    for (const SceneLandmark& l : s.landmarks)
        EXPECT_GT(l.position.z, 0.0f) << l.name << ": on the vault";
    EXPECT_GT(s.vertexCount, 1000u);
    EXPECT_EQ(s.indexCount, makeSurgicalField(skull, want).indices.size());
    EXPECT_LT(s.meshPayload.size(), s.meshRawBytes * 3 / 4) << "the mesh travels compressed";
    EXPECT_EQ(s.sceneId, sceneIdOf(s));
}

TEST(Scene, ReadsBackWholeWithItsMeshAndTheSameId) {
    const Volume skull = makeSkull(48);
    const Scene s = buildScene(skull);
    Scene back;
    MeshData mesh;
    ASSERT_TRUE(decodeScene(encoded(s), back, &mesh));
    EXPECT_EQ(back, s);
    const MeshData field = makeSurgicalField(skull, defaultBurrSite(skull));
    ASSERT_EQ(mesh.vertices.size(), field.vertices.size());
    ASSERT_EQ(mesh.indices, field.indices);
    for (size_t i = 0; i < mesh.vertices.size(); ++i) {
        EXPECT_EQ(mesh.vertices[i].position, field.vertices[i].position);
        EXPECT_EQ(mesh.vertices[i].normal, field.vertices[i].normal);
        EXPECT_NEAR(mesh.vertices[i].color.r, field.vertices[i].color.r, 0.5f / 255.0f);
    }
    // A volume without bone under its top still has presets and a site (looking down), no field.
    const Scene empty = buildScene(Volume({8, 8, 8}, glm::vec3(1.0f)));
    ASSERT_TRUE(decodeScene(encoded(empty), back, &mesh));
    EXPECT_EQ(back.vertexCount, 0u);
    EXPECT_TRUE(mesh.vertices.empty());
    ASSERT_NE(findSite(back, kDefaultSiteName), nullptr);
    EXPECT_EQ(findSite(back, kDefaultSiteName)->normal, glm::vec3(0, 0, 1));
}

TEST(Scene, ADamagedSceneIsRefusedNeverApplied) {
    const Scene s = buildScene(makeSkull(48));
    const std::vector<uint8_t> good = encoded(s);
    Scene back;
    // Any byte of the mesh or the lists changed: the id no longer matches (or a range fails).
    for (size_t at : {good.size() / 3, good.size() / 2, good.size() - 5}) {
        std::vector<uint8_t> bad = good;
        bad[at] ^= 0x40;
        EXPECT_FALSE(decodeScene(bad, back)) << "byte " << at;
    }
    // An index beyond the vertices, with a matching id, is refused by the mesh check.
    Scene wrong = s;
    MeshData field;
    field.vertices.resize(3);
    field.indices = {0, 1, 7};
    setSceneMesh(wrong, field);
    stampScene(wrong);
    EXPECT_FALSE(decodeScene(encoded(wrong), back));
    // The extent must be dims x spacing; a scene of another format is refused.
    Scene off = s;
    off.extentMm.x += 1.0f;
    EXPECT_TRUE(encoded(off).empty());
    std::vector<uint8_t> format = good;
    format[1] = uint8_t(kSceneFormat + 1);
    EXPECT_FALSE(decodeScene(format, back));
    // Truncated.
    EXPECT_FALSE(decodeScene(std::span<const uint8_t>(good).first(good.size() - 1), back));
}

// A DBI client gets the server's scene right after its welcome: its presets name the server's
// views, and no voxel reaches it (benchmark_net's BM_DbiJoin measures the join's bytes).
TEST(Scene, AClientGetsTheServersSceneAfterTheWelcome) {
    const Volume skull = makeSkull(64);
    SessionServer server(skull, trephine::testing::loopbackServerConfig("skull:64"));
    Pumped pumped(server);
    ClientConfig cc;
    cc.view.width = cc.view.height = 1;
    SessionClient client(cc);
    client.connect(trephine::testing::loopback(server.port()));
    ASSERT_TRUE(trephine::testing::pumpUntil({&client}, [&] { return client.scene() != nullptr; }));
    EXPECT_EQ(client.scenesReceived(), 1u);
    EXPECT_EQ(client.scene()->scene, buildScene(skull));
    EXPECT_GT(client.scene()->field.vertices.size(), 1000u);
    EXPECT_EQ(client.localVolume(), nullptr);
    const auto working = presetCamera(client.scene()->scene, "working", {64, 64});
    ASSERT_TRUE(working);
    EXPECT_EQ(*working, cameraPreset("working", skull, {64, 64}));
    EXPECT_EQ(client.stats().totalBytesIn(Channel::Volume), 0u) << "no voxels";
    server.stop();
}

// A preset names the same camera before and after a save and restart, however the skull was
// drilled at the site: the server writes its scene beside the saved volume and a server started on
// that volume serves it again. Built afresh from the drilled volume, `working` would move.
TEST(Scene, APresetNamesTheSameCameraAfterASaveAndRestart) {
    trephine::testing::TempDir dir;
    const std::string saved = dir / "session.nrrd";
    const Volume skull = makeSkull(64);
    const Scene before = buildScene(skull);
    ServerConfig sc = trephine::testing::loopbackServerConfig("skull:64");
    sc.saveOnExit = saved;
    {
        SessionServer server(skull, sc);
        Pumped pumped(server);
        // A hole at the burr site, through the outer table.
        const SceneSite& site = *findSite(before, kDefaultSiteName);
        const glm::ivec3 v = glm::ivec3(skull.toVoxel(site.position));
        server.submitBoxCut(Box3i{v - glm::ivec3(3, 3, 4), v + glm::ivec3(4, 4, 2)});
        ASSERT_TRUE(trephine::testing::waitFor([&] { return server.idle(); }));
        server.stop();
    }
    ASSERT_TRUE(std::filesystem::is_regular_file(scenePathFor(saved)));
    const Volume reopened = loadVolume(saved);
    EXPECT_NE(buildScene(reopened).presets, before.presets)
        << "the drilled site moved: a scene built afresh names another working view";
    const Scene after = sceneForVolume(reopened, saved);
    EXPECT_EQ(after, before);
    EXPECT_EQ(presetCamera(after, "working", {500, 500}),
              presetCamera(before, "working", {500, 500}));
    // And a server started on it sends that scene.
    SessionServer restarted(Volume(reopened), [&] {
        ServerConfig c = trephine::testing::loopbackServerConfig("x");
        c.scene = std::make_shared<const Scene>(after);
        return c;
    }());
    Pumped pumpedRestarted(restarted);
    ClientConfig cc;
    cc.view.width = cc.view.height = 1;
    SessionClient client(cc);
    client.connect(trephine::testing::loopback(restarted.port()));
    ASSERT_TRUE(trephine::testing::pumpUntil({&client}, [&] { return client.scene() != nullptr; }));
    EXPECT_EQ(client.scene()->scene.sceneId, before.sceneId);
    restarted.stop();
}

TEST(Scene, AMismatchedOrDamagedSceneFileIsRefusedInOneLine) {
    trephine::testing::TempDir dir;
    const std::string volume = dir / "v.nrrd";
    writeSceneFile(scenePathFor(volume), buildScene(makeSkull(48)));
    try {
        sceneForVolume(makeSkull(64), volume);
        ADD_FAILURE() << "a scene of another volume was taken";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("v.nrrd.scene is for a volume of 48x48x48"),
                  std::string::npos)
            << e.what();
    }
    std::ofstream(scenePathFor(volume), std::ios::binary) << "TRPSCN01garbage";
    try {
        readSceneFile(scenePathFor(volume));
        ADD_FAILURE() << "a damaged scene file was read";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("damaged"), std::string::npos) << e.what();
        EXPECT_EQ(std::string(e.what()).find('\n'), std::string::npos);
    }
    // No scene beside the volume: built from it.
    std::filesystem::remove(scenePathFor(volume));
    EXPECT_EQ(sceneForVolume(makeSkull(48), volume), buildScene(makeSkull(48)));
}

// No client opens a path the server names: a hostile server's welcome names a local file (here a
// watched one), and a headless trainee, started in an empty folder, takes part all the same with
// the scene alone and never opens it.
TEST(Scene, AHeadlessTraineeNeverOpensThePathTheServerNames) {
    trephine::testing::TempDir bait, empty;
    const std::string named = bait / "patient.nrrd";
    saveVolume(makeSphere(16), named);
    const int fd = inotify_init1(IN_NONBLOCK | IN_CLOEXEC);
    ASSERT_GE(fd, 0);
    ASSERT_GE(inotify_add_watch(fd, named.c_str(), IN_OPEN), 0);
    SessionServer server(makeSkull(48), trephine::testing::loopbackServerConfig(named));
    server.start(); // its threads serve the trainee processes the test waits for
    for (const char* sync : {"dbi", "volume"}) {
        const trephine::testing::CommandResult r = trephine::testing::runTrephine(
            empty, "trainee --headless --connect 127.0.0.1:" + std::to_string(server.port()) +
                       " --sync " + sync + " --camera working --size 48 --duration 0.5");
        EXPECT_EQ(r.exitCode, 0) << sync << ": " << r.err;
        EXPECT_NE(r.out.find("trainee: 127.0.0.1:"), std::string::npos) << r.out;
    }
    server.stop();
    alignas(inotify_event) char buf[4096];
    const ssize_t events = ::read(fd, buf, sizeof buf);
    ::close(fd);
    EXPECT_LE(events, 0) << "the file the server names was opened";
}

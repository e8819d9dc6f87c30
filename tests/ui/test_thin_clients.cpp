// Thin clients: every client kind (trainee window, instructor window, headless trainee), in both
// designs, joins with the server's address alone, from an empty working folder, against a server
// whose volume file the clients cannot use; each gets the server's picture of its view and none
// opens the file the server names. And picking on the DBI finds the bone a ray cast on the volume
// finds. Windows need a display (xvfb-run).
#include "gl_window_test.h"
#include "ui/mouse_tool.h"
#include "ui/trainer_app.h"

#include "libsim/camera.h"
#include "libsim/renderer.h"
#include "libsim/skull.h"
#include "libsim/volume_io.h"
#include "libsim_image/dbi_io.h"
#include "net/scene.h"
#include "net/session_client.h"
#include "net/session_server.h"
#include "net/view.h"

#include "loopback.h"
#include "test_support.h"

#include <gtest/gtest.h>

#include <sys/inotify.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <filesystem>
#include <string>
#include <thread>

using namespace trephine;
using namespace trephine::ui;
using trephine::testing::shellQuote;
using trephine::testing::TempDir;

namespace {

constexpr int kView = 96;

// Opens of one file, by any process, seen through inotify.
struct OpenWatch {
    int fd = -1;
    explicit OpenWatch(const std::string& path) {
        fd = inotify_init1(IN_NONBLOCK | IN_CLOEXEC);
        if (fd >= 0 && inotify_add_watch(fd, path.c_str(), IN_OPEN) < 0) {
            ::close(fd);
            fd = -1;
        }
    }
    ~OpenWatch() {
        if (fd >= 0)
            ::close(fd);
    }
    // Opens since the last call; -1 when the watch could not be set.
    int opens() {
        if (fd < 0)
            return -1;
        alignas(inotify_event) char buf[4096];
        int n = 0;
        for (;;) {
            const ssize_t len = ::read(fd, buf, sizeof buf);
            if (len <= 0)
                return n;
            for (ssize_t at = 0; at < len;) {
                const auto* ev = reinterpret_cast<const inotify_event*>(buf + at);
                n += (ev->mask & IN_OPEN) != 0;
                at += ssize_t(sizeof(inotify_event) + ev->len);
            }
        }
    }
};

// Runs in `dir` while alive (the clients' empty working folder).
struct InFolder {
    std::filesystem::path was = std::filesystem::current_path();
    explicit InFolder(const std::filesystem::path& dir) { std::filesystem::current_path(dir); }
    ~InFolder() { std::filesystem::current_path(was); }
};

// How far a client's picture is from the server's render of the same view: pixels whose
// hit/miss differs, and pixels hit in both whose colour differs by more than a few levels or
// whose depth differs by more than a voxel's worth.
struct Agreement {
    int64_t bothHit = 0, maskMismatch = 0, off = 0;
};
Agreement agree(const Dbi& client, const Dbi& server, const Camera& camera, float voxelMm) {
    Agreement a;
    for (int y = 0; y < server.height(); ++y)
        for (int x = 0; x < server.width(); ++x) {
            const bool hc = client.depth(x, y) < 1.0f, hs = server.depth(x, y) < 1.0f;
            if (hc != hs) {
                ++a.maskMismatch;
                continue;
            }
            if (!hc)
                continue;
            ++a.bothHit;
            int diff = 0;
            for (int c = 0; c < 3; ++c)
                diff = std::max(diff,
                                std::abs(int(client.color(x, y)[c]) - int(server.color(x, y)[c])));
            const double dz = std::abs(eyeZFromWindowDepth(camera, client.depth(x, y)) -
                                       eyeZFromWindowDepth(camera, server.depth(x, y)));
            a.off += diff > 6 || dz > voxelMm;
        }
    return a;
}

// `minHit`: the fraction of the view that shows bone at least (an overview frames the whole
// volume's bounding sphere: the skull covers a tenth of it).
void expectSamePicture(const Dbi& client, const Dbi& server, const Camera& camera, float voxelMm,
                       const std::string& who, double minHit = 1.0 / 8.0) {
    ASSERT_EQ(client.width(), server.width()) << who;
    ASSERT_EQ(client.height(), server.height()) << who;
    const Agreement a = agree(client, server, camera, voxelMm);
    EXPECT_GT(double(a.bothHit), minHit * server.width() * server.height()) << who;
    EXPECT_LE(a.maskMismatch, a.bothHit / 100) << who << ": hit/miss differs only on silhouettes";
    EXPECT_LE(a.off, a.bothHit / 100) << who << ": colours and depths agree";
}

} // namespace

TEST(ThinClients, EveryClientKindInBothDesignsJoinsWithTheAddressAlone) {
    TREPHINE_NEED_DISPLAY("the windows");
    TempDir serverDir, clientDir;
    const std::string file = serverDir / "patient.nrrd";
    saveVolume(makeSkull(64), file);
    const Volume skull = loadVolume(file);
    // The path the server names now holds another volume: a client that opened it would get
    // other presets, another site and another picture. And the watch sees any open of it.
    saveVolume(makeSphere(32), file);
    OpenWatch watch(file);
    ASSERT_GE(watch.opens(), 0) << "inotify";
    net::SessionServer server(skull, trephine::testing::loopbackServerConfig(file, 2));
    trephine::testing::Pumped pumped(server);
    const std::string address = "127.0.0.1:" + std::to_string(server.port());
    const net::Scene scene = net::buildScene(skull);
    const float voxelMm = skull.spacing().x;
    InFolder inEmpty(clientDir.path);

    for (const bool instructor : {false, true})
        for (const std::string sync : {"dbi", "volume"}) {
            const std::string who =
                std::string(instructor ? "instructor" : "trainee") + " window, " + sync;
            TrainerReport report;
            TrainerOptions o;
            o.address = address;
            o.instructor = instructor;
            o.name = instructor ? "ins" : "tra";
            o.sync = sync;
            o.camera = "working";
            o.size = kView;
            o.screenshot = clientDir / "shot.png";
            o.frames = 2;
            o.timeoutS = 100.0;
            o.visible = false;
            o.report = &report;
            ASSERT_EQ(trephine::testing::whilePumping([&] { return runTrainerWindow(o); }), 0)
                << who;
            const Camera want = *net::presetCamera(scene, "working", {kView, kView});
            EXPECT_LT(glm::length(report.camera.eye - want.eye), 1e-3f) << who;
            EXPECT_EQ(report.camera.target, want.target) << who;
            expectSamePicture(report.view, server.renderView(net::toViewSpec(report.camera)),
                              report.camera, voxelMm, who);
        }

    // The headless trainee drills the burr hole at the server's site, then its picture is the
    // server's render of the drilled skull.
    for (const std::string sync : {"dbi", "volume"}) {
        const std::string exr = clientDir / ("headless-" + sync + ".exr");
        const std::string args = "trainee --headless --connect " + address + " --sync " + sync +
                                 " --camera working --size " + std::to_string(kView) +
                                 " --duration 1 --save-dbi " + shellQuote(exr);
        const trephine::testing::CommandResult r = trephine::testing::whilePumping(
            [&] { return trephine::testing::runTrephine(clientDir, args); });
        ASSERT_EQ(r.exitCode, 0) << r.err;
        const Camera camera = *net::presetCamera(scene, "working", {kView, kView});
        expectSamePicture(readDbiExr(exr).image, server.renderView(net::toViewSpec(camera)), camera,
                          voxelMm, "headless trainee, " + sync);
    }
    server.stop();
    EXPECT_EQ(watch.opens(), 0) << "no client opened the file the server names";
    // Nothing was written where the clients ran but what they were asked to write.
    for (const auto& e : std::filesystem::directory_iterator(clientDir.path)) {
        const std::string name = e.path().filename().string();
        EXPECT_TRUE(name == "shot.png" || name.rfind("headless-", 0) == 0 ||
                    name.rfind("std", 0) == 0)
            << name;
    }
}

// Picking reads the DBI's depth (16-bit linear codes over lz4) and unprojects it: the point is the
// one a ray cast on the server's volume finds through that pixel, within a voxel.
TEST(ThinClients, PickingOnTheDbiFindsTheVolumesSurfaceWithinAVoxel) {
    const Volume skull = makeSkull(64);
    net::SessionServer server(skull, trephine::testing::loopbackServerConfig("skull:64"));
    trephine::testing::Pumped pumped(server);
    net::ClientConfig cc;
    cc.view.width = cc.view.height = 1;
    cc.codec = net::Codec::Lz4;
    net::SessionClient client(cc);
    client.connect(trephine::testing::loopback(server.port()));
    ASSERT_TRUE(trephine::testing::pumpUntil({&client}, [&] { return client.scene() != nullptr; }));
    const Camera camera = *net::presetCamera(client.scene()->scene, "working", {128, 128});
    ASSERT_NE(client.requestView(net::toViewSpec(camera)), 0u);
    ASSERT_TRUE(trephine::testing::pumpUntil({&client}, [&] { return client.hasFullImage(); }));
    const Renderer volumeCast(skull);
    int picked = 0;
    for (int y = 4; y < 128; y += 8)
        for (int x = 4; x < 128; x += 8) {
            const RayHit hit = volumeCast.castRay(camera, x, y);
            const std::optional<glm::vec3> p = pickSurface(client.dbi(), camera, x, y);
            ASSERT_EQ(p.has_value(), hit.hit) << x << "," << y;
            if (!p)
                continue;
            ++picked;
            EXPECT_LT(glm::length(glm::dvec3(*p) - hit.position), double(skull.spacing().x))
                << "pixel " << x << "," << y;
        }
    EXPECT_GT(picked, 100);
    server.stop();
}

// A server of skull:64 with trainee "alex" on it (the "left" preset, 80 x 80) polled on a thread of
// its own, and the options of instructor "ines" viewing as alex from its own "top" camera.
struct AlexOnAServer {
    const Volume skull = makeSkull(64);
    net::SessionServer server{skull, trephine::testing::loopbackServerConfig("skull:64", 2)};
    trephine::testing::Pumped pumped{server};
    net::ClientConfig tc = alexConfig(skull);
    net::SessionClient trainee{tc};
    std::atomic<bool> stop{false};
    std::thread pump;

    static net::ClientConfig alexConfig(const Volume& skull) {
        net::ClientConfig c =
            trephine::testing::namedClientConfig(skull, "alex", net::Role::Trainee, 80);
        c.view = net::toViewSpec(cameraPreset("left", skull, {80, 80}));
        return c;
    }
    // False when alex got no picture.
    bool start() {
        trainee.connect(trephine::testing::loopback(server.port()));
        if (!trephine::testing::pumpUntil({&trainee}, [&] { return trainee.hasFullImage(); }))
            return false;
        pump = std::thread([this] {
            while (!stop)
                trainee.poll(1);
        });
        return true;
    }
    TrainerOptions instructor() const {
        TrainerOptions o;
        o.address = "127.0.0.1:" + std::to_string(server.port());
        o.instructor = true;
        o.name = "ines";
        o.viewAs = "alex";
        o.camera = "top";
        o.timeoutS = 100.0;
        o.visible = false;
        return o;
    }
    int run(const TrainerOptions& o) {
        const int rc = trephine::testing::whilePumping([&] { return runTrainerWindow(o); });
        stop = true;
        if (pump.joinable())
            pump.join();
        return rc;
    }
    ~AlexOnAServer() {
        stop = true;
        if (pump.joinable())
            pump.join();
    }
};

// `trephine instructor --view-as alex`: the instructor's window shows the server's picture of the
// trainee's camera, at the window's own size.
TEST(ThinClients, AnInstructorViewsAsATraineeThroughItsCamera) {
    TREPHINE_NEED_DISPLAY("the instructor window");
    AlexOnAServer a;
    ASSERT_TRUE(a.start());
    const Volume& skull = a.skull;
    net::SessionServer& server = a.server;
    const net::ClientConfig& tc = a.tc;
    TempDir dir;
    TrainerReport report;
    TrainerOptions o = a.instructor();
    o.size = kView;
    o.screenshot = dir / "as.png";
    o.frames = 2;
    o.report = &report;
    const int rc = a.run(o);
    ASSERT_EQ(rc, 0);
    net::ViewSpec want = tc.view;
    want.width = want.height = kView;
    EXPECT_EQ(net::toViewSpec(report.camera), want);
    expectSamePicture(report.view, server.renderView(want), report.camera, skull.spacing().x,
                      "viewing as alex", 1.0 / 20.0);
    server.stop();
}

// An instructor viewing as a trainee resizes its window: it goes on seeing the trainee's camera,
// at the new size, not its own.
TEST(ThinClients, AnInstructorViewingAsATraineeKeepsItsCameraThroughAResize) {
    TREPHINE_NEED_DISPLAY("the instructor window");
    AlexOnAServer a;
    ASSERT_TRUE(a.start());
    const net::ClientConfig& tc = a.tc;
    std::atomic<bool> quit{false};
    std::vector<Camera> pictures;
    double resizedAt = -1.0;
    TrainerReport report;
    TrainerOptions o = a.instructor();
    o.size = 200; // a 980 x 760 window
    o.quit = &quit;
    o.report = &report;
    o.onPicture = [&](const Camera& c) { pictures.push_back(c); };
    o.input = [&](double t) {
        InjectedInput in;
        quit = quit || t > 30.0;
        const bool asAlex = !pictures.empty() && pictures.back().eye == toCamera(tc.view).eye;
        if (resizedAt < 0.0 && t > 0.3 && asAlex)
            resizedAt = t;
        if (resizedAt >= 0.0) {
            in.windowWidth = 1100, in.windowHeight = 820;
            quit = quit || (t - resizedAt > 0.3 && pictures.back().width != 200);
        }
        in.done = quit;
        return in;
    };
    const int rc = a.run(o);
    a.server.stop();
    ASSERT_EQ(rc, 0);
    ASSERT_GE(resizedAt, 0.0) << "the trainee's picture never came";
    const net::ViewSpec got = net::toViewSpec(report.camera);
    EXPECT_NE(got.width, 200) << "the picture of the new size";
    EXPECT_EQ(got.eye, tc.view.eye) << "the trainee's camera, not the instructor's own";
    EXPECT_EQ(got.target, tc.view.target);
}

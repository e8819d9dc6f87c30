// The trainee window in both designs of issue 7 against an in-process server (needs a display:
// xvfb-run): in volume mode it ray casts its own copy of the volume and shows the skull and the
// drilled hole as the server renders them; switched live DBI -> volume -> DBI while a script
// drills, it ends with exactly the server's picture (nothing lost), with local haptics while the
// volume fed the picture, and the Comparison panel holds figures of both designs. Deadlines only
// guard against hangs; nothing asserts wall time.
#include "gl_window_test.h"
#include "ui/trainer_app.h"
#include "ui/window.h"

#include "libsim/camera.h"
#include "libsim/renderer.h"
#include "libsim/skull.h"
#include "net/session_server.h"
#include "net/trainee_core.h"
#include "net/view.h"

#include "loopback.h"
#include "screenshot.h"
#include "test_support.h"

#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <functional>
#include <memory>
#include <string>
#include <thread>

using namespace trephine;
using namespace trephine::ui;

namespace {

using trephine::testing::Image;
using trephine::testing::Pumped;
using trephine::testing::readPng;
using trephine::testing::TempDir;
using trephine::testing::whilePumping;

constexpr int kView = 256; // small: llvmpipe ray casts on the CPU

bool boneColoured(const uint8_t* p) {
    return p[0] > 150 && p[1] > 140 && p[2] > 110 && p[0] >= p[2] && p[0] - p[2] < 90;
}

int maxChannelDiff(const uint8_t* a, const uint8_t* b) {
    return std::max({std::abs(a[0] - b[0]), std::abs(a[1] - b[1]), std::abs(a[2] - b[2])});
}

// Waits for `pred` up to `seconds`, pumping the pumped server meanwhile (a guard against hangs,
// not a timing assertion).
bool waitFor(const std::function<bool()>& pred, double seconds = 60.0) {
    return trephine::testing::waitFor(pred, seconds);
}

// A server of `volume` named `name`, on `port` (0: any free one), pumped by the test.
struct PumpedServer {
    std::unique_ptr<net::SessionServer> server;
    std::unique_ptr<Pumped> pumped;

    PumpedServer(const Volume& volume, const std::string& name, uint16_t port = 0) {
        net::ServerConfig sc = trephine::testing::loopbackServerConfig(name);
        sc.port = port;
        server = std::make_unique<net::SessionServer>(volume, sc);
        pumped = std::make_unique<Pumped>(*server);
    }
    ~PumpedServer() { stop(); }
    PumpedServer(const PumpedServer&) = delete;
    PumpedServer& operator=(const PumpedServer&) = delete;
    net::SessionServer* operator->() { return server.get(); }
    // Gone from its port (idempotent).
    void stop() {
        if (server)
            server->stop();
        pumped.reset();
        server.reset();
    }
};

// A hidden 128-pixel window of the top view on 127.0.0.1:`port`.
TrainerOptions hiddenTopWindow(uint16_t port) {
    TrainerOptions o;
    o.address = "127.0.0.1:" + std::to_string(port);
    o.camera = "top";
    o.size = 128;
    o.visible = false;
    return o;
}

// runTrainerWindow(options) on a thread of its own, with its report; close() quits it as its
// close button would (if it is still open) and gives its exit code.
struct WindowThread {
    TrainerReport report;
    std::atomic<bool> quit{false}, done{false};
    std::atomic<int> pictures{0};          // whole pictures the view has taken in
    std::atomic<float> pictureDistance{0}; // eye to target of the last one's camera
    int rc = -1;
    std::thread thread;

    explicit WindowThread(TrainerOptions o) {
        o.report = &report;
        o.quit = &quit;
        o.onPicture = [this](const Camera& c) {
            pictureDistance = glm::length(c.eye - c.target);
            ++pictures;
        };
        thread = std::thread([this, o] {
            rc = runTrainerWindow(o);
            done = true;
        });
    }
    int close() {
        quit = true;
        if (thread.joinable())
            thread.join();
        return rc;
    }
    ~WindowThread() { close(); }
};

// The window's options for a scripted burr hole on an in-process server.
TrainerOptions windowOptions(uint16_t port, const std::string& sync, const std::string& shot,
                             TrainerReport* report) {
    TrainerOptions o;
    o.address = "127.0.0.1:" + std::to_string(port);
    o.sync = sync;
    o.size = kView;
    o.script = "burrhole";
    o.screenshot = shot;
    o.frames = 2;
    o.timeoutS = 100.0;
    o.visible = false;
    o.report = report;
    return o;
}

// How far a volume-mode picture (GPU ray cast) is from the server's CPU render of the same view:
// pixels whose hit/miss differs, and pixels hit in both whose colour differs by more than a few
// levels (the ray caster's own tests bound both on llvmpipe).
struct PictureAgreement {
    int64_t bothHit = 0, maskMismatch = 0, colourOff = 0;
};
PictureAgreement agree(const Dbi& gpu, const Dbi& cpu) {
    PictureAgreement a;
    for (int y = 0; y < cpu.height(); ++y)
        for (int x = 0; x < cpu.width(); ++x) {
            const bool hg = gpu.depth(x, y) < 1.0f, hc = cpu.depth(x, y) < 1.0f;
            if (hg != hc) {
                ++a.maskMismatch;
                continue;
            }
            if (!hg)
                continue;
            ++a.bothHit;
            a.colourOff += maxChannelDiff(gpu.color(x, y), cpu.color(x, y)) > 6;
        }
    return a;
}

} // namespace

TEST(ComparisonWindow, VolumeModeShowsTheSkullAndTheDrilledHole) {
    TREPHINE_NEED_DISPLAY("the window");
    const Volume skull = makeSkull(64);
    net::SessionServer server(skull, trephine::testing::loopbackServerConfig("skull:64", 2));
    Pumped pumped(server);
    TempDir dir;
    TrainerReport report;
    const std::string shot = dir / "volume.png";
    const TrainerOptions o = windowOptions(server.port(), "volume", shot, &report);
    ASSERT_EQ(whilePumping([&] { return runTrainerWindow(o); }), 0);

    EXPECT_EQ(report.picture, SyncDesign::Volume);
    EXPECT_GE(report.volumeUploads, 1u) << "the whole volume at join";
    EXPECT_GT(report.volumeBoxUpdates, 0u) << "the drilled boxes";
    EXPECT_EQ(report.frames[int(SyncDesign::Dbi)], 0u) << "no DBI frame in volume mode";
    EXPECT_GT(report.localForceTicks, 0u) << "haptics computed on the local volume";
    ASSERT_TRUE(report.comparison.measured(SyncDesign::Volume));
    EXPECT_FALSE(report.comparison.measured(SyncDesign::Dbi));
    EXPECT_GT(report.comparison.series(SyncDesign::Volume).last.frameMs, 0.0);
    EXPECT_GT(report.comparison.series(SyncDesign::Volume).last.hapticHz, 0.0);

    // The window's picture (pass 1, read back) is the server's render of its view.
    ASSERT_EQ(report.view.width(), kView);
    ASSERT_EQ(report.view.height(), kView);
    const net::ViewSpec view = net::toViewSpec(report.camera);
    const Dbi truth = server.renderView(view);
    const PictureAgreement a = agree(report.view, truth);
    EXPECT_GT(a.bothHit, int64_t(kView) * kView / 4);
    EXPECT_LT(a.maskMismatch, a.bothHit / 100) << "hit/miss differs only on silhouettes";
    EXPECT_LT(a.colourOff, a.bothHit / 100) << "colours agree within a few levels";

    // The screenshot is bone-coloured where the server's render has bone (a ring away from the
    // resting drill, outside the hole); and at the site the picture's bone lies deeper than the
    // intact skull's.
    const Dbi intact = Renderer(skull).render(report.camera);
    Image img = readPng(shot);
    ASSERT_GE(img.w, kView);
    ASSERT_GE(img.h, kView);
    const double c = kView * 0.5;
    int ring = 0, ringBone = 0, centre = 0, centreChanged = 0;
    for (int y = 0; y < kView; ++y)
        for (int x = 0; x < kView; ++x) {
            const int row = kView - 1 - y; // the view is at the window's top left, rows top-down
            const double r = std::hypot(x + 0.5 - c, row + 0.5 - c);
            if (r > kView * 0.16 && r < kView * 0.2 && x > c && truth.depth(x, y) < 1.0f) {
                ++ring;
                ringBone += boneColoured(img.at(x, row));
            }
            if (r < kView * 0.024) {
                // In the picture itself (the screenshot has the fading dirty boxes over the site,
                // which alone changed most of these pixels while they were fresh): the bone seen
                // there lies deeper than the intact skull's.
                ++centre;
                centreChanged += report.view.depth(x, y) > intact.depth(x, y) + 1e-4f;
            }
        }
    EXPECT_GT(ring, 100);
    EXPECT_GT(ringBone, ring * 8 / 10) << "bone-coloured where the server's render has bone";
    EXPECT_GT(centreChanged, centre * 3 / 4) << "the drilled hole at the site";
    server.stop();
}

TEST(ComparisonWindow, LiveSwitchDbiVolumeDbiLosesNoDrillingAndFillsBothFigures) {
    TREPHINE_NEED_DISPLAY("the window");
    const Volume skull = makeSkull(64);
    net::SessionServer server(skull, trephine::testing::loopbackServerConfig("skull:64", 2));
    Pumped pumped(server);
    TempDir dir;
    TrainerReport report;
    TrainerOptions o = windowOptions(server.port(), "dbi", dir / "switch.png", &report);
    // The burr hole's script drills from 0 to 4 s after the first picture: both switches happen
    // while it drills (each waits for the one before it to complete). The volume design feeds the
    // picture for 2.4 s: at least two of the window's 1 s ticks, one of them clear of a switch
    // (no Comparison point is taken while a switch is under way).
    o.switchSyncAtS = {1.0, 3.4};
    ASSERT_EQ(whilePumping([&] { return runTrainerWindow(o); }), 0);

    EXPECT_EQ(report.switchesRequested, 2);
    EXPECT_EQ(report.switchesCompleted, 2);
    EXPECT_EQ(report.picture, SyncDesign::Dbi);
    EXPECT_GT(report.frames[int(SyncDesign::Dbi)], 0u);
    EXPECT_GT(report.frames[int(SyncDesign::Volume)], 0u);
    EXPECT_GE(report.volumeUploads, 1u) << "the whole volume at the switch";
    EXPECT_GT(report.localForceTicks, 0u) << "local haptics while the volume fed the picture";
    EXPECT_GT(report.serverForceTicks, 0u) << "the server's models in DBI mode";

    // The picture after the switches is exactly the server's render: no drilling was lost.
    const Dbi truth = server.renderView(net::toViewSpec(report.camera));
    ASSERT_EQ(report.view.width(), kView);
    const DbiDiff diff = compare(report.view, truth);
    EXPECT_EQ(diff.maxColorError, 0) << diff.describe();
    EXPECT_LT(diff.maxDepthError, 1e-5f) << diff.describe();
    const Dbi intact = Renderer(skull).render(report.camera);
    EXPECT_GT(compare(intact, truth).differingPixels, 0) << "the script drilled";

    // The Comparison panel's data: both designs measured, the DBI active at the end.
    const ComparisonHistory& h = report.comparison;
    ASSERT_TRUE(h.measured(SyncDesign::Dbi));
    ASSERT_TRUE(h.measured(SyncDesign::Volume));
    EXPECT_EQ(h.active, SyncDesign::Dbi);
    for (SyncDesign d : {SyncDesign::Dbi, SyncDesign::Volume}) {
        const ComparisonHistory::Series& s = h.series(d);
        SCOPED_TRACE(syncDesignName(d));
        EXPECT_GT(s.points, 0u);
        EXPECT_EQ(s.frameMs.size(), std::min(s.points, h.seriesLength));
        EXPECT_GT(s.last.frameMs, 0.0);
        EXPECT_GT(s.last.hapticHz, 0.0);
        EXPECT_GT(s.last.bytesPerUpdate, 0.0);
        EXPECT_GE(s.last.rawBytesPerUpdate, s.last.bytesPerUpdate * 0.99);
        // Latency runs to the end of the frame that drew the update, so it holds most of a
        // frame (updates are taken at the frame's start).
        EXPECT_GT(s.last.latencyP50Ms, 0.5 * s.last.frameMs);
    }
    // Incremental updates only: the whole volume sent at the switch (64^3 bytes raw) is not an
    // update of the drilling.
    EXPECT_LT(h.series(SyncDesign::Volume).last.rawBytesPerUpdate, 64.0 * 64 * 64 / 8);
    server.stop();
}

// A screenshot the window cannot write ends it with the error (the haptic thread stopped before
// the client it sends to is destroyed), not a crash.
TEST(ComparisonWindow, AnUnwritableScreenshotEndsTheWindowWithItsError) {
    TREPHINE_NEED_DISPLAY("the window");
    const Volume skull = makeSkull(64);
    net::SessionServer server(skull, trephine::testing::loopbackServerConfig("skull:64", 2));
    Pumped pumped(server);
    TrainerOptions o = windowOptions(server.port(), "volume", "/nonexistent-dir/shot.png", nullptr);
    try {
        whilePumping([&] { return runTrainerWindow(o); });
        FAIL() << "expected the screenshot's error";
    } catch (const std::exception& e) {
        EXPECT_NE(std::string(e.what()).find("/nonexistent-dir/shot.png"), std::string::npos)
            << e.what();
    }
    server.stop();
}

// The server restarts on the same port with another volume while the window is open: the
// window rejoins and rebuilds its scene and camera for the new volume (the old skull's scalp,
// drape and camera stayed, around the new volume's picture).
TEST(ComparisonWindow, AReconnectToAnotherVolumeRebuildsTheScene) {
    TREPHINE_NEED_DISPLAY("the window");
    const Volume first = makeSphere(32), second = makeBox(48);
    auto distance = [](const Camera& c) { return glm::length(c.eye - c.target); };
    const float boxTop = distance(cameraPreset("top", second, {128, 128}));
    const float sphereTop = distance(cameraPreset("top", first, {128, 128}));
    ASSERT_GT(std::abs(boxTop - sphereTop), 5.0f) << "the two volumes' views differ";
    PumpedServer server(first, "sphere:32");
    const uint16_t port = server->port();
    WindowThread window(hiddenTopWindow(port));
    // The window shows its own view of the sphere (not the hello's placeholder); then the server
    // goes, and a new one serves the box on the same port. Counting the server's renders could
    // not tell: a view asked for before the placeholder was rendered replaces it unrendered.
    auto showing = [&](float d) { return std::abs(window.pictureDistance - d) < 0.5f; };
    const bool joined = waitFor([&] { return showing(sphereTop); });
    server.stop();
    PumpedServer box(second, "box:48", port);
    // Rejoined, with the scene and camera rebuilt for the box and its picture shown.
    const bool rejoined = waitFor([&] { return showing(boxTop); });
    const int rc = whilePumping([&] { return window.close(); });
    ASSERT_TRUE(joined);
    ASSERT_TRUE(rejoined);
    ASSERT_EQ(rc, 0);
    EXPECT_NEAR(distance(window.report.camera), boxTop, 0.5f) << "the new volume's camera";
}

// A volume the server names that this machine does not have: the window never opens it (the scene
// comes from the server), so the picture comes at once, and again from the server restarted on
// the same port (the same scene: the view it asked for rides on the new hello). The window used
// to open the named volume itself, fail, and wait for good.
TEST(ComparisonWindow, AVolumeNamedButNotOnThisMachineStillGivesThePictureAfterReconnects) {
    TREPHINE_NEED_DISPLAY("the window");
    const Volume sphere = makeSphere(32);
    PumpedServer server(sphere, "/nonexistent/scan.nrrd");
    const uint16_t port = server->port();
    WindowThread window(hiddenTopWindow(port));
    const bool joined = waitFor([&] { return server->clientCount() >= 1; });
    // The view the window asks for from the scene's preset, shown.
    const float top = glm::length(cameraPreset("top", sphere, {128, 128}).eye -
                                  cameraPreset("top", sphere, {128, 128}).target);
    const bool pictured = waitFor([&] { return std::abs(window.pictureDistance - top) < 0.5f; });
    server.stop();
    const int before = window.pictures;
    PumpedServer again(sphere, "sphere:32", port);
    const bool viewed = waitFor([&] {
        return again->clientCount() >= 1 && again->rendersDone() >= 1 && window.pictures > before;
    });
    const int rc = whilePumping([&] { return window.close(); });
    again.stop();
    ASSERT_TRUE(joined);
    EXPECT_TRUE(pictured) << "no view asked of a server whose volume file is not here";
    EXPECT_TRUE(viewed) << "no view asked of the restarted server";
    EXPECT_EQ(rc, 0);
    EXPECT_EQ(window.report.view.width(), 128);
}

// A --frames run whose server goes away counted the last picture's frames on and exited 0 (and in
// volume mode never ended): frames count only while connected, and --timeout without one fails.
TEST(ComparisonWindow, AFramesRunWhoseServerGoesAwayFails) {
    TREPHINE_NEED_DISPLAY("the window");
    const Volume sphere = makeSphere(32);
    PumpedServer server(sphere, "sphere:32");
    TrainerOptions o = hiddenTopWindow(server->port());
    o.frames = 1000000; // hours of frames: the run ends by failing, or not at all
    o.timeoutS = 5.0;
    WindowThread window(o);
    const bool pictured = waitFor([&] { return window.pictures >= 1; });
    trephine::testing::pumpFor(0.3); // frames counted while connected, before the server goes
    server.stop();
    const bool ended = waitFor([&] { return window.done.load(); }, 30.0);
    const int rc = window.close(); // the guard, were it still running
    ASSERT_TRUE(pictured);
    EXPECT_TRUE(ended) << "still counting frames 30 s after the server went";
    EXPECT_EQ(rc, 1);
}

// Closed before its --screenshot (here: while still connecting to nothing), the window exited 0
// with no PNG, which a script took for done.
TEST(ComparisonWindow, AWindowClosedBeforeItsScreenshotExits1) {
    TREPHINE_NEED_DISPLAY("the window");
    TempDir dir;
    TrainerOptions o = hiddenTopWindow(9); // port 9: nothing answers
    o.screenshot = dir / "shot.png";
    WindowThread window(o);
    std::this_thread::sleep_for(std::chrono::milliseconds(500));
    EXPECT_EQ(window.close(), 1);
    EXPECT_FALSE(std::filesystem::exists(dir / "shot.png"));
}

// A window whose view is larger than the server serves waited for its first image for good,
// "Waiting for the first image" on screen: the limit is said, and a scripted run ends with exit 1.
TEST(ComparisonWindow, AViewLargerThanTheServerServesIsSaid) {
    TREPHINE_NEED_DISPLAY("the window");
    const Volume sphere = makeSphere(32);
    net::ServerConfig sc = trephine::testing::loopbackServerConfig("sphere:32");
    sc.maxViewPixels = 100 * 100;
    net::SessionServer server(sphere, sc);
    Pumped pumped(server);
    TrainerOptions o = hiddenTopWindow(server.port());
    o.frames = 5;
    o.timeoutS = 60.0;
    ::testing::internal::CaptureStderr();
    const int rc = whilePumping([&] { return runTrainerWindow(o); });
    const std::string err = ::testing::internal::GetCapturedStderr();
    server.stop();
    EXPECT_EQ(rc, 1);
    EXPECT_NE(err.find("The server serves views of at most 10000 pixels; this view is 128 x 128: "
                       "restart with --size 100 or less"),
              std::string::npos)
        << err;
}

// The window and the headless trainee run one client core and fold one client model, so one
// session gives both the same figures: here both watch the top of the sphere while the server cuts
// it box by box (each cut one update to each), and their reports agree on every count they share.
TEST(ComparisonWindow, TheWindowAndTheHeadlessTraineeReportTheSameFigures) {
    TREPHINE_NEED_DISPLAY("the window");
    const Volume sphere = makeSphere(32);
    // Stays threaded: the window's last frames cannot be seen from here, so the end is a wait.
    auto server = std::make_unique<net::SessionServer>(
        sphere, trephine::testing::loopbackServerConfig("sphere:32"));
    server->start();
    TrainerOptions wo = hiddenTopWindow(server->port());
    wo.codec = "raw"; // bytes follow the rectangles alone
    WindowThread window(wo);

    // The headless trainee's way (apps/mode_trainee.cpp): a placeholder view, then its preset.
    net::TraineeCoreConfig cc;
    cc.client.address = "127.0.0.1:" + std::to_string(server->port());
    cc.client.client.codec = net::Codec::Raw;
    cc.client.client.view.width = cc.client.client.view.height = 1;
    net::TraineeCore core(cc);
    net::HeadlessView headless(wo.size);
    core.connect();
    ASSERT_TRUE(headless.waitFor(core.client(), 30.0, [&] { return headless.connected(); }));
    core.client().requestView(net::toViewSpec(cameraPreset("top", sphere, {wo.size, wo.size})));
    ASSERT_TRUE(headless.waitFor(core.client(), 30.0, [&] { return headless.hasPicture(); }));
    // Both hold their picture before the cuts.
    ASSERT_TRUE(waitFor([&] { return window.pictures >= 1 && server->idle(); }));
    std::this_thread::sleep_for(std::chrono::milliseconds(500));
    constexpr int kCuts = 4;
    for (int i = 0; i < kCuts; ++i) {
        server->submitBoxCut(Box3i{{12 + i, 12, 26}, {14 + i, 16, 32}});
        ASSERT_TRUE(waitFor([&] { return server->idle(); }));
        std::this_thread::sleep_for(std::chrono::milliseconds(100));
    }
    ASSERT_TRUE(headless.waitFor(core.client(), 10.0, [&] {
        return headless.snap()->updatesApplied - headless.snap()->fullUpdates >= kCuts;
    }));
    std::this_thread::sleep_for(std::chrono::milliseconds(500)); // the window's last frames
    headless.take(core.client(), 0);
    core.stop();
    ASSERT_EQ(window.close(), 0);
    server->stop();

    const nlohmann::ordered_json& w = window.report.session;
    net::ClientReportExtras extras = core.reportExtras();
    extras.session = {{"server", wo.address}, {"codec", "raw"}, {"name", wo.name}, {"sync", "dbi"}};
    const nlohmann::ordered_json h = headless.model.report(extras);
    ASSERT_FALSE(w.empty());
    // One schema: every field of one report is in the other.
    for (const auto& [key, value] : h.items())
        EXPECT_TRUE(w.contains(key)) << key;
    for (const auto& [key, value] : w.items())
        EXPECT_TRUE(h.contains(key)) << key;
    for (const char* key : {"updates_rejected", "malformed_dropped", "updates_shown"})
        EXPECT_EQ(w.at(key), h.at(key))
            << key << "\nwindow " << w.dump() << "\nheadless " << h.dump();
    // Each hellos with a placeholder view and then asks for its own: the placeholder's full image
    // comes only if the server rendered it before the view replaced it, so the full images may
    // differ by one; the updates of the cuts are the same.
    auto cutUpdates = [](const nlohmann::ordered_json& r) {
        return r.at("updates_applied").get<int>() - r.at("full_updates").get<int>();
    };
    EXPECT_EQ(cutUpdates(w), cutUpdates(h)) << "window " << w.dump() << "\nheadless " << h.dump();
    for (const nlohmann::ordered_json* r : {&w, &h}) {
        EXPECT_GE(r->at("full_updates").get<int>(), 1);
        EXPECT_LE(r->at("full_updates").get<int>(), 2);
    }
    EXPECT_EQ(w.at("update_bytes").at("count"), kCuts);
    EXPECT_EQ(h.at("update_bytes").at("count"), kCuts);
    EXPECT_EQ(w.at("update_latency_us").at("count"), h.at("update_latency_us").at("count"));
    // The same view (the window's home view is its preset): the same rectangles, byte for byte.
    if (window.report.camera == net::toCamera(headless.snap()->view)) {
        EXPECT_EQ(w.at("update_raw_bytes"), h.at("update_raw_bytes"));
        EXPECT_EQ(w.at("update_bytes").at("mean"), h.at("update_bytes").at("mean"));
    }
}

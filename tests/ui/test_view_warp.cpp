// The client's view warp (ui/view_warp.h) on Mesa llvmpipe against the CPU renderer's exact image
// of the new camera: exact for a camera that did not move, close for small orbits, the old picture
// scaled after a resize. Needs a display (xvfb-run).
#include "ui/compositor.h"
#include "ui/trainer_app.h"
#include "ui/window.h"

#include "gl_window_test.h"

#include "libsim/camera.h"
#include "libsim/hole.h"
#include "libsim/renderer.h"
#include "libsim/skull.h"
#include "net/session_server.h"

#include "loopback.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <future>
#include <memory>
#include <string>
#include <vector>

using namespace trephine;
using namespace trephine::ui;

namespace {

constexpr int kSize = 256;
constexpr float kDistanceMm = 170.0f;

bool isBackground(const uint8_t* c) {
    return c[0] == kBackgroundRgba[0] && c[1] == kBackgroundRgba[1] && c[2] == kBackgroundRgba[2];
}

// Pixels whose colour channels are all within `tolerance` levels of `exact`'s, as a share of all
// pixels, and of those that show bone in either image; `mask` (when given) keeps only some.
struct Match {
    double all = 0.0, bone = 0.0;
};
Match matchOf(const Dbi& shown, const Dbi& exact, int tolerance,
              const std::vector<bool>* mask = nullptr) {
    int64_t n = 0, close = 0, bone = 0, boneClose = 0;
    for (int y = 0; y < exact.height(); ++y)
        for (int x = 0; x < exact.width(); ++x) {
            if (mask && !(*mask)[exact.index(x, y)])
                continue;
            const uint8_t *a = shown.color(x, y), *b = exact.color(x, y);
            const bool ok = std::abs(a[0] - b[0]) <= tolerance &&
                            std::abs(a[1] - b[1]) <= tolerance &&
                            std::abs(a[2] - b[2]) <= tolerance;
            ++n;
            close += ok;
            if (!isBackground(a) || !isBackground(b)) {
                ++bone;
                boneClose += ok;
            }
        }
    return {n ? double(close) / double(n) : 0.0, bone ? double(boneClose) / double(bone) : 0.0};
}

class ViewWarpTest : public trephine::testing::GlWindowTest {
protected:
    void SetUp() override {
        GlWindowTest::SetUp();
        if (!window)
            return;
        comp = std::make_unique<Compositor>();
        skull = std::make_unique<Volume>(makeSkull(96));
        site = defaultBurrSite(*skull);
        // A burr hole at the site: its walls and floor are depth jumps the warp must break at.
        drillHoleAlong(*skull, site.position, -site.normal, 6.0f, 6.0f);
        renderer = std::make_unique<Renderer>(*skull);
        opened =
            cameraLookingAt(site.position, site.normal, kDistanceMm, 45.0f, {kSize, kSize}, *skull);
    }
    void TearDown() override {
        comp.reset();
        GlWindowTest::TearDown();
    }
    Camera orbited(float yawDeg, float pitchDeg, glm::ivec2 size = {kSize, kSize}) const {
        return orbitCamera(opened, yawDeg, pitchDeg, kDistanceMm, size, *skull);
    }
    // The DBI rendered for `from`, drawn by the warp for `to`.
    Dbi warped(const Camera& from, const Camera& to) {
        comp->uploadFull(renderer->render(from));
        comp->resizeView(to.width, to.height);
        comp->beginWarped(from, to);
        return comp->readBack();
    }

    std::unique_ptr<Compositor> comp;
    std::unique_ptr<Volume> skull;
    std::unique_ptr<Renderer> renderer;
    SurfaceSite site{};
    Camera opened;
};

} // namespace

TEST_F(ViewWarpTest, ACameraThatDidNotMoveIsTheDbiBitForBit) {
    const Camera cam = orbited(0.0f, 30.0f);
    const Dbi dbi = renderer->render(cam);
    for (int step : {1, WarpOptions{}.gridStep}) {
        WarpOptions wo;
        wo.gridStep = step;
        comp->warp().setOptions(wo);
        const Dbi out = warped(cam, cam);
        int64_t colourDiffer = 0;
        float depthError = 0.0f;
        for (int y = 0; y < kSize; ++y)
            for (int x = 0; x < kSize; ++x) {
                const uint8_t *a = out.color(x, y), *b = dbi.color(x, y);
                colourDiffer += a[0] != b[0] || a[1] != b[1] || a[2] != b[2];
                depthError = std::max(depthError, std::abs(out.depth(x, y) - dbi.depth(x, y)));
            }
        EXPECT_EQ(colourDiffer, 0)
            << "pixels whose colour the identity warp changed, step " << step;
        // The depth is the mesh's, rasterised from float matrices: one vertex a pixel meets the
        // bone within a hair of the exact picture; coarser cells are planes between their
        // corners (the window blits, never warps, a camera that did not move).
        if (step == 1) {
            EXPECT_LT(depthError, 1e-5f);
        }
    }
}

TEST_F(ViewWarpTest, AFiveDegreeOrbitMatchesTheExactImage) {
    const Camera from = orbited(0.0f, 30.0f);
    for (const Camera& to : {orbited(5.0f, 30.0f), orbited(0.0f, 35.0f)}) {
        const Dbi exact = renderer->render(to);
        const Match warp = matchOf(warped(from, to), exact, 8);
        const Match stale = matchOf(renderer->render(from), exact, 8);
        std::printf("5-degree orbit: %.1f %% of pixels within 8/255 (bone %.1f %%); the old "
                    "picture unwarped %.1f %% (bone %.1f %%)\n",
                    100.0 * warp.all, 100.0 * warp.bone, 100.0 * stale.all, 100.0 * stale.bone);
        EXPECT_GE(warp.all, 0.90); // issue 32's target for the warp's first frame
        EXPECT_GE(warp.bone, 0.85);
        EXPECT_GT(warp.bone, stale.bone + 0.1) << "the warp moved the picture with the camera";
    }
}

// A resize (or H's full-window view) changes the aspect and size: the old picture is drawn scaled
// into the new view, where the old view saw; what it never saw is background.
TEST_F(ViewWarpTest, AResizeShowsTheOldPictureScaled) {
    const Camera from = orbited(0.0f, 30.0f);
    const Camera to = orbited(0.0f, 30.0f, {360, 200});
    const Dbi out = warped(from, to);
    ASSERT_EQ(out.width(), 360);
    ASSERT_EQ(out.height(), 200);
    const Dbi exact = renderer->render(to);
    // The new pixels whose ray the old view saw (its frustum): there the picture must match.
    std::vector<bool> seen(size_t(to.width) * size_t(to.height));
    const glm::dmat4 back = viewProjection(from) * glm::inverse(viewProjection(to));
    int64_t seenCount = 0, boneShown = 0;
    for (int y = 0; y < to.height; ++y)
        for (int x = 0; x < to.width; ++x) {
            const glm::dvec4 ndc(2.0 * (x + 0.5) / to.width - 1.0,
                                 2.0 * (y + 0.5) / to.height - 1.0, 0.0, 1.0);
            const glm::dvec4 o = back * ndc;
            const bool in = std::abs(o.x / o.w) < 0.99 && std::abs(o.y / o.w) < 0.99;
            seen[exact.index(x, y)] = in;
            seenCount += in;
            boneShown += !isBackground(out.color(x, y));
        }
    EXPECT_GT(seenCount, 0);
    EXPECT_GT(boneShown, int64_t(to.width) * to.height / 4) << "never an empty view";
    const Match m = matchOf(out, exact, 8, &seen);
    std::printf("resize 256x256 -> 360x200: %.1f %% of the pixels the old view saw within 8/255 "
                "(bone %.1f %%)\n",
                100.0 * m.all, 100.0 * m.bone);
    EXPECT_GE(m.all, 0.90);
}

// The window: a right drag, then a resize, each while the server is not pumped (its answer held
// back). The frame of the change already shows the held picture warped to the new camera, and the
// server's exact picture, once it is let through, is within tolerance of that warped frame.
TEST(ViewWarpWindow, ACameraOrSizeChangeChangesTheNextFrameWhileTheServerIsHeldBack) {
    TREPHINE_NEED_DISPLAY("the trainee window");
    net::SessionServer server(makeSkull(64), trephine::testing::loopbackServerConfig("skull:64"));
    trephine::testing::Pumped pumped(server);
    struct Frame {
        Dbi view;
        Camera camera;
        size_t pictures; // full images taken in so far
    };
    std::vector<Frame> frames;    // one per composited frame (the window's thread)
    std::vector<Camera> pictures; // onPicture
    std::atomic<bool> hold{false}, quit{false};
    // Frames of each step (indices into `frames`): before and at the drag, before and at the
    // resize; the step and its start.
    size_t beforeDrag = 0, atDrag = 0, beforeResize = 0, atResize = 0;
    int step = 0, held = 0;
    constexpr int kWidth = 980, kHeight = 760; // --size 200's window
    TrainerOptions o;
    o.address = "127.0.0.1:" + std::to_string(server.port());
    o.size = 200;
    o.tiltDeg = 20.0f;
    o.timeoutS = 100.0;
    o.visible = false;
    o.quit = &quit;
    o.onPicture = [&](const Camera& c) { pictures.push_back(c); };
    o.onComposite = [&](const Dbi& d, const Camera& c) {
        frames.push_back({d, c, pictures.size()});
    };
    // One step a frame: hold the server, press, drag 17 pixels (5.1 degrees), keep still while
    // held for 5 frames, let the server go and wait for the exact picture; then the same for a
    // resize.
    o.input = [&](double t) {
        InjectedInput in;
        in.x = 100.0f, in.y = 100.0f;
        if (t < 0.3)
            return in;
        if (t > 30.0 || frames.size() > 3000) // a hung step: fail below, not run out of memory
            quit = true;
        const bool exact = !frames.empty() && frames.back().camera == pictures.back();
        switch (step) {
        case 0:
            hold = true, ++step;
            break;
        case 1:
            in.right = true, beforeDrag = frames.size() - 1, ++step;
            break;
        case 2:
            in.x += 17.0f, in.right = true, atDrag = frames.size(), ++step;
            break;
        case 3:
            in.x += 17.0f, hold = ++held < 5, step += !hold;
            break;
        case 4:
            in.x += 17.0f, hold = false, step += exact;
            break;
        case 5:
            hold = true, beforeResize = frames.size() - 1, ++step;
            break;
        case 6:
            in.windowWidth = kWidth + 120, in.windowHeight = kHeight + 60;
            if (frames.back().camera.width != frames[beforeResize].camera.width)
                atResize = frames.size() - 1, held = 0, ++step;
            break;
        case 7:
            in.windowWidth = kWidth + 120, in.windowHeight = kHeight + 60;
            hold = ++held < 5, quit = quit || (!hold && exact);
            break;
        }
        in.done = quit;
        return in;
    };
    std::future<int> window = std::async(std::launch::async, [&] { return runTrainerWindow(o); });
    while (window.wait_for(std::chrono::microseconds(500)) != std::future_status::ready)
        if (!hold)
            trephine::testing::Pumped::pumpAll();
    ASSERT_EQ(window.get(), 0);
    server.stop();
    ASSERT_EQ(step, 7) << "the step that did not end; frames " << frames.size();
    ASSERT_GT(atDrag, beforeDrag);
    ASSERT_GT(atResize, beforeResize);

    // The drag's frame: a new camera, no new picture from the server, a changed frame.
    const Frame &before = frames[beforeDrag], &at = frames[atDrag];
    EXPECT_NE(at.camera, before.camera) << "the frame of the drag draws the new camera";
    EXPECT_EQ(at.pictures, before.pictures) << "the server's answer was held back";
    EXPECT_LT(matchOf(at.view, before.view, 0).all, 0.8) << "the frame changed with the camera";
    // Against the server's exact picture of the same camera, once let through (tools and field
    // drawn over both).
    const auto exactOf = [&](const Camera& c, size_t from) {
        for (size_t i = from; i < frames.size(); ++i)
            if (frames[i].camera == c && frames[i].pictures > frames[from].pictures)
                return i;
        return frames.size();
    };
    const size_t dragExact = exactOf(at.camera, atDrag);
    ASSERT_LT(dragExact, frames.size()) << "the server's picture of the dragged view came";
    const Match drag = matchOf(at.view, frames[dragExact].view, 8);
    std::printf("window, 5.1-degree drag: the warped frame has %.1f %% of pixels within 8/255 of "
                "the server's (bone %.1f %%)\n",
                100.0 * drag.all, 100.0 * drag.bone);
    EXPECT_GE(drag.all, 0.90);

    // The resize: every frame composited, the first at the new size with the old picture scaled.
    const Frame& resized = frames[atResize];
    EXPECT_EQ(resized.pictures, frames[beforeResize].pictures) << "held back";
    EXPECT_NE(resized.camera.width, frames[beforeResize].camera.width);
    int64_t bone = 0;
    for (int y = 0; y < resized.view.height(); ++y)
        for (int x = 0; x < resized.view.width(); ++x)
            bone += !isBackground(resized.view.color(x, y));
    // The wider view sees past the old one's sides: those are background until the server's.
    EXPECT_GT(bone, int64_t(resized.view.width()) * resized.view.height() / 4)
        << "the old picture, never an empty view";
    const size_t resizeExact = exactOf(resized.camera, atResize);
    ASSERT_LT(resizeExact, frames.size());
    const Match scaled = matchOf(resized.view, frames[resizeExact].view, 8);
    std::printf("window, resize: the scaled frame has %.1f %% of pixels within 8/255 of the "
                "server's (bone %.1f %%)\n",
                100.0 * scaled.all, 100.0 * scaled.bone);
}

namespace {

// A hidden window of --size 200 (980 x 760) on `server`, run while the test pumps it.
int runPumpedWindow(const net::SessionServer& server, TrainerOptions& o, std::atomic<bool>& quit,
                    const std::string& sync) {
    o.address = "127.0.0.1:" + std::to_string(server.port());
    o.size = 200;
    o.timeoutS = 100.0;
    o.visible = false;
    o.quit = &quit;
    o.sync = sync;
    std::future<int> window = std::async(std::launch::async, [&] { return runTrainerWindow(o); });
    while (window.wait_for(std::chrono::microseconds(500)) != std::future_status::ready)
        trephine::testing::Pumped::pumpAll();
    return window.get();
}

// One peer's view requests in the server's report.
int viewRequests(const net::SessionServer& server) {
    const nlohmann::json report = nlohmann::json::parse(server.reportJson());
    return report.at("peers").size() == 1 ? report["peers"][0]["view_requests"].get<int>() : -1;
}

constexpr int kDragWidth = 980, kDragHeight = 760, kDragSteps = 40;

} // namespace

// A window's edge dragged through 40 sizes, a frame each: the first size is asked for at once, the
// frames after it draw the held picture scaled, and the size it stops at is asked for once it has
// held kResizeSettleS (0.1 s), not the 38 between. A frame slower than that (a loaded machine)
// lets one more through.
TEST(ViewWarpWindow, ADraggedWindowEdgeAsksForItsFirstAndLastSizesOnly) {
    TREPHINE_NEED_DISPLAY("the trainee window");
    net::SessionServer server(makeSkull(64), trephine::testing::loopbackServerConfig("skull:64"));
    trephine::testing::Pumped pumped(server);
    constexpr double kSettleS = 0.1;
    std::vector<Camera> composited, pictures;
    std::vector<double> dragAt; // the input's time at each step of the drag
    double exactAfterS = 0.0;   // the last step to the exact picture of its size
    std::atomic<bool> quit{false};
    int step = 0;
    TrainerOptions o;
    o.onPicture = [&](const Camera& c) { pictures.push_back(c); };
    o.onComposite = [&](const Dbi&, const Camera& c) { composited.push_back(c); };
    o.input = [&](double t) {
        InjectedInput in;
        if (t < 0.3)
            return in;
        if (t > 30.0) // a hung step: fail below
            quit = true;
        const bool exact = !composited.empty() && composited.back() == pictures.back();
        if (step == 0) {
            step += exact; // the first view's picture is in
        } else if (step <= kDragSteps) {
            dragAt.push_back(t);
            in.windowWidth = kDragWidth + 8 * step, in.windowHeight = kDragHeight + 4 * step;
            ++step;
        } else {
            in.windowWidth = kDragWidth + 8 * kDragSteps;
            in.windowHeight = kDragHeight + 4 * kDragSteps;
            if (exact && composited.back().height != composited.front().height &&
                t - dragAt.back() > kSettleS && !quit) {
                exactAfterS = t - dragAt.back();
                quit = true;
            }
        }
        in.done = quit;
        return in;
    };
    ASSERT_EQ(runPumpedWindow(server, o, quit, "dbi"), 0);
    const int requests = viewRequests(server);
    server.stop();
    ASSERT_EQ(step, kDragSteps + 1);
    int slowGaps = 0;
    for (size_t i = 1; i < dragAt.size(); ++i)
        slowGaps += dragAt[i] - dragAt[i - 1] >= kSettleS;
    std::printf("a drag through %d sizes: %d view requests (frames slower than %.2f s: %d); the "
                "exact picture %.3f s after its last step\n",
                kDragSteps, requests, kSettleS, slowGaps, exactAfterS);
    // The scene's preset view, the drag's first size, the size it stopped at.
    EXPECT_LE(requests, 3 + slowGaps);
    EXPECT_GE(requests, 3);
    // The last picture is the server's of the size the drag stopped at.
    EXPECT_EQ(pictures.back(), composited.back());
    EXPECT_GT(composited.back().height, composited.front().height);
}

// In the volume design the window draws its own picture, and the server renders nothing for its
// views: each size of a drag is asked for at once, so the local picture follows it.
TEST(ViewWarpWindow, TheVolumeDesignsDraggedEdgeAsksForEverySizeAtOnce) {
    TREPHINE_NEED_DISPLAY("the trainee window");
    net::SessionServer server(makeSkull(64), trephine::testing::loopbackServerConfig("skull:64"));
    trephine::testing::Pumped pumped(server);
    std::atomic<bool> quit{false};
    int step = 0;
    TrainerOptions o;
    o.input = [&](double t) {
        InjectedInput in;
        if (t < 0.3)
            return in;
        quit = quit || t > 30.0 || step > kDragSteps + 10;
        const int at = std::min(step++, kDragSteps);
        in.windowWidth = kDragWidth + 8 * at, in.windowHeight = kDragHeight + 4 * at;
        in.done = quit;
        return in;
    };
    ASSERT_EQ(runPumpedWindow(server, o, quit, "volume"), 0);
    const int requests = viewRequests(server);
    server.stop();
    ASSERT_GT(step, kDragSteps);
    std::printf("the volume design's drag through %d sizes: %d view requests\n", kDragSteps,
                requests);
    EXPECT_GE(requests, kDragSteps);
}

// `trephine instructor` windowed against an in-process server: a headless trainee SessionClient
// holds its tool in view, and the instructor's screenshot shows that tool in the trainee's colour
// where the server's camera projects it. Needs a display (xvfb-run).
#include "gl_window_test.h"
#include "ui/panels.h"
#include "ui/trainer_app.h"
#include "ui/window.h"

#include "libsim/camera.h"
#include "libsim/skull.h"
#include "libsim/tool.h"
#include "net/session_client.h"
#include "net/session_server.h"

#include "loopback.h"
#include "screenshot.h"
#include "test_support.h"
#include <OpenImageIO/imageio.h>
#include <glm/geometric.hpp>
#include <glm/gtx/quaternion.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <thread>
#include <vector>

using namespace trephine;

namespace {

using trephine::testing::Image;
using trephine::testing::Pumped;
using trephine::testing::readPng;
using trephine::testing::shellQuote;
using trephine::testing::waitFor;
using trephine::testing::whilePumping;

// A lit pixel of `colour`'s hue: the compositor scales the base colour by its headlight term.
bool hasHue(const uint8_t* p, glm::vec4 colour) {
    glm::vec3 px(p[0], p[1], p[2]);
    float len = glm::length(px);
    if (len < 40.0f)
        return false;
    return glm::dot(px / len, glm::normalize(glm::vec3(colour))) > 0.985f;
}

// Pixels of `colour`'s hue within `radius` of (x, y) (image rows from the top).
int countHue(const Image& img, int x, int y, int radius, glm::vec4 colour) {
    int n = 0;
    for (int dy = -radius; dy <= radius; ++dy)
        for (int dx = -radius; dx <= radius; ++dx) {
            int px = x + dx, py = y + dy;
            if (px >= 0 && py >= 0 && px < img.w && py < img.h)
                n += hasHue(img.at(px, py), colour);
        }
    return n;
}

glm::vec3 anyPerpendicular(glm::vec3 n) {
    return glm::normalize(
        glm::cross(n, std::abs(n.z) < 0.9f ? glm::vec3(0, 0, 1) : glm::vec3(1, 0, 0)));
}

} // namespace

TEST(InstructorWindow, ShowsTheTraineesToolInItsColourWhereItIs) {
    TREPHINE_NEED_DISPLAY("the instructor window");
    Volume skull = makeSkull(128);
    const SurfaceSite site = defaultBurrSite(skull);
    net::ServerConfig sc;
    sc.port = 0;
    sc.volumeName = "skull:128";
    sc.renderThreads = 1;
    net::SessionServer server(skull, sc);
    Pumped pumped(server);
    const std::string address = "127.0.0.1:" + std::to_string(server.port());

    // The trainee's burr rests 10 mm to one side of the site, its handpiece leaning outwards.
    const glm::vec3 n = site.normal, e1 = anyPerpendicular(n);
    const glm::vec3 axis = glm::normalize(n - e1 * 0.5f);
    net::ToolState tool;
    tool.toolKind = uint8_t(ToolKind::Burr);
    tool.diameterMm = 5.0f;
    tool.position = site.position - e1 * 10.0f + n * 3.0f;
    tool.orientation = glm::rotation(glm::vec3(0, 0, 1), axis);

    net::ClientConfig tc;
    tc.name = "trainee";
    tc.view = net::ViewSpec{};
    tc.view.width = tc.view.height = 32;
    net::SessionClient trainee(tc);
    trainee.connect(net::parseAddress(address));
    std::atomic<bool> stop{false};
    std::atomic<uint16_t> traineeId{0};
    std::atomic<size_t> traineeMarks{0}; // marks the trainee holds (the instructor places one)
    // The colours the trainee's roster gives it and the instructor (0xRRGGBB + 1; 0: not listed):
    // what the trainee's own window draws them in.
    std::atomic<uint32_t> traineeOwnColour{0}, instructorColour{0};
    std::thread traineeThread([&] {
        auto next = std::chrono::steady_clock::now();
        while (!stop) {
            trainee.poll(1);
            if (trainee.welcomed()) {
                traineeId = trainee.welcome().clientId;
                traineeMarks = trainee.annotations().size();
                for (const auto& [id, p] : trainee.participants()) {
                    const uint32_t rgb =
                        (uint32_t(p.colour.r) << 16 | p.colour.g << 8 | p.colour.b) + 1;
                    (id == traineeId ? traineeOwnColour : instructorColour) = rgb;
                }
                if (std::chrono::steady_clock::now() >= next) {
                    net::ToolState t = tool;
                    trainee.sendToolState(t);
                    next += std::chrono::milliseconds(20);
                }
            }
        }
        trainee.disconnect();
    });
    waitFor([&] { return traineeId != 0; }, 20.0);

    const std::string out =
        (std::filesystem::temp_directory_path() / "trephine_instructor.png").string();
    std::filesystem::remove(out);
    // A mark across the site from the tool, placed by the instructor for everyone.
    const glm::vec3 e2 = glm::normalize(glm::cross(n, e1));
    const glm::vec3 markAt = site.position + e2 * 25.0f;
    // And one 40 mm inside the skull on the other side: bone hides it from this view.
    const glm::vec3 hiddenAt = site.position - n * 40.0f - e2 * 25.0f;
    char mark[320];
    std::snprintf(mark, sizeof mark, " --mark '%.3f,%.3f,%.3f:entry point' --mark '%.3f,%.3f,%.3f'",
                  double(markAt.x), double(markAt.y), double(markAt.z), double(hiddenAt.x),
                  double(hiddenAt.y), double(hiddenAt.z));
    const std::string cmd = shellQuote(TREPHINE_BIN) + " instructor --connect " + address + mark +
                            " --window-size 500 --tilt 0 --screenshot " + shellQuote(out) +
                            " --frames 3 --timeout 80 > " + shellQuote(out + ".log") + " 2>&1";
    const int rc = whilePumping([&] { return std::system(cmd.c_str()); });
    const uint64_t relays = server.hapticRelaysSent();
    waitFor([&] { return traineeMarks >= 2; }, 10.0); // the list reaches the trainee too
    stop = true;
    traineeThread.join();
    server.stop();
    ASSERT_NE(traineeId.load(), 0) << "the trainee joined";
    ASSERT_EQ(rc, 0) << cmd;
    EXPECT_GT(relays, 0u) << "the trainee's force models were relayed to the instructor";

    Image img = readPng(out);
    ASSERT_EQ(img.w, 1280);
    // The instructor's camera: its close view of the burr site, straight down the normal
    // (--tilt 0), 500 x 500 at the top left.
    const Camera cam =
        cameraLookingAt(site.position, site.normal, 170.0f, 45.0f, {500, 500}, skull);
    const glm::dmat4 vp = viewProjection(cam);
    auto pixelOf = [&](glm::vec3 p) {
        WindowPoint w = projectToWindow(vp, cam, glm::dvec3(p));
        return glm::ivec2(int(w.window.x), 500 - 1 - int(w.window.y));
    };
    // Two windows, one colour: the instructor's screenshot shows the trainee in the colour the
    // trainee's own roster gives it (the server's), distinct from the instructor's.
    auto rgbOf = [](uint32_t packed) {
        const uint32_t v = packed - 1;
        return ui::toColour({uint8_t(v >> 16), uint8_t(v >> 8), uint8_t(v)});
    };
    ASSERT_NE(traineeOwnColour.load(), 0u) << "the trainee was listed to itself";
    ASSERT_NE(instructorColour.load(), 0u) << "the instructor was listed to the trainee";
    const glm::vec4 colour = rgbOf(traineeOwnColour);
    ASSERT_NE(colour, rgbOf(instructorColour)) << "a colour distinct from the instructor's own";
    // The owner-coloured handpiece body lies 38..76 mm up the axis from the burr's centre.
    int onTool = 0, besideTool = 0;
    for (float d : {45.0f, 55.0f, 65.0f}) {
        glm::ivec2 at = pixelOf(tool.position + axis * d);
        ASSERT_TRUE(at.x >= 0 && at.x < 500 && at.y >= 0 && at.y < 500) << at.x << "," << at.y;
        onTool += countHue(img, at.x, at.y, 2, colour);
    }
    // Across the site from the tool (the handpiece leans away from there): bone, none of the
    // trainee's colour.
    for (float d : {20.0f, 25.0f}) {
        glm::ivec2 m = pixelOf(site.position + e1 * d);
        besideTool += countHue(img, m.x, m.y, 2, colour);
    }
    EXPECT_GE(onTool, 3 * 25 * 6 / 10) << "the trainee's colour at its projected handpiece";
    EXPECT_EQ(besideTool, 0) << "no trainee colour on the bone across the site";
    // The Forces panel (under the view, left half) plots the trainee's relayed force in its colour.
    int inForces = 0;
    for (int y = 500; y < img.h; ++y)
        for (int x = 0; x < 250; ++x)
            inForces += hasHue(img.at(x, y), colour);
    EXPECT_GT(inForces, 50) << "the trainee's force plot in the instructor's Forces panel";
    // The mark: a ring in the mark colour where the instructor's camera projects it, and the
    // trainee got it too.
    EXPECT_EQ(traineeMarks.load(), 2u) << "the marks reached the trainee";
    const glm::ivec2 m = pixelOf(markAt);
    ASSERT_TRUE(m.x >= 10 && m.x < 490 && m.y >= 10 && m.y < 490) << m.x << "," << m.y;
    EXPECT_GE(countHue(img, m.x, m.y, 10, ui::markColor()), 40) << "the mark's ring";
    const glm::ivec2 h = pixelOf(hiddenAt);
    ASSERT_TRUE(h.x >= 10 && h.x < 490 && h.y >= 10 && h.y < 490) << h.x << "," << h.y;
    EXPECT_LT(countHue(img, h.x, h.y, 10, ui::markColor()), 5)
        << "a mark behind the bone is drawn faint, not in full colour";
    EXPECT_EQ(countHue(img, pixelOf(tool.position + axis * 55.0f).x,
                       pixelOf(tool.position + axis * 55.0f).y, 2, ui::markColor()),
              0)
        << "no mark colour on the tool";
}

// A malformed --mark is one line naming it and a non-zero exit, before any window opens.
TEST(InstructorWindow, MalformedMarkIsOneLineNamingIt) {
    TREPHINE_NEED_DISPLAY("the instructor window");
    trephine::testing::TempDir dir;
    for (const char* bad : {"1,2", "1,2,x", "1,2,3,4", "nan,0,0:label"}) {
        SCOPED_TRACE(bad);
        trephine::testing::CommandResult r = trephine::testing::runTrephine(
            dir, std::string("instructor --connect 127.0.0.1:9 --mark '") + bad + "'");
        EXPECT_NE(r.exitCode, 0);
        EXPECT_NE(r.err.find(std::string("--mark '") + bad + "'"), std::string::npos) << r.err;
        EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
    }
}

// A mark that projects outside the view (here 100 mm below the site, under the view's lower edge)
// is not drawn over the panels: its ring was drawn in the Forces panel under the view.
TEST(InstructorWindow, AMarkOutsideTheViewIsNotDrawnOverThePanels) {
    TREPHINE_NEED_DISPLAY("the instructor window");
    const Volume skull = makeSkull(64);
    const SurfaceSite site = defaultBurrSite(skull);
    net::SessionServer server(skull, trephine::testing::loopbackServerConfig("skull:64"));
    Pumped pumped(server);
    constexpr int kView = 256;
    const Camera cam =
        cameraLookingAt(site.position, site.normal, 170.0f, 45.0f, {kView, kView}, skull);
    const glm::vec3 look = glm::normalize(cam.target - cam.eye);
    const glm::vec3 up = glm::normalize(cam.up - look * glm::dot(cam.up, look));
    const glm::vec3 inView = cam.target + up * 20.0f, below = cam.target - up * 100.0f;
    const glm::dmat4 vp = viewProjection(cam);
    auto pixelOf = [&](glm::vec3 p) { // image rows from the top
        WindowPoint w = projectToWindow(vp, cam, glm::dvec3(p));
        return glm::ivec2(int(w.window.x), kView - 1 - int(w.window.y));
    };
    const glm::ivec2 in = pixelOf(inView), out = pixelOf(below);
    ASSERT_TRUE(in.x > 10 && in.x < kView - 10 && in.y > 10 && in.y < kView - 10);
    ASSERT_TRUE(out.x > 10 && out.x < kView - 10 && out.y > kView + 20) << out.x << "," << out.y;
    auto mark = [](glm::vec3 p) {
        char text[96];
        std::snprintf(text, sizeof text, "%.3f,%.3f,%.3f", double(p.x), double(p.y), double(p.z));
        return std::string(text);
    };

    trephine::testing::TempDir dir;
    ui::TrainerOptions o;
    o.address = "127.0.0.1:" + std::to_string(server.port());
    o.name = "Dr Cho";
    o.instructor = true;
    o.size = kView;
    o.marks = {mark(inView), mark(below)};
    o.screenshot = dir / "marks.png";
    o.frames = 2;
    o.timeoutS = 60.0;
    o.visible = false;
    ASSERT_EQ(whilePumping([&] { return ui::runTrainerWindow(o); }), 0);
    server.stop();

    const Image img = readPng(o.screenshot);
    ASSERT_GT(img.h, kView + 40);
    EXPECT_GE(countHue(img, in.x, in.y, 10, ui::markColor()), 40) << "the mark in the view";
    EXPECT_LT(countHue(img, out.x, out.y, 10, ui::markColor()), 5)
        << "no mark ring in the panel under the view";
}

// An instructor whose view is larger than the server serves is told the option it has: the
// message said "--size", the trainee's; the instructor's (and the demo's) is --window-size.
TEST(InstructorWindow, AViewTooLargeNamesTheInstructorsOwnOption) {
    TREPHINE_NEED_DISPLAY("the instructor window");
    const Volume sphere = makeSphere(32);
    net::ServerConfig sc = trephine::testing::loopbackServerConfig("sphere:32");
    sc.maxViewPixels = 100 * 100;
    net::SessionServer server(sphere, sc);
    Pumped pumped(server);
    trephine::testing::TempDir dir;
    const std::string args = "instructor --connect 127.0.0.1:" + std::to_string(server.port()) +
                             " --window-size 128 --frames 5 --timeout 60";
    const trephine::testing::CommandResult r =
        whilePumping([&] { return trephine::testing::runTrephine(dir, args); });
    server.stop();
    EXPECT_EQ(r.exitCode, 1);
    EXPECT_NE(r.err.find("this view is 128 x 128: restart with --window-size 100 or less"),
              std::string::npos)
        << r.err;
}

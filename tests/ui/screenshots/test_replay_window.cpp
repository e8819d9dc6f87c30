// An instructor window watching a recorded session served as a replay (SessionServer::serveLog,
// as `trephine replay --serve` serves it): its screenshot at the end shows the view the same, pixel
// for pixel, as a window on the original session after its trainee had drilled and left, with the
// replay's timeline over the view's bottom, at its end. Needs a display (xvfb-run).
#include "gl_window_test.h"

#include "libsim/skull.h"
#include "net/replay_feed.h"
#include "net/scene.h"
#include "net/session_client.h"
#include "net/session_log.h"
#include "net/session_server.h"

#include "loopback.h"
#include "screenshot.h"
#include "test_support.h"

#include <gtest/gtest.h>

#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

using namespace trephine;

namespace {

using trephine::testing::Image;
using trephine::testing::Pumped;
using trephine::testing::readPng;
using trephine::testing::shellQuote;
using trephine::testing::whilePumping;

// `trephine instructor` on `address`, its settled view saved to `png`; the exit status.
int screenshot(const std::string& address, const std::string& png) {
    std::filesystem::remove(png);
    const std::string cmd = shellQuote(TREPHINE_BIN) + " instructor --connect " + address +
                            " --window-size 400 --screenshot " + shellQuote(png) +
                            " --frames 3 --timeout 80 > " + shellQuote(png + ".log") + " 2>&1";
    return std::system(cmd.c_str());
}

} // namespace

TEST(ReplayWindow, AWindowWatchingAReplayEndsOnTheOriginalSessionsPicture) {
    TREPHINE_NEED_DISPLAY("the instructor window");
    const trephine::testing::TempDir dir;
    const std::string log = dir / "s.log", original = dir / "original.png",
                      replayed = dir / "replayed.png";
    const Volume skull = makeSkull(96);
    const SurfaceSite site = defaultBurrSite(skull);
    {
        net::ServerConfig sc;
        sc.port = 0;
        sc.volumeName = "skull:96";
        sc.renderThreads = 1;
        sc.scene = std::make_shared<const net::Scene>(net::buildScene(skull));
        sc.recorder =
            net::SessionRecorder::create(log, net::makeLogHeader(skull, sc, "skull:96", false, 0));
        net::SessionServer server(skull, sc);
        Pumped pumped(server);
        // A trainee drills a hole at the site the instructor's view centres on, then leaves.
        net::ClientConfig tc =
            trephine::testing::namedClientConfig(skull, "Ada", net::Role::Trainee, 32);
        net::SessionClient ada(tc);
        ada.connect(trephine::testing::loopback(server.port()));
        ASSERT_TRUE(trephine::testing::pumpUntil({&ada}, [&] { return ada.hasFullImage(); }));
        for (int i = 0; i < 60; ++i) {
            ada.sendToolState(trephine::testing::burrState(site, i, 60, 1000000));
            Pumped::pumpAll();
            ada.poll(2);
        }
        ASSERT_TRUE(trephine::testing::pumpUntil({&ada}, [&] { return server.idle(); }));
        ada.disconnect();
        ASSERT_TRUE(trephine::testing::pumpUntil({}, [&] { return server.clientCount() == 0; }));
        const std::string address = "127.0.0.1:" + std::to_string(server.port());
        ASSERT_EQ(whilePumping([&] { return screenshot(address, original); }), 0)
            << "the window on the original session";
        server.stop();
    }
    // The same window on the undrilled skull: the hole must show in the view for the comparison
    // to mean anything.
    const std::string untouched = dir / "untouched.png";
    {
        net::ServerConfig sc;
        sc.port = 0;
        sc.volumeName = "skull:96";
        sc.renderThreads = 1;
        net::SessionServer server(skull, sc);
        Pumped pumped(server);
        const std::string address = "127.0.0.1:" + std::to_string(server.port());
        ASSERT_EQ(whilePumping([&] { return screenshot(address, untouched); }), 0);
    }
    // The log served as `trephine replay LOG --serve --speed 1000` serves it.
    const net::LogContents contents = net::readSessionLog(log);
    ASSERT_TRUE(contents.stopped.empty()) << contents.stopped;
    const Volume start =
        net::logStartVolume(contents.header, [&](const std::string&) { return skull; });
    net::SessionServer served(
        start, net::replayServerConfig(contents.header,
                                       trephine::testing::loopbackServerConfig("skull:96")));
    served.serveLog(contents.records, 1000.0, true);
    Pumped pumpedReplay(served);
    // The window joins once the replay is over, as a late watcher: a window watching the drilling
    // would show the fading BB_screen rectangles of its updates over the view.
    ASSERT_TRUE(trephine::testing::waitFor(
        [&] {
            const std::optional<net::ReplayState> s = served.replayState();
            return s && !s->playing && s->positionUs == s->durationUs && served.idle();
        },
        60.0))
        << "the replay reached its end";
    const std::string address = "127.0.0.1:" + std::to_string(served.port());
    ASSERT_EQ(whilePumping([&] { return screenshot(address, replayed); }), 0)
        << "the window on the replay";
    served.stop();

    const Image a = readPng(original), b = readPng(replayed);
    ASSERT_GT(a.w, 400);
    ASSERT_EQ(a.w, b.w);
    ASSERT_EQ(a.h, b.h);
    const Image u = readPng(untouched);
    ASSERT_EQ(u.w, a.w);
    // The view: the window's top-left 400 x 400 (the panels beside it list other people), above
    // the replay's timeline, which lies over the view's bottom 44 rows, and without the frame
    // rate in its top-right corner (a window that took over a second under load shows a figure).
    constexpr int kView = 400, kBar = 44, kRateW = 100, kRateH = 26;
    auto differing = [&](const Image& x, const Image& y) {
        int n = 0;
        for (int row = 0; row < kView - kBar; ++row)
            for (int col = 0; col < kView; ++col)
                if (row >= kRateH || col < kView - kRateW)
                    n += std::memcmp(x.at(col, row), y.at(col, row), 3) != 0;
        return n;
    };
    EXPECT_GT(differing(a, u), 200) << "the drilled hole shows in the original session's view";
    EXPECT_EQ(differing(a, b), 0) << "pixels of the view that differ between " << original
                                  << " and " << replayed;
    // The timeline: ImGui's blue (the Play button, the slider's grab) in the bar, which a
    // window on a live session does not draw; the grab at the slider's right end (the replay is
    // over), the button at the bar's left.
    auto blue = [&](const Image& x, int fromCol, int toCol) {
        int n = 0;
        for (int row = kView - kBar; row < kView; ++row)
            for (int col = fromCol; col < toCol; ++col) {
                const uint8_t* p = x.at(col, row);
                n += p[2] > p[0] + 60 && p[2] > p[1] + 30;
            }
        return n;
    };
    EXPECT_LT(blue(a, 0, kView), 5) << "no timeline on a live session";
    EXPECT_GT(blue(b, 0, 70), 50) << "the Play button at the bar's left in " << replayed;
    EXPECT_GT(blue(b, 250, kView - 80), 20) << "the slider's grab at its end in " << replayed;
    EXPECT_LT(blue(b, 80, 200), 5) << "no grab in the slider's first part in " << replayed;
}

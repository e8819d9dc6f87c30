// The trainee window drilled with a SpaceMouse, end to end: an in-process server on skull:128 and
// the window started with a SpaceMouseDevice (TrainerOptions::device) whose reports, built to the
// 3Dconnexion HID format, come from a test source timed by the window's own clock. The tool
// starts over the burr site; the drill button starts the drill, a push away (into the view)
// feeds it into the bone, and bone goes. Needs a display (xvfb-run).
#include "gl_window_test.h"
#include "ui/trainer_app.h"

#include "libsim/skull.h"
#include "libsim_devices/spacemouse.h"
#include "net/session_server.h"

#include "loopback.h"
#include "test_support.h"

#include <gtest/gtest.h>

#include <atomic>
#include <cstdio>

using namespace trephine;
using namespace trephine::ui;
using trephine::testing::boneVoxels;

namespace {

// The seconds since the window's first picture (negative before), as the window's input
// callback last saw them; the source's script runs on it.
std::atomic<double> g_windowT{-1.0};

// At 0.5 s the drill button goes down and up; from 1 s to 3.5 s the cap is pushed away at 3/7 of
// full scale past the dead zone's edge; then released.
class TimedSource : public SpaceMouseSource {
public:
    std::string name() const override { return "timed test SpaceMouse"; }
    bool poll(SpaceMouseParser& parser) override {
        const double t = g_windowT.load();
        const uint8_t buttons = t > 0.5 && t < 0.6 ? 1 : 0;
        if (buttons != m_buttons) {
            const uint8_t r[] = {3, buttons};
            parser.feed(r);
            m_buttons = buttons;
        }
        const bool push = t > 1.0 && t < 3.5;
        if (push != m_push) {
            const int16_t y = push ? int16_t(-150) : int16_t(0); // negative y: away from the user
            const uint8_t r[] = {1, 0, 0, uint8_t(uint16_t(y) & 0xff), uint8_t(uint16_t(y) >> 8),
                                 0, 0};
            parser.feed(r);
            m_push = push;
        }
        return true;
    }

private:
    uint8_t m_buttons = 0;
    bool m_push = false;
};

} // namespace

TEST(SpaceMouseWindow, TheDrillButtonAndAPushIntoTheViewDrillTheBone) {
    TREPHINE_NEED_DISPLAY("the trainee window");
    const Volume skull = makeSkull(128);
    const int64_t before = boneVoxels(skull);
    net::SessionServer server(skull, trephine::testing::loopbackServerConfig("skull:128", 2));
    trephine::testing::Pumped pumped(server);
    SpaceMouseConfig c;
    c.translationGainMmPerS = 20.0; // (150 - 12) / (350 - 12) of it: 8.2 mm/s for 2.5 s
    TrainerReport report;
    TrainerOptions o;
    o.address = "127.0.0.1:" + std::to_string(server.port());
    o.size = 256;
    o.tiltDeg = 30.0f;
    std::atomic<bool> quit{false};
    o.quit = &quit;
    o.timeoutS = 100.0;
    o.visible = false;
    o.report = &report;
    o.device = std::make_shared<SpaceMouseDevice>(std::make_unique<TimedSource>(), c);
    g_windowT = -1.0;
    o.input = [&quit](double t) {
        g_windowT = t;
        if (t > 4.5)
            quit = true;        // the push is over and its last tool states have been answered
        return InjectedInput{}; // no pointer over the view: the SpaceMouse has the tool
    };
    ASSERT_EQ(trephine::testing::whilePumping([&] { return runTrainerWindow(o); }), 0);
    const int64_t removed = before - boneVoxels(server.volumeSnapshot());
    server.stop();
    std::printf("spacemouse window: pushed 20 mm into the view from 10.5 mm over the site with "
                "the drill on, skull:128: %lld bone voxels removed\n",
                (long long)removed);
    EXPECT_GT(removed, 17) << "more than the burr's own sphere";
}

// The window's tool driven by a device and a pedal, without a window: a SpaceMouse fed reports
// built to its HID format (read by the haptic loop's side at 1 kHz) moves the tool from above the
// burr site into the view; its buttons start the drill, pick the next tool and recentre; a fake
// joystick (GLFW has none under Xvfb) sets the speed, drills, clutches and switches tools.
#include "ui/device_drive.h"

#include "libsim/tool_catalogue.h"
#include "libsim_devices/spacemouse.h"

#include <deque>
#include <glm/geometric.hpp>
#include <gtest/gtest.h>

using namespace trephine;
using namespace trephine::ui;

namespace {

struct QueueSource : SpaceMouseSource {
    std::deque<std::vector<uint8_t>>& queue;
    explicit QueueSource(std::deque<std::vector<uint8_t>>& q) : queue(q) {}
    std::string name() const override { return "test SpaceMouse"; }
    bool poll(SpaceMouseParser& parser) override {
        for (; !queue.empty(); queue.pop_front())
            parser.feed(queue.front());
        return true;
    }
};

std::vector<uint8_t> axes(uint8_t id, int16_t a, int16_t b, int16_t c) {
    auto lo = [](int16_t v) { return uint8_t(uint16_t(v) & 0xff); };
    auto hi = [](int16_t v) { return uint8_t(uint16_t(v) >> 8); };
    return {id, lo(a), hi(a), lo(b), hi(b), lo(c), hi(c)};
}

// The haptic loop's side: reads at 1 kHz from t0 for `seconds`.
void loop(net::ToolSource& tools, double t0, double seconds) {
    for (int i = 0; i <= int(seconds * 1000.0 + 0.5); ++i)
        tools.device().read(t0 + i * 0.001);
}

struct Rig {
    std::deque<std::vector<uint8_t>> queue;
    WindowDevice window;
    std::vector<JoystickInput> joysticks;
    SpaceMouseConfig config;
    Camera camera; // eye on +z looking at the origin: into the view is -z, up the screen +y
    ToolControls controls;
    std::unique_ptr<DeviceDrive> drive;
    Rig(std::optional<PedalMap> pedal = std::nullopt, bool withDevice = true) {
        config.translationGainMmPerS = 30.0;
        std::shared_ptr<Device> d;
        if (withDevice)
            d = std::make_shared<SpaceMouseDevice>(std::make_unique<QueueSource>(queue), config);
        drive = std::make_unique<DeviceDrive>(d, std::move(pedal), window,
                                              [this] { return joysticks; });
    }
};

ToolPose home() {
    ToolPose h;
    h.position = {10, 20, 30};
    return h;
}

} // namespace

TEST(DeviceDrive, ASpaceMousePushedAwayMovesTheToolFromTheSiteIntoTheView) {
    Rig rig;
    ASSERT_TRUE(rig.drive->drivesTool());
    EXPECT_FALSE(rig.drive->frame(home(), rig.camera, rig.controls)) << "nothing read yet";
    loop(*rig.drive->tools(), 0.0, 0.01);
    auto pose = rig.drive->frame(home(), rig.camera, rig.controls);
    ASSERT_TRUE(pose);
    EXPECT_NEAR(glm::length(pose->position - home().position), 0.0f, 1e-4f);
    rig.queue.push_back(axes(1, 0, -kSpaceMouseFullScale, 0)); // pushed away, full scale
    loop(*rig.drive->tools(), 0.011, 2.0);
    pose = rig.drive->frame(home(), rig.camera, rig.controls);
    ASSERT_TRUE(pose);
    EXPECT_NEAR(pose->position.z, 30.0f - 60.0f, 0.1f); // 30 mm/s for 2 s, into the view
    EXPECT_NEAR(pose->position.x, 10.0f, 1e-3f);
    EXPECT_NEAR(pose->position.y, 20.0f, 1e-3f);
    EXPECT_FALSE(rig.controls.drilling);
}

TEST(DeviceDrive, ButtonsStartTheDrillPickTheNextToolAndRecentre) {
    Rig rig;
    loop(*rig.drive->tools(), 0.0, 0.01);
    rig.drive->frame(home(), rig.camera, rig.controls);
    rig.queue.push_back({3, 0x01}); // drill button: press and release within one frame
    loop(*rig.drive->tools(), 0.011, 0.005);
    rig.queue.push_back({3, 0x00});
    loop(*rig.drive->tools(), 0.017, 0.005);
    rig.drive->frame(home(), rig.camera, rig.controls);
    EXPECT_TRUE(rig.controls.drilling);
    // The loop's tool state carries what the frame set on the window's device.
    rig.window.set(DeviceState{}, {ToolKind::Burr, 5.0f, 0.7f, rig.controls.drilling}, 0.0);
    const net::ToolState ts = rig.drive->tools()->toolAt(ToolPose{}, 0.03);
    EXPECT_TRUE(ts.drilling);
    EXPECT_FLOAT_EQ(ts.speed, 0.7f);

    const int kind = rig.controls.kind;
    rig.queue.push_back({3, 0x02}); // the tool button, held over two frames: one switch
    loop(*rig.drive->tools(), 0.03, 0.005);
    rig.drive->frame(home(), rig.camera, rig.controls);
    rig.drive->frame(home(), rig.camera, rig.controls);
    EXPECT_EQ(rig.controls.kind, (kind + 1) % int(kToolKindCount));
    EXPECT_TRUE(rig.controls.drilling) << "the tool button leaves the drill running";
    rig.queue.push_back({3, 0x01}); // the drill button again: off
    loop(*rig.drive->tools(), 0.04, 0.005);
    rig.queue.push_back({3, 0x00});
    loop(*rig.drive->tools(), 0.05, 0.005);
    rig.drive->frame(home(), rig.camera, rig.controls);
    EXPECT_FALSE(rig.controls.drilling);

    rig.queue.push_back(axes(1, kSpaceMouseFullScale, 0, 0));
    loop(*rig.drive->tools(), 0.06, 1.0);
    rig.queue.push_back(axes(1, 0, 0, 0));
    rig.queue.push_back({3, 0x04}); // the centre button
    loop(*rig.drive->tools(), 1.061, 0.005);
    rig.drive->frame(home(), rig.camera, rig.controls);
    loop(*rig.drive->tools(), 1.07, 0.005);
    const auto pose = rig.drive->frame(home(), rig.camera, rig.controls);
    ASSERT_TRUE(pose);
    EXPECT_NEAR(glm::length(pose->position - home().position), 0.0f, 0.05f);
    rig.controls.canDrill = false; // taken over: the device does not drill
    rig.drive->frame(home(), rig.camera, rig.controls);
    EXPECT_FALSE(rig.controls.drilling);
}

TEST(DeviceDrive, APedalSetsTheSpeedDrillsWhilePressedAndItsClutchHoldsTheTool) {
    Rig rig{PedalMap{}};
    rig.joysticks = {{"Foot Pedal", {-1.0f}, {0, 0}}};
    loop(*rig.drive->tools(), 0.0, 0.01);
    rig.drive->frame(home(), rig.camera, rig.controls);
    EXPECT_FALSE(rig.controls.drilling);
    rig.joysticks[0].axes[0] = 1.0f; // pressed to the floor
    rig.drive->frame(home(), rig.camera, rig.controls);
    EXPECT_TRUE(rig.controls.drilling);
    EXPECT_FLOAT_EQ(rig.controls.speed, 1.0f);
    rig.joysticks[0].axes[0] = 0.0f;
    rig.drive->frame(home(), rig.camera, rig.controls);
    EXPECT_NEAR(rig.controls.speed, 0.45f / 0.95f, 1e-5f);

    rig.joysticks[0].buttons[0] = 1; // clutch held: the SpaceMouse moves the hand, not the tool
    rig.drive->frame(home(), rig.camera, rig.controls);
    rig.queue.push_back(axes(1, kSpaceMouseFullScale, 0, 0));
    loop(*rig.drive->tools(), 0.011, 1.0);
    auto pose = rig.drive->frame(home(), rig.camera, rig.controls);
    ASSERT_TRUE(pose);
    EXPECT_NEAR(pose->position.x, 10.0f, 0.05f);
    rig.joysticks[0].buttons[0] = 0;
    rig.drive->frame(home(), rig.camera, rig.controls);
    loop(*rig.drive->tools(), 1.012, 1.0);
    pose = rig.drive->frame(home(), rig.camera, rig.controls);
    EXPECT_NEAR(pose->position.x, 10.0f + 30.0f, 0.1f);

    const int kind = rig.controls.kind;
    rig.joysticks[0].buttons[1] = 1;
    rig.drive->frame(home(), rig.camera, rig.controls);
    rig.drive->frame(home(), rig.camera, rig.controls); // held: one switch
    EXPECT_EQ(rig.controls.kind, (kind + 1) % int(kToolKindCount));
}

TEST(DeviceDrive, WithTheMouseThePedalSetsOnlyTheSpeedAndTheTool) {
    Rig rig{PedalMap{}, false};
    EXPECT_FALSE(rig.drive->drivesTool());
    EXPECT_EQ(rig.drive->tools(), nullptr);
    rig.joysticks = {{"Foot Pedal", {0.5f}, {0, 1}}};
    rig.controls.drilling = false;
    rig.drive->pedalOnly(rig.controls);
    EXPECT_NEAR(rig.controls.speed, (0.75f - 0.05f) / 0.95f, 1e-5f);
    EXPECT_FALSE(rig.controls.drilling) << "the mouse's button drills";
    EXPECT_EQ(rig.controls.kind, 1);
    rig.joysticks.clear(); // unplugged: the speed stays where the pedal left it
    rig.drive->pedalOnly(rig.controls);
    EXPECT_FALSE(rig.drive->pedal().present);
    EXPECT_NEAR(rig.controls.speed, (0.75f - 0.05f) / 0.95f, 1e-5f);
}

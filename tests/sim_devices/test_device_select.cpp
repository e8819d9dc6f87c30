// --device SPEC: parsed the same for every shell, refused in one line when bad or unusable there,
// and opened (a SpaceMouse that is not attached, a plugin that does not load: one line each).
#include "libsim_devices/device_select.h"
#include "libsim_devices/spacenav.h"

#include <algorithm>

#include <gtest/gtest.h>

using namespace trephine;

namespace {

bool anySpaceMouse() {
    const auto all = enumerateHidDevices();
    return std::any_of(all.begin(), all.end(), [](const HidDeviceInfo& d) { return d.usable; });
}

std::string refusal(const std::string& text, DeviceShell shell) {
    std::string error;
    if (parseDeviceSpec(text, shell, error))
        return "accepted";
    EXPECT_EQ(error.find('\n'), std::string::npos) << error;
    return error;
}

} // namespace

TEST(DeviceSelect, EachShellHasItsDefaultAndTheSpecsParse) {
    std::string error;
    auto w = parseDeviceSpec("", DeviceShell::Window, error);
    ASSERT_TRUE(w);
    EXPECT_EQ(w->kind, DeviceKind::Mouse);
    auto h = parseDeviceSpec("", DeviceShell::Headless, error);
    ASSERT_TRUE(h);
    EXPECT_EQ(h->kind, DeviceKind::Script);

    auto s = parseDeviceSpec("spacemouse", DeviceShell::Headless, error);
    ASSERT_TRUE(s);
    EXPECT_EQ(s->kind, DeviceKind::SpaceMouse);
    EXPECT_EQ(s->backend, SpaceMouseBackend::Auto);
    s = parseDeviceSpec("spacemouse:spnav?speed=30,turn=90,deadzone=20", DeviceShell::Window,
                        error);
    ASSERT_TRUE(s) << error;
    EXPECT_EQ(s->backend, SpaceMouseBackend::SpaceNav);
    EXPECT_DOUBLE_EQ(s->spaceMouse.translationGainMmPerS, 30.0);
    EXPECT_NEAR(s->spaceMouse.rotationGainRadPerS, M_PI / 2, 1e-12);
    EXPECT_EQ(s->spaceMouse.deadZone, 20);
    s = parseDeviceSpec("spacemouse?speed=5", DeviceShell::Window, error);
    ASSERT_TRUE(s) << error;
    EXPECT_EQ(s->backend, SpaceMouseBackend::Auto);
    EXPECT_DOUBLE_EQ(s->spaceMouse.translationGainMmPerS, 5.0);

    auto p = parseDeviceSpec("plugin:/opt/x/sim.so?mass=0.2", DeviceShell::Headless, error);
    ASSERT_TRUE(p);
    EXPECT_EQ(p->kind, DeviceKind::Plugin);
    EXPECT_EQ(p->plugin, "/opt/x/sim.so?mass=0.2");
}

TEST(DeviceSelect, BadSpecsAreOneLineSayingWhatToDo) {
    EXPECT_NE(refusal("mouse", DeviceShell::Headless).find("no pointer"), std::string::npos);
    EXPECT_NE(refusal("script", DeviceShell::Window).find("--headless"), std::string::npos);
    EXPECT_NE(refusal("joystick", DeviceShell::Window).find("unknown device"), std::string::npos);
    EXPECT_NE(refusal("spacemouse:usb", DeviceShell::Window).find("unknown backend (auto, hid or"),
              std::string::npos);
    EXPECT_NE(refusal("spacemouse?speed=0", DeviceShell::Window).find("out of range"),
              std::string::npos);
    EXPECT_NE(refusal("spacemouse?speed=fast", DeviceShell::Window).find("out of range"),
              std::string::npos);
    EXPECT_NE(refusal("spacemouse?deadzone=3.5", DeviceShell::Window).find("deadzone"),
              std::string::npos);
    EXPECT_NE(refusal("spacemouse?gain=2", DeviceShell::Window).find("unknown setting 'gain=2'"),
              std::string::npos);
    EXPECT_NE(refusal("plugin:", DeviceShell::Window).find("name the plugin's file"),
              std::string::npos);
    EXPECT_NE(refusal("plugin", DeviceShell::Window).find("name the plugin's file"),
              std::string::npos);
}

// No SpaceMouse is attached on a test machine and spacenavd does not run: opening one is a line
// that says so, never a crash; the shell's own devices open as nothing for the shell to make.
TEST(DeviceSelect, DevicesThatCannotOpenSayWhyInOneLine) {
    std::string error;
    EXPECT_EQ(openDevice("mouse", DeviceShell::Window, error), nullptr);
    EXPECT_EQ(error, "");
    EXPECT_EQ(openDevice("script", DeviceShell::Headless, error), nullptr);
    EXPECT_EQ(error, "");

    if (!spaceNavRunning()) {
        EXPECT_EQ(openDevice("spacemouse:spnav", DeviceShell::Window, error), nullptr);
        EXPECT_EQ(error.rfind("--device spacemouse:spnav: ", 0), 0u) << error;
        EXPECT_EQ(error.find('\n'), std::string::npos);
    }
    if (!anySpaceMouse()) {
        EXPECT_EQ(openDevice("spacemouse:hid", DeviceShell::Headless, error), nullptr);
        EXPECT_NE(error.find("no SpaceMouse found"), std::string::npos) << error;
        EXPECT_EQ(describeDeviceChoice("spacemouse:hid", DeviceShell::Window).rfind("refused: ", 0),
                  0u);
    }
    EXPECT_EQ(openDevice("plugin:/no/such/plugin.so", DeviceShell::Headless, error), nullptr);
    EXPECT_EQ(error.rfind("--device plugin:/no/such/plugin.so: ", 0), 0u) << error;
    EXPECT_EQ(error.find('\n'), std::string::npos) << error;
    EXPECT_NE(describeDeviceChoice("", DeviceShell::Window).find("mouse"), std::string::npos);
    EXPECT_NE(describeDeviceChoice("", DeviceShell::Headless).find("script"), std::string::npos);
    EXPECT_EQ(describeDeviceChoice("mouse", DeviceShell::Headless).rfind("refused: ", 0), 0u);
}

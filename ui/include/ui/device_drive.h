// The window's tool driven by a device other than the mouse (--device spacemouse, plugin:...), and
// the pedal or joystick (--pedal-map) beside any device. The device is read by the 1 kHz haptic
// loop (DeviceTools is the loop's tool source); each frame the window takes its last pose to
// draw, its button presses (drill on/off, next tool, back to the site) and the pedal's speed,
// clutch and tool switch. No GL here: tests drive it with fake devices and joysticks.
#pragma once

#include "libsim/camera.h"
#include "libsim/force_model.h"
#include "libsim/skull.h"
#include "libsim_devices/anchored_device.h"
#include "libsim_devices/pedal.h"
#include "net/trainee_core.h"
#include "ui/mouse_tool.h"
#include "ui/panels.h"

#include <functional>
#include <memory>
#include <optional>
#include <vector>

namespace trephine::ui {

// The joysticks GLFW sees now (GLFW's joystick API; the main thread, GLFW initialised).
std::vector<JoystickInput> pollJoysticks();

// A device's buttons (bit i: button i) as the window reads them.
inline constexpr uint32_t kDrillButton = 1u << 0;  // drill on / off (without a pedal's speed axis)
inline constexpr uint32_t kToolButton = 1u << 1;   // the next tool
inline constexpr uint32_t kCentreButton = 1u << 2; // the tool back over the burr site

// The loop's tool source for a device: the device's pose, the tool the frame chose (from the
// WindowDevice's Tool), and the velocity of the loop's own poses (the device moves every tick).
class DeviceTools : public net::ToolSource {
public:
    DeviceTools(AnchoredDevice& device, WindowDevice& window)
        : m_device(device), m_window(window) {}
    Device& device() override { return m_device; }
    net::ToolState toolAt(const ToolPose& pose, double now) override;
    glm::vec3 velocity(const ToolPose& pose, double now) override;

private:
    AnchoredDevice& m_device;
    WindowDevice& m_window;
    VelocityEstimate m_velocity;
};

// Where a device's tool starts: lifted `liftMm` clear of the site along its normal.
ToolPose homePose(const SurfaceSite& site, const ToolShape& shape, float liftMm);

class DeviceDrive {
public:
    using JoystickPoll = std::function<std::vector<JoystickInput>()>;
    // `device` null: the mouse drives the tool; `pedal` nullopt: no pedal is read.
    DeviceDrive(std::shared_ptr<Device> device, std::optional<PedalMap> pedal, WindowDevice& window,
                JoystickPoll poll = pollJoysticks);
    bool drivesTool() const { return m_anchored != nullptr; }
    // The haptic loop's tool source for the device (null when the mouse drives).
    net::ToolSource* tools() { return m_tools.get(); }
    AnchoredDevice* device() { return m_anchored.get(); }

    // [UI thread, once a frame] The device's tool: placed at `home` the first time, moved in the
    // view's frame (`view`), its buttons and the pedal applied to `controls`. nullopt while the
    // device reports nothing (not yet read, unplugged, cut off).
    std::optional<ToolPose> frame(const ToolPose& home, const Camera& view, ToolControls& controls);
    // [UI thread, once a frame] The pedal alone (the mouse drives): its speed sets the drill's
    // speed, its tool switch the next tool.
    void pedalOnly(ToolControls& controls);
    // The pedal's last reading (present = false without one).
    const PedalOutput& pedal() const { return m_pedalOut; }

private:
    void applyPedal(ToolControls& controls);

    std::shared_ptr<AnchoredDevice> m_anchored;
    std::unique_ptr<DeviceTools> m_tools;
    std::optional<PedalControl> m_pedal;
    JoystickPoll m_poll;
    PedalOutput m_pedalOut;
    bool m_placed = false;
    bool m_drilling = false; // the drill button's toggle
};

} // namespace trephine::ui

#include "ui/device_drive.h"

#include "libsim/tool_catalogue.h"
#include "libsim_devices/spacemouse.h"

#include <GLFW/glfw3.h>
#include <glm/geometric.hpp>

namespace trephine::ui {

std::vector<JoystickInput> pollJoysticks() {
    std::vector<JoystickInput> out;
    for (int jid = GLFW_JOYSTICK_1; jid <= GLFW_JOYSTICK_LAST; ++jid) {
        if (!glfwJoystickPresent(jid))
            continue;
        JoystickInput js;
        const char* name = glfwGetJoystickName(jid);
        js.name = name ? name : "";
        int n = 0;
        if (const float* axes = glfwGetJoystickAxes(jid, &n))
            js.axes.assign(axes, axes + n);
        if (const unsigned char* buttons = glfwGetJoystickButtons(jid, &n))
            js.buttons.assign(buttons, buttons + n);
        out.push_back(std::move(js));
    }
    return out;
}

net::ToolState DeviceTools::toolAt(const ToolPose& pose, double) {
    return m_window.toolAt(pose);
}

glm::vec3 DeviceTools::velocity(const ToolPose& pose, double now) {
    return m_velocity.update(pose.position, now);
}

ToolPose homePose(const SurfaceSite& site, const ToolShape& shape, float liftMm) {
    return toolPoseAlong(site.position, glm::normalize(site.normal), shape, -liftMm);
}

DeviceDrive::DeviceDrive(std::shared_ptr<Device> device, std::optional<PedalMap> pedal,
                         WindowDevice& window, JoystickPoll poll)
    : m_poll(std::move(poll)) {
    if (device) {
        m_anchored = std::make_shared<AnchoredDevice>(std::move(device));
        m_tools = std::make_unique<DeviceTools>(*m_anchored, window);
    }
    if (pedal)
        m_pedal.emplace(std::move(*pedal));
}

void DeviceDrive::applyPedal(ToolControls& controls) {
    m_pedalOut = m_pedal && m_poll ? m_pedal->update(m_poll()) : PedalOutput{};
    if (!m_pedalOut.present)
        return;
    if (m_pedalOut.speed)
        controls.speed = *m_pedalOut.speed;
    if (m_pedalOut.toolSwitch)
        controls.kind = (controls.kind + 1) % int(kToolKindCount);
}

void DeviceDrive::pedalOnly(ToolControls& controls) {
    applyPedal(controls);
}

std::optional<ToolPose> DeviceDrive::frame(const ToolPose& home, const Camera& view,
                                           ToolControls& controls) {
    AnchoredDevice& d = *m_anchored;
    if (!m_placed) {
        d.moveTo(home);
        m_placed = true;
    }
    // A SpaceMouse moves the tool as seen: push away is into the view, lift is up the screen.
    if (auto* sm = dynamic_cast<SpaceMouseDevice*>(&d.inner())) {
        const glm::vec3 back = glm::normalize(view.eye - view.target);
        const glm::vec3 right = glm::normalize(glm::cross(view.up, back));
        sm->setFrame(spaceMouseViewFrame(right, glm::cross(back, right), back));
    }
    applyPedal(controls);
    d.setClutch(m_pedalOut.present && m_pedalOut.clutch);
    const uint32_t presses = d.takePresses();
    if (presses & kToolButton)
        controls.kind = (controls.kind + 1) % int(kToolKindCount);
    if (presses & kCentreButton)
        d.moveTo(home);
    if (presses & kDrillButton)
        m_drilling = !m_drilling;
    const DeviceState s = d.last();
    // A pedal with a speed axis is the drill's switch: pressed drills, released stops.
    const bool pedalDrills = m_pedalOut.present && m_pedalOut.speed.has_value();
    const bool wants = pedalDrills ? *m_pedalOut.speed > 0.0f : m_drilling;
    controls.drilling = controls.canDrill && s.valid && wants;
    if (!s.valid)
        return std::nullopt;
    return s.pose;
}

} // namespace trephine::ui

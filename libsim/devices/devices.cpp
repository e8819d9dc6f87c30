#include "libsim_devices/devices.h"

#include <algorithm>
#include <glm/gtc/quaternion.hpp>

namespace trephine {

ScriptedDevice::ScriptedDevice(std::vector<Waypoint> waypoints)
    : m_waypoints(std::move(waypoints)) {
    std::stable_sort(m_waypoints.begin(), m_waypoints.end(),
                     [](const Waypoint& a, const Waypoint& b) { return a.time < b.time; });
}

DeviceState ScriptedDevice::read(double now) {
    DeviceState s;
    if (m_waypoints.empty())
        return s;
    s.valid = true;
    auto it = std::upper_bound(m_waypoints.begin(), m_waypoints.end(), now,
                               [](double t, const Waypoint& w) { return t < w.time; });
    if (it == m_waypoints.begin()) {
        s.pose = it->pose;
        s.buttons = it->buttons;
    } else if (it == m_waypoints.end()) {
        s.pose = m_waypoints.back().pose;
        s.buttons = m_waypoints.back().buttons;
    } else {
        const Waypoint& a = *(it - 1);
        const Waypoint& b = *it;
        const float u = b.time > a.time ? float((now - a.time) / (b.time - a.time)) : 1.0f;
        s.pose.position = a.pose.position + u * (b.pose.position - a.pose.position);
        s.pose.orientation = glm::slerp(a.pose.orientation, b.pose.orientation, u);
        s.buttons = a.buttons;
    }
    return s;
}

void MouseDevice::setPose(const ToolPose& pose, uint32_t buttons) {
    std::lock_guard lock(m_mutex);
    m_state.pose = pose;
    m_state.buttons = buttons;
    m_state.valid = true;
}

DeviceState MouseDevice::read(double) {
    std::lock_guard lock(m_mutex);
    return m_state;
}

} // namespace trephine

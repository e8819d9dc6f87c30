// Input devices for the haptic loop that need no hardware: null (no device), scripted (a timed
// trajectory of poses, e.g. the trajectory scripts) and mouse (a pose set from outside by the GUI).
#pragma once

#include "libsim/device.h"

#include <mutex>
#include <vector>

namespace trephine {

// Reports nothing (valid = false): the loop outputs no force and sends no tool state.
class NullDevice : public Device {
public:
    std::string name() const override { return "null"; }
    DeviceState read(double) override { return {}; }
    void setForce(glm::vec3) override {}
};

struct Waypoint {
    double time = 0.0; // s
    ToolPose pose;
    uint32_t buttons = 0;
};

// Plays a trajectory: position linear and orientation slerp between waypoints (sorted by time);
// holds the first pose before the first waypoint and the last after the last.
class ScriptedDevice : public Device {
public:
    explicit ScriptedDevice(std::vector<Waypoint> waypoints);
    std::string name() const override { return "scripted"; }
    DeviceState read(double now) override;
    void setForce(glm::vec3 f) override { m_lastForce = f; }
    bool hasForceOutput() const override { return true; } // records it, for tests and studies
    glm::vec3 lastForce() const { return m_lastForce; }
    double duration() const { return m_waypoints.empty() ? 0.0 : m_waypoints.back().time; }

private:
    std::vector<Waypoint> m_waypoints;
    glm::vec3 m_lastForce{0.0f};
};

// The GUI's mouse: another thread sets the pose; the haptic thread reads it. No force output.
class MouseDevice : public Device {
public:
    std::string name() const override { return "mouse"; }
    void setPose(const ToolPose& pose, uint32_t buttons = 0);
    DeviceState read(double now) override;
    void setForce(glm::vec3) override {}

private:
    std::mutex m_mutex;
    DeviceState m_state;
};

} // namespace trephine

// The input/haptic device interface the 1 kHz haptic loop drives: read a pose and buttons, write a
// force. Implementations (null, scripted, mouse, SpaceMouse) live in sim_devices.
#pragma once

#include "libsim/tool.h"

#include <cstdint>
#include <glm/vec3.hpp>
#include <string>

namespace trephine {

struct DeviceState {
    ToolPose pose;        // the tool pose the device commands (object space, mm)
    uint32_t buttons = 0; // bit i set: button i pressed
    bool valid = false;   // false when the device has nothing to report (disconnected, no data)
};

class Device {
public:
    virtual ~Device() = default;
    virtual std::string name() const = 0;
    // Called by the haptic thread once a tick; `now` in seconds on the loop's clock.
    virtual DeviceState read(double now) = 0;
    // Force on the user's hand (N, object space). Devices without force output ignore it.
    virtual void setForce(glm::vec3 forceN) = 0;
    virtual bool hasForceOutput() const { return false; }
};

} // namespace trephine

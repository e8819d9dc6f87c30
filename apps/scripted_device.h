// A device that plays a script's poses, for a TraineeSession (net does not link the devices): the
// headless trainee's and the demo's.
#pragma once

#include "libsim_devices/devices.h"
#include "net/trainee_core.h"

#include <memory>
#include <vector>

namespace trephine::app {

inline std::unique_ptr<Device> scriptedDevice(const std::vector<net::ScriptSample>& script) {
    std::vector<Waypoint> waypoints;
    for (const net::ScriptSample& s : script)
        waypoints.push_back({s.t, ToolPose{s.tool.position, s.tool.orientation}, 0});
    return std::make_unique<ScriptedDevice>(std::move(waypoints));
}

} // namespace trephine::app

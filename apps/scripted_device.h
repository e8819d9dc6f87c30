// The devices of the headless shells (the trainee's and the demo's) for a TraineeSession (net
// does not link the devices): the script's poses, or the --device chosen.
#pragma once

#include "libsim/error.h"
#include "libsim_devices/anchored_device.h"
#include "libsim_devices/device_select.h"
#include "libsim_devices/devices.h"
#include "libsim_devices/spacemouse.h"
#include "net/trainee_core.h"

#include <cstdio>
#include <memory>
#include <string>
#include <vector>

namespace trephine::app {

inline std::unique_ptr<Device> scriptedDevice(const std::vector<net::ScriptSample>& script) {
    std::vector<Waypoint> waypoints;
    for (const net::ScriptSample& s : script)
        waypoints.push_back({s.t, ToolPose{s.tool.position, s.tool.orientation}, 0});
    return std::make_unique<ScriptedDevice>(std::move(waypoints));
}

// The --device `spec` opened before anything connects (null: the script's own poses); a bad one
// throws trephine::Error, its one line.
inline std::unique_ptr<Device> openHeadlessDevice(const std::string& spec, const char* who) {
    std::string error;
    std::unique_ptr<Device> d = openDevice(spec, DeviceShell::Headless, error);
    if (!error.empty())
        throw Error(error);
    if (d)
        std::printf("%s: the tool follows %s\n", who, d->name().c_str());
    return d;
}

// The tool's device: the script's poses, or `opened`, which moves the tool from the script's
// first pose (a SpaceMouse) or through its own workspace (a plugin, the script its intent).
inline std::unique_ptr<Device> headlessDevice(std::unique_ptr<Device> opened,
                                              const std::vector<net::ScriptSample>& script) {
    if (!opened)
        return scriptedDevice(script);
    if (!dynamic_cast<SpaceMouseDevice*>(opened.get()))
        return opened;
    auto placed = std::make_unique<AnchoredDevice>(std::move(opened));
    placed->setAnchor(ToolPose{script.front().tool.position, script.front().tool.orientation});
    return placed;
}

} // namespace trephine::app

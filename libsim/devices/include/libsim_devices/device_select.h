// `--device SPEC`: which device drives the tool, the same in every shell (the window, the headless
// trainee, `trephine devices`). SPEC is one of
//   mouse                          the window's pointer (the window's default)
//   script                         the --script's poses (the headless trainee's default)
//   spacemouse[:auto|hid|spnav][?speed=MM/S,turn=DEG/S,deadzone=COUNTS]
//                                  a 3Dconnexion SpaceMouse; auto: spacenavd when it answers,
//                                  else hidapi
//   plugin:PATH.so[?ARGS]          a force-feedback plugin (plugin_device.h)
// A bad spec, or a device that cannot be opened, is one line saying what to do.
#pragma once

#include "libsim/device.h"
#include "libsim_devices/spacemouse.h"

#include <memory>
#include <optional>
#include <string>

namespace trephine {

enum class DeviceShell { Window, Headless };
enum class DeviceKind { Mouse, Script, SpaceMouse, Plugin };
enum class SpaceMouseBackend { Auto, Hid, SpaceNav };

struct DeviceSpec {
    DeviceKind kind = DeviceKind::Mouse;
    SpaceMouseBackend backend = SpaceMouseBackend::Auto;
    SpaceMouseConfig spaceMouse; // speed, turn and dead zone from the spec's ?query
    std::string plugin;          // PATH.so[?ARGS]
    std::string text;            // as given
};

// The shell's own device when --device is not given.
const char* defaultDeviceSpec(DeviceShell shell);
const char* shellName(DeviceShell shell);

// nullopt and a one-line `error` for a spec this shell cannot use ("" is the shell's default).
std::optional<DeviceSpec> parseDeviceSpec(const std::string& text, DeviceShell shell,
                                          std::string& error);

// Opens what `spec` names: a SpaceMouse or a plugin. nullptr with an empty `error` for the
// shell's own devices (mouse, script), which the shell makes; nullptr and a one-line `error` when
// the device cannot be opened.
std::unique_ptr<Device> openDevice(const DeviceSpec& spec, std::string& error);
// parseDeviceSpec, then openDevice.
std::unique_ptr<Device> openDevice(const std::string& text, DeviceShell shell, std::string& error);

// The backend `auto` resolves to here, now (spacenavd when it answers, else hidapi).
SpaceMouseBackend resolveBackend(SpaceMouseBackend wanted);
const char* backendName(SpaceMouseBackend backend);

// One line for `trephine devices`: the device `text` gives this shell here and now (it is opened
// and closed to find out), or why it cannot.
std::string describeDeviceChoice(const std::string& text, DeviceShell shell);

} // namespace trephine

#include "libsim_devices/device_select.h"

#include "libsim/error.h"
#include "libsim_devices/plugin_device.h"
#include "libsim_devices/spacenav.h"

#include <charconv>
#include <cmath>

namespace trephine {

namespace {

const char* kSpecs = "mouse, script, spacemouse[:auto|hid|spnav][?speed=,turn=,deadzone=] or "
                     "plugin:PATH.so";

// A finite number in [lo, hi] from `text`, or false.
bool numberIn(const std::string& text, double lo, double hi, double& out) {
    const char* end = text.data() + text.size();
    auto [p, ec] = std::from_chars(text.data(), end, out);
    return ec == std::errc() && p == end && std::isfinite(out) && out >= lo && out <= hi;
}

// "speed=40,turn=90,deadzone=20" into `c`; false with `error` on the first bad item.
bool parseSpaceMouseQuery(const std::string& query, SpaceMouseConfig& c, std::string& error) {
    size_t at = 0;
    while (at <= query.size()) {
        const size_t comma = std::min(query.find(',', at), query.size());
        const std::string item = query.substr(at, comma - at);
        at = comma + 1;
        const size_t eq = item.find('=');
        const std::string key = item.substr(0, eq),
                          value = eq == std::string::npos ? "" : item.substr(eq + 1);
        double v = 0.0;
        if (key == "speed" && numberIn(value, 0.1, 1000.0, v))
            c.translationGainMmPerS = v;
        else if (key == "turn" && numberIn(value, 1.0, 1440.0, v))
            c.rotationGainRadPerS = v * M_PI / 180.0;
        else if (key == "deadzone" && numberIn(value, 0.0, kSpaceMouseFullScale - 1, v) &&
                 v == std::floor(v))
            c.deadZone = int(v);
        else {
            error = key == "speed" || key == "turn" || key == "deadzone"
                        ? "--device spacemouse: " + key + "=" + value +
                              " is out of range (speed 0.1-1000 mm/s, turn 1-1440 deg/s, "
                              "deadzone a whole 0-349)"
                        : "--device spacemouse: unknown setting '" + item +
                              "' (known: speed=MM/S, turn=DEG/S, deadzone=COUNTS)";
            return false;
        }
    }
    return true;
}

std::optional<DeviceSpec> parseSpaceMouse(DeviceSpec s, const std::string& rest,
                                          std::string& error) {
    const size_t q = rest.find('?');
    const std::string backend = rest.substr(0, q);
    if (backend.empty() || backend == "auto")
        s.backend = SpaceMouseBackend::Auto;
    else if (backend == "hid")
        s.backend = SpaceMouseBackend::Hid;
    else if (backend == "spnav")
        s.backend = SpaceMouseBackend::SpaceNav;
    else {
        error = "--device spacemouse:" + backend + ": unknown backend (auto, hid or spnav)";
        return std::nullopt;
    }
    if (q != std::string::npos && !parseSpaceMouseQuery(rest.substr(q + 1), s.spaceMouse, error))
        return std::nullopt;
    return s;
}

std::unique_ptr<Device> openSpaceMouse(const DeviceSpec& spec, std::string& error) {
    try {
        const SpaceMouseBackend b = resolveBackend(spec.backend);
        std::unique_ptr<SpaceMouseSource> source =
            b == SpaceMouseBackend::SpaceNav ? openSpaceNav() : openHidSpaceMouse();
        return std::make_unique<SpaceMouseDevice>(std::move(source), spec.spaceMouse);
    } catch (const Error& e) {
        error = std::string("--device ") + spec.text + ": " + e.what();
        if (spec.backend == SpaceMouseBackend::Auto && kHaveSpaceNav)
            error += " (spacenavd does not answer either)";
        return nullptr;
    }
}

} // namespace

const char* defaultDeviceSpec(DeviceShell shell) {
    return shell == DeviceShell::Window ? "mouse" : "script";
}

const char* shellName(DeviceShell shell) {
    return shell == DeviceShell::Window ? "the window" : "the headless trainee";
}

std::optional<DeviceSpec> parseDeviceSpec(const std::string& given, DeviceShell shell,
                                          std::string& error) {
    DeviceSpec s;
    s.text = given.empty() ? defaultDeviceSpec(shell) : given;
    const std::string& t = s.text;
    const size_t colon = t.find(':');
    const std::string head = t.substr(0, std::min(colon, t.find('?')));
    if (t == "mouse") {
        if (shell == DeviceShell::Headless) {
            error = "--device mouse: the headless trainee has no pointer (script, spacemouse or "
                    "plugin:PATH.so; the window's default is the mouse)";
            return std::nullopt;
        }
        s.kind = DeviceKind::Mouse;
    } else if (t == "script") {
        if (shell == DeviceShell::Window) {
            error = "--device script: the window's tool follows the mouse or a device (mouse, "
                    "spacemouse or plugin:PATH.so); a --headless trainee plays scripts";
            return std::nullopt;
        }
        s.kind = DeviceKind::Script;
    } else if (head == "spacemouse") {
        s.kind = DeviceKind::SpaceMouse;
        return parseSpaceMouse(
            s, colon == std::string::npos ? t.substr(head.size()) : t.substr(colon + 1), error);
    } else if (head == "plugin") {
        s.kind = DeviceKind::Plugin;
        s.plugin = colon == std::string::npos ? "" : t.substr(colon + 1);
        if (s.plugin.empty() || s.plugin[0] == '?') {
            error = "--device plugin: name the plugin's file (plugin:PATH.so)";
            return std::nullopt;
        }
    } else {
        error = "--device " + t + ": unknown device (" + kSpecs + ")";
        return std::nullopt;
    }
    return s;
}

SpaceMouseBackend resolveBackend(SpaceMouseBackend wanted) {
    if (wanted != SpaceMouseBackend::Auto)
        return wanted;
    // spacenavd holds the device when it runs; through it the user's own settings apply.
    return spaceNavRunning() ? SpaceMouseBackend::SpaceNav : SpaceMouseBackend::Hid;
}

const char* backendName(SpaceMouseBackend backend) {
    switch (backend) {
    case SpaceMouseBackend::Hid:
        return "hid";
    case SpaceMouseBackend::SpaceNav:
        return "spnav";
    default:
        return "auto";
    }
}

std::unique_ptr<Device> openDevice(const DeviceSpec& spec, std::string& error) {
    error.clear();
    switch (spec.kind) {
    case DeviceKind::SpaceMouse:
        return openSpaceMouse(spec, error);
    case DeviceKind::Plugin: {
        std::unique_ptr<Device> d = openPluginDevice(spec.plugin, error);
        if (!d && error.empty())
            error = "--device " + spec.text + ": the plugin did not open";
        else if (!d && error.rfind("--device", 0) != 0)
            error = "--device " + spec.text + ": " + error;
        return d;
    }
    default:
        return nullptr;
    }
}

std::unique_ptr<Device> openDevice(const std::string& text, DeviceShell shell, std::string& error) {
    const std::optional<DeviceSpec> spec = parseDeviceSpec(text, shell, error);
    return spec ? openDevice(*spec, error) : nullptr;
}

std::string describeDeviceChoice(const std::string& text, DeviceShell shell) {
    std::string error;
    const std::optional<DeviceSpec> spec = parseDeviceSpec(text, shell, error);
    if (!spec)
        return "refused: " + error;
    switch (spec->kind) {
    case DeviceKind::Mouse:
        return "mouse (the pointer on the bone under it)";
    case DeviceKind::Script:
        return "script (the --script's poses: burrhole or a CSV trajectory)";
    default:
        break;
    }
    std::unique_ptr<Device> d = openDevice(*spec, error);
    if (!d)
        return "refused: " + error;
    std::string line = spec->text + ": " + d->name();
    if (spec->kind == DeviceKind::SpaceMouse)
        line +=
            std::string(" through ") +
            (resolveBackend(spec->backend) == SpaceMouseBackend::SpaceNav ? "spacenavd" : "hidapi");
    if (d->hasForceOutput())
        line += ", with force output";
    return line;
}

} // namespace trephine

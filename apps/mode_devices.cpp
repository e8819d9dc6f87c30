// `trephine devices`: what is attached (the HID devices hidapi sees, spacenavd, the joysticks GLFW
// sees) and which device each mode would drive its tool with, given --device and --pedal-map.
#include "mode_window.h"
#include "modes.h"

#include "libsim_devices/device_select.h"
#include "libsim_devices/pedal.h"
#include "libsim_devices/spacemouse.h"
#include "libsim_devices/spacenav.h"

#include <cstdio>
#include <optional>

#ifdef TREPHINE_HAVE_GUI
#include "ui/device_drive.h"
#include "ui/window.h"
#endif

namespace trephine::app {

namespace {

struct DevicesOptions {
    std::string device;
    std::string pedalMap;
};

void printHid() {
    const std::vector<HidDeviceInfo> devices = enumerateHidDevices();
    int usable = 0;
    for (const HidDeviceInfo& d : devices) {
        std::printf("%04x:%04x  %-10s %s %s  %s\n", d.vendorId, d.productId,
                    d.usable ? "usable" : "-", d.manufacturer.c_str(), d.product.c_str(),
                    d.path.c_str());
        usable += d.usable;
    }
    std::printf("hidapi: %zu HID device%s, %d usable SpaceMouse%s\n", devices.size(),
                devices.size() == 1 ? "" : "s", usable, usable == 1 ? "" : "s");
    std::string why;
    std::printf("spacenavd: %s\n", spaceNavRunning(&why) ? "answers" : why.c_str());
}

// The joysticks GLFW sees (nullopt and `why` without a display: GLFW cannot start).
std::optional<std::vector<JoystickInput>> joysticks(std::string& why) {
#ifdef TREPHINE_HAVE_GUI
    if (ui::displayAvailable(&why))
        return ui::pollJoysticks();
#else
    why = "this trephine was built without the GUI";
#endif
    return std::nullopt;
}

void printPedal(const DevicesOptions& o) {
    std::string why;
    const auto attached = joysticks(why);
    if (!attached) {
        std::printf("joysticks: not listed (%s; GLFW's joystick API needs a display)\n",
                    why.c_str());
    } else {
        std::printf("joysticks: %zu\n", attached->size());
        for (const JoystickInput& j : *attached)
            std::printf("  %s  (%zu axes, %zu buttons)\n", j.name.c_str(), j.axes.size(),
                        j.buttons.size());
    }
    if (o.pedalMap.empty()) {
        std::printf("pedal: none read (--pedal-map FILE or default to read one)\n");
        return;
    }
    const PedalMap map = readPedalMap(o.pedalMap); // a bad one: one line, exit 1
    std::printf("pedal: %s\n", pedalMapJson(map).c_str());
    if (attached) {
        const int i = chooseJoystick(map, *attached);
        std::printf("pedal: %s\n", i < 0 ? "no attached joystick matches the mapping"
                                         : ("reads " + (*attached)[size_t(i)].name).c_str());
    }
}

int runDevices(const DevicesOptions& o) {
    printHid();
    printPedal(o);
    const std::string given = o.device.empty() ? "" : " (--device " + o.device + ")";
    std::printf("window (trainee, instructor)%s: %s\n", given.c_str(),
                describeDeviceChoice(o.device, DeviceShell::Window).c_str());
    std::printf("headless trainee%s: %s\n", given.c_str(),
                describeDeviceChoice(o.device, DeviceShell::Headless).c_str());
    return 0;
}

} // namespace

void addDevicesMode(CLI::App& root, int& exitCode) {
    auto o = std::make_shared<DevicesOptions>();
    CLI::App* sub = root.add_subcommand(
        "devices", "What is attached, and which device each mode would drive its tool with");
    addDeviceOptions(sub, o->device, o->pedalMap);
    sub->callback([o, &exitCode] { exitCode = runDevices(*o); });
}

} // namespace trephine::app

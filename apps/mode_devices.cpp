// `trephine devices`: the HID devices hidapi sees and which of them can drive a tool (3Dconnexion
// SpaceMice). The mouse and scripted devices need no hardware and are always available.
#include "modes.h"

#include "libsim_devices/spacemouse.h"

#include <cstdio>

namespace trephine::app {

namespace {

int runDevices() {
    const std::vector<HidDeviceInfo> devices = enumerateHidDevices();
    if (devices.empty()) {
        std::printf("no HID devices found; the mouse and scripted devices are always available\n");
        return 0;
    }
    int usable = 0;
    for (const HidDeviceInfo& d : devices) {
        std::printf("%04x:%04x  %-10s %s %s  %s\n", d.vendorId, d.productId,
                    d.usable ? "usable" : "-", d.manufacturer.c_str(), d.product.c_str(),
                    d.path.c_str());
        usable += d.usable;
    }
    std::printf("%zu HID device%s, %d usable SpaceMouse%s; the mouse and scripted devices are "
                "always available\n",
                devices.size(), devices.size() == 1 ? "" : "s", usable, usable == 1 ? "" : "s");
    return 0;
}

} // namespace

void addDevicesMode(CLI::App& root, int& exitCode) {
    CLI::App* sub = root.add_subcommand("devices", "List haptic and 6-DOF input devices");
    sub->callback([&exitCode] { exitCode = runDevices(); });
}

} // namespace trephine::app

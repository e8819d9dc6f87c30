// Force-feedback devices loaded at run time: a shared library implementing the C ABI of
// trephine_device_abi.h, opened with dlopen and driven through a worker thread, so a plugin call
// that hangs costs the 1 kHz loop one deadline, never a stall (docs/devices.md).
#pragma once

#include "libsim/device_guard.h"
#include "libsim_devices/trephine_device_abi.h"

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

namespace trephine {

struct PluginOptions {
    // Passed to the plugin's open() (e.g. "mass=0.15,k=1"): the part of a spec after '?'.
    std::string args;
    // A read not back this long after it was posted reads invalid: the loop outputs zero force
    // that tick (one tick).
    double deadlineS = 0.001;
    // A call inside the plugin this long cuts the device off: from then on it reads invalid and
    // is never called again but to close. Longer than a tick, so that one preemption or USB
    // hiccup on a busy machine costs a tick's force, not the session's.
    double hangS = 0.02;
    // Where the one line saying why a device was cut off goes (default: stderr).
    std::function<void(const std::string&)> report;
};

// One tick as the device saw it: the pose it reported and the force it says it applied.
struct PluginSample {
    double time = 0.0;
    glm::vec3 position{0.0f};
    glm::vec3 applied{0.0f}; // the device's own measure, or the force last written
};

class PluginDevice : public ForceDevice {
public:
    ~PluginDevice() override;
    std::string name() const override;
    DeviceState read(double now) override;
    void setForce(glm::vec3 forceN) override;
    bool hasForceOutput() const override { return true; }
    float maxForceN() const override;
    DeviceWorkspace workspace() const override;
    bool acceptsIntent() const override;
    void setIntent(const ToolPose& pose) override;
    std::string fault() const override;

    // The most recent ticks (oldest first), for tests and figures.
    std::vector<PluginSample> history() const;
    uint64_t calls() const;       // plugin calls made
    uint64_t missedTicks() const; // reads that came back invalid for a late or failed call

    struct Impl;

private:
    friend std::unique_ptr<PluginDevice> openPlugin(const std::string&, const PluginOptions&,
                                                    std::string&);
    explicit PluginDevice(std::shared_ptr<Impl> impl);
    std::shared_ptr<Impl> m_impl; // shared with the worker, which may outlive a hung close
};

// A plugin's library loaded and its device opened, its table padded with nulls to this ABI's
// size. Called directly, on the caller's thread: for simulated time (the haptics study's hand),
// where a slow call cannot cost a tick; a live loop uses PluginDevice.
struct LoadedPlugin {
    void* library = nullptr;
    TrephineDeviceApi api{};
    TrephineDevice* device = nullptr;
    TrephineDeviceInfo info{};
};
// Loads `path` and opens its device with `args`; false and a one-line `error` as openPluginDevice.
bool loadPlugin(const std::string& path, const std::string& args, LoadedPlugin& out,
                std::string& error);
// Closes the device and unloads the library.
void unloadPlugin(LoadedPlugin& p);

// Loads PATH (a spec "PATH.so" or "PATH.so?ARGS") and opens its device. nullptr and a one-line
// `error` (naming the file and what failed) when the library, its entry point, its ABI version or
// its open() fails. The --device plugin:SPEC selector calls this.
std::unique_ptr<Device> openPluginDevice(const std::string& path, std::string& error);
std::unique_ptr<PluginDevice> openPlugin(const std::string& path, const PluginOptions& options,
                                         std::string& error);

} // namespace trephine

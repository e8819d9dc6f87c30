// The safety every force device goes through: forces clamped to the device's maximum and
// rate-limited per tick, zero at once when the device faults, the link is down or the session has
// ended. ForceDevice is what a force-feedback device adds to Device (docs/devices.md).
#pragma once

#include "libsim/device.h"
#include "libsim/force_model.h"

#include <atomic>
#include <functional>
#include <glm/vec3.hpp>
#include <optional>
#include <string>

namespace trephine {

// The box a device's tool can reach (mm, in the frame its poses are in).
struct DeviceWorkspace {
    glm::vec3 min{-1e6f}, max{1e6f};
};

class ForceDevice : public Device {
public:
    virtual float maxForceN() const = 0;
    virtual DeviceWorkspace workspace() const = 0;
    // A simulated hand moves towards an intent (a real hand has its own): where the tool should
    // be this tick. Real devices ignore it.
    virtual bool acceptsIntent() const { return false; }
    virtual void setIntent(const ToolPose&) {}
    // Non-empty once the device was cut off (a failed or late call): why, in one line.
    virtual std::string fault() const { return {}; }
};

struct DeviceGuardConfig {
    float maxForceN = kDefaultMaxForceN; // the lower of this and the device's own maximum
    float maxStepN = 1.0f;               // the most the output may change from one tick to the next
};

struct DeviceGuardStats {
    uint64_t ticks = 0;
    uint64_t clamped = 0; // forces above the maximum
    uint64_t limited = 0; // steps above maxStepN
    uint64_t gated = 0;   // ticks held at zero: link down, session over, device invalid or faulted
};

// Wraps a device for the haptic loop (read and setForce on its thread); setDriven and the gate
// may change from any thread. A drop to zero is never rate-limited.
class DeviceGuard : public Device {
public:
    using Gate = std::function<bool()>;
    using IntentSource = std::function<std::optional<ToolPose>(double now)>;

    explicit DeviceGuard(Device& inner, DeviceGuardConfig config = {});
    std::string name() const override { return m_inner.name(); }
    DeviceState read(double now) override;
    void setForce(glm::vec3 forceN) override;
    bool hasForceOutput() const override { return m_inner.hasForceOutput(); }

    // Asked once a tick: false holds the output at zero (e.g. the link is down).
    void setGate(Gate gate) { m_gate = std::move(gate); }
    // Where a simulated hand wants the tool, handed to the device before each read.
    void setIntentSource(IntentSource source) { m_intent = std::move(source); }
    // For good (the session is over; call with the loop stopped): writes zero now and on every
    // later setForce.
    void release();
    bool released() const { return m_released.load(); }

    float maxForceN() const { return m_maxForceN; }
    glm::vec3 lastOutput() const { return m_last; }
    DeviceGuardStats stats() const { return m_stats; } // the haptic thread's, or after it stopped
    Device& inner() { return m_inner; }
    const Device& inner() const { return m_inner; }

private:
    Device& m_inner;
    ForceDevice* m_force; // m_inner when it is one
    DeviceGuardConfig m_config;
    float m_maxForceN;
    Gate m_gate;
    IntentSource m_intent;
    std::atomic<bool> m_released{false};
    bool m_open = false; // this tick: the device read valid and the gate was open
    glm::vec3 m_last{0.0f};
    DeviceGuardStats m_stats;
};

} // namespace trephine

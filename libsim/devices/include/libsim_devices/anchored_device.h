// A device placed in the scene: its own pose (a SpaceMouse's integrated motion from the origin, a
// force device's stylus in its workspace) offset by an anchor, held still while a clutch is held,
// and its last state and button presses kept for another thread (the window draws the tool the
// haptic loop reads). The haptic loop reads it; forces pass through unchanged (the anchor only
// translates positions), and a force device's maximum, workspace and intent are passed on, so
// DeviceGuard treats the wrapped device as the device itself.
#pragma once

#include "libsim/device_guard.h"

#include <memory>
#include <mutex>

namespace trephine {

class AnchoredDevice : public ForceDevice {
public:
    explicit AnchoredDevice(std::shared_ptr<Device> inner);
    std::string name() const override { return m_inner->name(); }
    // The haptic thread: the inner device's pose moved by the anchor (position added, orientation
    // turned by the anchor's), or, while clutched, the pose held when the clutch went down.
    // Invalid until placed (setAnchor, or moveTo and a read).
    DeviceState read(double now) override;
    void setForce(glm::vec3 forceN) override { m_inner->setForce(forceN); }
    bool hasForceOutput() const override { return m_inner->hasForceOutput(); }
    // A force device's own; a device without force output reports 0 N.
    float maxForceN() const override { return m_force ? m_force->maxForceN() : 0.0f; }
    DeviceWorkspace workspace() const override;
    bool acceptsIntent() const override { return m_force && m_force->acceptsIntent(); }
    void setIntent(const ToolPose& pose) override; // scene -> the device's own frame
    std::string fault() const override { return m_force ? m_force->fault() : std::string(); }

    // Any thread. Where the device's origin sits in the scene: the next read reports the inner
    // pose composed with it (a SpaceMouse that has not moved reports exactly `anchor`).
    void setAnchor(const ToolPose& anchor);
    // Re-anchors so that the tool is at `pose` now, wherever the inner device is (recentring).
    void moveTo(const ToolPose& pose);
    bool anchored() const;
    // While held, the tool stays where it was and the inner device's motion is dropped; on release
    // the tool goes on from there (a clutch: reposition the hand, not the tool).
    void setClutch(bool held);
    // The last state read (valid = false before the first read).
    DeviceState last() const;
    // Buttons that went down since the last call (bit i: button i), so a press shorter than a
    // frame still counts.
    uint32_t takePresses();
    Device& inner() { return *m_inner; }

private:
    ToolPose compose(const ToolPose& p) const; // under m_mutex

    std::shared_ptr<Device> m_inner;
    ForceDevice* m_force; // m_inner when it is one
    mutable std::mutex m_mutex;
    ToolPose m_anchor;
    bool m_anchored = false;
    bool m_clutch = false;
    bool m_pendingMove = false; // moveTo before a read
    ToolPose m_moveTo;
    DeviceState m_last, m_lastInner;
    uint32_t m_presses = 0;
};

} // namespace trephine

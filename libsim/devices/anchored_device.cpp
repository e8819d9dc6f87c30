#include "libsim_devices/anchored_device.h"

#include <glm/gtc/quaternion.hpp>

namespace trephine {

AnchoredDevice::AnchoredDevice(std::shared_ptr<Device> inner)
    : m_inner(std::move(inner)), m_force(dynamic_cast<ForceDevice*>(m_inner.get())) {}

DeviceWorkspace AnchoredDevice::workspace() const {
    if (!m_force)
        return {};
    DeviceWorkspace w = m_force->workspace();
    std::lock_guard lock(m_mutex);
    w.min += m_anchor.position;
    w.max += m_anchor.position;
    return w;
}

void AnchoredDevice::setIntent(const ToolPose& pose) {
    if (!m_force)
        return;
    ToolPose inner;
    {
        std::lock_guard lock(m_mutex);
        inner.position = pose.position - m_anchor.position;
        inner.orientation = glm::normalize(pose.orientation * glm::inverse(m_anchor.orientation));
    }
    m_force->setIntent(inner);
}

ToolPose AnchoredDevice::compose(const ToolPose& p) const {
    ToolPose out;
    out.position = m_anchor.position + p.position;
    out.orientation = glm::normalize(p.orientation * m_anchor.orientation);
    return out;
}

// The anchor that puts the tool at `target` with the inner device at `inner`: the inverse of
// compose.
static ToolPose anchorFor(const ToolPose& target, const ToolPose& inner) {
    ToolPose a;
    a.position = target.position - inner.position;
    a.orientation = glm::normalize(glm::inverse(inner.orientation) * target.orientation);
    return a;
}

DeviceState AnchoredDevice::read(double now) {
    DeviceState s = m_inner->read(now); // outside the lock: a plugin call may take its tick
    std::lock_guard lock(m_mutex);
    if (m_pendingMove && s.valid) {
        m_anchor = anchorFor(m_moveTo, s.pose);
        m_anchored = true;
        m_pendingMove = false;
    }
    if (m_clutch && m_last.valid && s.valid)
        m_anchor = anchorFor(m_last.pose, s.pose); // the tool stays; the hand moves
    m_presses |= s.buttons & ~m_lastInner.buttons;
    m_lastInner = s;
    s.pose = compose(s.pose);
    // Not yet placed: its pose means nothing in the scene (a force device's rest sits at the
    // volume's centre), so nothing is sent or felt from it.
    s.valid = s.valid && m_anchored;
    m_last = s;
    return s;
}

void AnchoredDevice::setAnchor(const ToolPose& anchor) {
    std::lock_guard lock(m_mutex);
    m_anchor = anchor;
    m_anchored = true;
    m_pendingMove = false;
}

void AnchoredDevice::moveTo(const ToolPose& pose) {
    std::lock_guard lock(m_mutex);
    if (m_lastInner.valid) {
        m_anchor = anchorFor(pose, m_lastInner.pose);
        m_anchored = true;
        m_last.valid = true; // placed where the device was last read
    } else {
        m_moveTo = pose;
        m_pendingMove = true;
    }
    m_last.pose = pose;
}

bool AnchoredDevice::anchored() const {
    std::lock_guard lock(m_mutex);
    return m_anchored || m_pendingMove;
}

void AnchoredDevice::setClutch(bool held) {
    std::lock_guard lock(m_mutex);
    m_clutch = held;
}

DeviceState AnchoredDevice::last() const {
    std::lock_guard lock(m_mutex);
    return m_last;
}

uint32_t AnchoredDevice::takePresses() {
    std::lock_guard lock(m_mutex);
    const uint32_t p = m_presses;
    m_presses = 0;
    return p;
}

} // namespace trephine

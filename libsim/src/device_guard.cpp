#include "libsim/device_guard.h"

#include <algorithm>
#include <cmath>
#include <glm/geometric.hpp>

namespace trephine {

DeviceGuard::DeviceGuard(Device& inner, DeviceGuardConfig config)
    : m_inner(inner), m_force(dynamic_cast<ForceDevice*>(&inner)), m_config(config),
      m_maxForceN(config.maxForceN) {
    if (m_force)
        m_maxForceN = std::min(m_maxForceN, std::max(0.0f, m_force->maxForceN()));
}

DeviceState DeviceGuard::read(double now) {
    m_stats.ticks++;
    if (m_intent && m_force && m_force->acceptsIntent())
        if (const std::optional<ToolPose> intent = m_intent(now))
            m_force->setIntent(*intent);
    DeviceState s = m_inner.read(now);
    m_open = s.valid && !m_released.load(std::memory_order_relaxed) && (!m_gate || m_gate());
    return s;
}

void DeviceGuard::setForce(glm::vec3 f) {
    if (!m_open || m_released.load(std::memory_order_relaxed) || !std::isfinite(f.x) ||
        !std::isfinite(f.y) || !std::isfinite(f.z)) {
        // Not driven: zero at once, and the next drive ramps up from zero.
        m_stats.gated++;
        m_last = glm::vec3(0.0f);
        m_inner.setForce(m_last);
        return;
    }
    const float n = glm::length(f);
    if (n > m_maxForceN) {
        m_stats.clamped++;
        f *= m_maxForceN / n;
    }
    const glm::vec3 step = f - m_last;
    const float s = glm::length(step);
    // A step straight to zero is always safe; any other large step is spread over ticks.
    if (s > m_config.maxStepN && glm::length(f) > 0.0f) {
        m_stats.limited++;
        f = m_last + step * (m_config.maxStepN / s);
    }
    m_last = f;
    m_inner.setForce(f);
}

void DeviceGuard::release() {
    m_released.store(true);
    m_open = false;
    m_last = glm::vec3(0.0f);
    m_inner.setForce(m_last);
}

} // namespace trephine

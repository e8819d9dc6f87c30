#include "ui/mouse_tool.h"

#include <glm/geometric.hpp>
#include <glm/gtx/quaternion.hpp>

namespace trephine::ui {

std::optional<glm::vec3> pickSurface(const Dbi& dbi, const Camera& camera, int px, int py) {
    if (!dbi.bounds().contains(px, py))
        return std::nullopt;
    const float d = dbi.depth(px, py);
    if (!(d < 1.0f))
        return std::nullopt;
    glm::dvec4 ndc(2.0 * (px + 0.5) / dbi.width() - 1.0, 2.0 * (py + 0.5) / dbi.height() - 1.0,
                   2.0 * double(d) - 1.0, 1.0);
    glm::dvec4 p = glm::inverse(viewProjection(camera)) * ndc;
    return glm::vec3(glm::dvec3(p) / p.w);
}

ToolPose toolPoseAt(glm::vec3 surface, const Camera& camera, const ToolShape& shape, float pushMm) {
    const glm::vec3 axis = glm::normalize(camera.eye - surface);
    const float out = shape.kind == ToolKind::Burr ? shape.diameterMm * 0.5f : 0.0f;
    ToolPose pose;
    pose.position = surface + axis * (out - pushMm);
    pose.orientation = glm::rotation(glm::vec3(0, 0, 1), axis);
    return pose;
}

namespace {

glm::vec3 anyPerpendicular(glm::vec3 n) {
    return glm::normalize(
        glm::cross(n, std::abs(n.z) < 0.9f ? glm::vec3(0, 0, 1) : glm::vec3(1, 0, 0)));
}

} // namespace

ScriptPose burrholePose(const SurfaceSite& site, double t) {
    const glm::vec3 n = site.normal, e1 = anyPerpendicular(n), e2 = glm::cross(n, e1);
    const float depth = 2.0f;
    if (t < 1.0) {
        float d = -1.0f + float(t) * (depth + 1.0f);
        return {site.position - n * d, n, true, false};
    }
    if (t < 4.0) {
        float u = float((t - 1.0) / 3.0);
        float r = 6.0f * u, a = glm::two_pi<float>() * 3.0f * u;
        return {site.position - n * depth + (e1 * std::cos(a) + e2 * std::sin(a)) * r, n, true,
                false};
    }
    // Out of the hole along its axis, then over to rest beside it, leaning away so the hole stays
    // in view. A hand lifts the burr out: a jump straight to the rest pose would cross the wall
    // within one tick and spike the extrapolated force.
    const glm::vec3 bottom = site.position - n * depth + e1 * 6.0f; // where the spiral ends
    const glm::vec3 above = site.position + e1 * 6.0f + n * 4.0f;
    const glm::vec3 rest = site.position + e1 * 16.0f + n * 4.0f;
    const glm::vec3 leaning = glm::normalize(n + e1 * 0.7f);
    if (t < 4.3) {
        const float u = float((t - 4.0) / 0.3);
        return {glm::mix(bottom, above, u), n, false, false};
    }
    if (t < 4.6) {
        const float u = float((t - 4.3) / 0.3);
        return {glm::mix(above, rest, u), glm::normalize(glm::mix(n, leaning, u)), false, false};
    }
    return {rest, leaning, false, t > 4.9};
}

DeviceState WindowDevice::read(double) {
    std::lock_guard lock(m_mutex);
    return m_state;
}

void WindowDevice::set(const DeviceState& s, const Tool& t, double frameTimeS) {
    std::lock_guard lock(m_mutex);
    m_state = s;
    m_tool = t;
    m_velocity = s.valid ? m_estimate.update(s.pose.position, frameTimeS) : glm::vec3(0.0f);
}

WindowDevice::Tool WindowDevice::tool() const {
    std::lock_guard lock(m_mutex);
    return m_tool;
}

glm::vec3 WindowDevice::velocity() const {
    std::lock_guard lock(m_mutex);
    return m_velocity;
}

} // namespace trephine::ui

#include "ui/mouse_tool.h"

#include "libsim/drill.h"

#include <algorithm>
#include <array>
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

std::optional<glm::vec3> rayOnPlane(const Camera& camera, int px, int py, glm::vec3 point,
                                    glm::vec3 normal) {
    const glm::dmat4 inv = glm::inverse(viewProjection(camera));
    const glm::dvec2 ndc(2.0 * (px + 0.5) / camera.width - 1.0,
                         2.0 * (py + 0.5) / camera.height - 1.0);
    const glm::dvec4 a = inv * glm::dvec4(ndc, -1.0, 1.0), b = inv * glm::dvec4(ndc, 1.0, 1.0);
    const glm::dvec3 p0 = glm::dvec3(a) / a.w, dir = glm::dvec3(b) / b.w - p0;
    const double denom = glm::dot(dir, glm::dvec3(normal));
    if (std::abs(denom) < 1e-9)
        return std::nullopt;
    const double t = glm::dot(glm::dvec3(point) - p0, glm::dvec3(normal)) / denom;
    if (!(t > 0.0))
        return std::nullopt;
    return glm::vec3(p0 + dir * t);
}

ToolPose toolPoseAt(glm::vec3 surface, const Camera& camera, const ToolShape& shape, float pushMm) {
    const glm::vec3 axis = glm::normalize(camera.eye - surface);
    const float out = shape.sphere() ? shape.diameterMm * 0.5f : 0.0f;
    ToolPose pose;
    pose.position = surface + axis * (out - pushMm);
    pose.orientation = glm::rotation(glm::vec3(0, 0, 1), axis);
    return pose;
}

std::optional<glm::vec3> surfaceNormal(const Dbi& dbi, const Camera& camera, int px, int py,
                                       int radiusPx) {
    const int r = std::max(1, radiusPx);
    const auto l = pickSurface(dbi, camera, px - r, py), rt = pickSurface(dbi, camera, px + r, py);
    const auto d = pickSurface(dbi, camera, px, py - r), u = pickSurface(dbi, camera, px, py + r);
    const auto c = pickSurface(dbi, camera, px, py);
    if (!l || !rt || !d || !u || !c)
        return std::nullopt;
    glm::vec3 n = glm::cross(*rt - *l, *u - *d);
    if (!(glm::dot(n, n) > 1e-12f))
        return std::nullopt;
    n = glm::normalize(n);
    return glm::dot(n, camera.eye - *c) < 0.0f ? -n : n;
}

ToolPose toolPoseAlong(glm::vec3 surface, glm::vec3 axis, const ToolShape& shape, float pushMm) {
    const float out = shape.sphere() ? shape.diameterMm * 0.5f : 0.0f;
    return ToolPose::fromAxis(surface + axis * (out - pushMm), axis);
}

float maxFeedMmPerS(ToolKind kind, float speed, glm::vec3 spacing) {
    const float voxel = std::min({spacing.x, spacing.y, spacing.z});
    const float s = std::isfinite(speed) ? std::clamp(speed, 0.0f, 1.0f) : 0.0f;
    return voxel * float(erosionRate(kind)) * s / 255.0f;
}

void Feed::press(glm::vec3 surface, glm::vec3 axis, float startMm) {
    m_held = true;
    m_surface = surface;
    m_axis = glm::normalize(axis);
    m_depthMm = startMm;
}

float Feed::advance(float dt, glm::vec3 force, float maxMmPerS) {
    if (!m_held || !(dt > 0.0f))
        return 0.0f;
    // The bone pushes the tool back out along its shaft (+axis); sideways force does not resist
    // the feed.
    const float resist = std::max(0.0f, glm::dot(force, m_axis));
    const float push = std::max(m_config.pushForceN, 1e-3f);
    const float rate = std::isfinite(resist) ? std::max(0.0f, maxMmPerS) *
                                                   std::clamp(1.0f - resist / push, 0.0f, 1.0f)
                                             : 0.0f;
    m_depthMm = std::min(m_depthMm + rate * dt, m_config.maxDepthMm);
    return rate;
}

void Feed::slideTo(glm::vec3 surface) {
    if (m_held) // onto the plane through the first contact, across the axis
        m_surface = surface - m_axis * glm::dot(surface - m_surface, m_axis);
}

HoleFloor floorOfColor(uint8_t r, uint8_t g, uint8_t b) {
    if (r < 24 && b < 24) // unlit, or no colour (the volume design reads back depth only)
        return HoleFloor::Unknown;
    if (b > r) // the sinus, venous blue-purple: the only label bluer than red
        return HoleFloor::Sinus;
    const float ratio = float(g) / float(r);
    return ratio > 0.85f   ? HoleFloor::Cortical
           : ratio > 0.55f ? HoleFloor::Diploe
           : ratio > 0.3f  ? HoleFloor::Dura
                           : HoleFloor::Artery; // arterial red: green a fifth of red
}

const char* holeFloorName(HoleFloor f) {
    switch (f) {
    case HoleFloor::Cortical:
        return "cortical bone";
    case HoleFloor::Diploe:
        return "diploe";
    case HoleFloor::Dura:
        return "dura";
    case HoleFloor::Sinus:
        return "the sagittal sinus";
    case HoleFloor::Artery:
        return "the meningeal artery";
    default:
        return "unknown";
    }
}

std::optional<HoleReading> readHole(const Dbi& dbi, const Camera& camera, glm::ivec2 bottomPx,
                                    glm::vec3 axis, float ringMm) {
    const auto bottom = pickSurface(dbi, camera, bottomPx.x, bottomPx.y);
    if (!bottom)
        return std::nullopt;
    const glm::vec3 n = glm::normalize(axis);
    const glm::vec3 e1 = glm::normalize(
        glm::cross(n, std::abs(n.z) < 0.9f ? glm::vec3(0, 0, 1) : glm::vec3(1, 0, 0)));
    const glm::vec3 e2 = glm::cross(n, e1);
    const glm::dmat4 vp = viewProjection(camera);
    std::vector<float> heights;
    constexpr int kRing = 16;
    for (int i = 0; i < kRing; ++i) {
        const float a = glm::two_pi<float>() * float(i) / kRing;
        const glm::vec3 p = *bottom + (e1 * std::cos(a) + e2 * std::sin(a)) * ringMm;
        const WindowPoint w = projectToWindow(vp, camera, glm::dvec3(p));
        if (w.w <= 0)
            continue;
        if (const auto s = pickSurface(dbi, camera, int(w.window.x), int(w.window.y)))
            heights.push_back(glm::dot(*s - *bottom, n));
    }
    if (heights.size() < kRing / 2) // mostly off the bone: no surface to measure from
        return std::nullopt;
    std::nth_element(heights.begin(), heights.begin() + heights.size() / 2, heights.end());
    HoleReading r;
    r.depthMm = std::max(0.0f, heights[heights.size() / 2]);
    const uint8_t* c = dbi.color(bottomPx.x, bottomPx.y);
    r.floor = floorOfColor(c[0], c[1], c[2]);
    return r;
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

net::ToolState WindowDevice::toolAt(const ToolPose& pose) const {
    const Tool t = tool();
    net::ToolState ts;
    ts.toolKind = uint8_t(t.kind);
    ts.diameterMm = t.diameterMm;
    ts.position = pose.position;
    ts.orientation = pose.orientation;
    ts.speed = t.drilling ? t.speed : 0.0f;
    ts.drilling = t.drilling;
    return ts;
}

glm::vec3 WindowDevice::velocity() const {
    std::lock_guard lock(m_mutex);
    return m_velocity;
}

} // namespace trephine::ui

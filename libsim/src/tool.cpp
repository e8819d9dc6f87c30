#include "libsim/tool.h"

#include "libsim/error.h"
#include "libsim/tool_catalogue.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fmt/format.h>
#include <glm/geometric.hpp>
#include <glm/gtx/quaternion.hpp>

namespace trephine {

namespace {

std::string formatMm(float v) {
    return fmt::format("{:g}", double(v));
}

// Distance from p to the segment [a, b] in the (rho, z) half-plane.
float segmentDistance(glm::vec2 p, glm::vec2 a, glm::vec2 b) {
    glm::vec2 ab = b - a, ap = p - a;
    float t = std::clamp(glm::dot(ap, ab) / glm::dot(ab, ab), 0.0f, 1.0f);
    return glm::length(ap - t * ab);
}

} // namespace

ToolShape ToolShape::of(ToolKind kind, float diameterMm) {
    if (uint8_t(kind) >= kToolKindCount)
        throw Error("unknown tool kind " + std::to_string(int(kind)));
    const ToolType& type = toolType(kind);
    ToolShape s;
    s.kind = kind;
    s.diameterMm = diameterMm;
    if (type.cutter == Cutter::TippedCylinder) {
        s.tipLengthMm = s.diameterMm * type.tipLengthPerDiameter;
        s.cutLengthMm = type.cutLengthMm;
    }
    s.validate();
    return s;
}

ToolShape ToolShape::perforator(float diameterMm) {
    return of(ToolKind::Perforator, diameterMm);
}

ToolShape ToolShape::perforator() {
    return of(ToolKind::Perforator, toolType(ToolKind::Perforator).defaultDiameterMm);
}

bool ToolShape::sphere() const {
    return toolType(kind).cutter == Cutter::Sphere;
}

void ToolShape::validate() const {
    if (uint8_t(kind) >= kToolKindCount)
        throw Error("unknown tool kind " + std::to_string(int(kind)));
    const ToolType& type = toolType(kind);
    // Written as !(in range) so that NaN is refused too.
    if (!(diameterMm >= type.minDiameterMm && diameterMm <= type.maxDiameterMm))
        throw Error(fmt::format("{} diameter {} mm is out of range: the {} is {} to {} mm",
                                type.name, formatMm(diameterMm), type.name,
                                formatMm(type.minDiameterMm), formatMm(type.maxDiameterMm)));
    if (type.cutter == Cutter::TippedCylinder &&
        (!(tipLengthMm >= 0.0f && tipLengthMm <= diameterMm) ||
         !(cutLengthMm > 0.0f && cutLengthMm <= 50.0f)))
        throw Error(fmt::format("{} tip length {} mm / cutting length {} mm is out of range",
                                type.name, formatMm(tipLengthMm), formatMm(cutLengthMm)));
}

float ToolShape::signedDistance(glm::vec3 local) const {
    if (sphere())
        return glm::length(local) - 0.5f * diameterMm;
    // A tipped cylinder is a solid of revolution whose half cross-section in (rho, z) is the convex
    // quadrilateral apex (0,0), shoulder (R,T), rim (R,H), axis top (0,H); its exact distance is
    // the 2D distance to that polygon's three outer edges.
    const float r = 0.5f * diameterMm, t = tipLengthMm, h = tipLengthMm + cutLengthMm;
    glm::vec2 p(std::sqrt(local.x * local.x + local.y * local.y), local.z);
    glm::vec2 apex(0.0f, 0.0f), shoulder(r, t), rim(r, h), top(0.0f, h);
    float d = std::min({segmentDistance(p, apex, shoulder), segmentDistance(p, shoulder, rim),
                        segmentDistance(p, rim, top)});
    bool inside = p.y <= h && p.x <= r && p.x * t <= p.y * r && p.y >= 0.0f;
    return inside ? -d : d;
}

float ToolShape::boundingRadius() const {
    if (sphere())
        return 0.5f * diameterMm;
    float r = 0.5f * diameterMm, h = tipLengthMm + cutLengthMm;
    return std::sqrt(r * r + h * h);
}

std::string ToolShape::describe() const {
    return std::string(toolType(kind).name) + " " + formatMm(diameterMm) + " mm";
}

ToolPose ToolPose::fromAxis(glm::vec3 position, glm::vec3 shaftAxis) {
    ToolPose pose;
    pose.position = position;
    float len = glm::length(shaftAxis);
    if (len > 0.0f)
        pose.orientation = glm::rotation(glm::vec3(0, 0, 1), shaftAxis / len);
    return pose;
}

} // namespace trephine

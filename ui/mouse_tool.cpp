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

} // namespace trephine::ui

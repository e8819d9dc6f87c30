#include "libsim/hole.h"

#include "libsim/drill.h"

#include <glm/geometric.hpp>
#include <glm/gtx/quaternion.hpp>

#include <algorithm>
#include <cassert>
#include <cmath>

namespace trephine {

HoleResult drillHoleAlong(Volume& volume, glm::vec3 surface, glm::vec3 direction, float depthMm,
                          float diameterMm) {
    Driller driller(ToolShape::burr(diameterMm));
    const float radius = 0.5f * diameterMm;
    const glm::vec3 dir = glm::normalize(direction);
    ToolPose pose;
    pose.orientation = glm::rotation(glm::vec3(0, 0, 1), -dir); // shaft back along the ray
    const glm::vec3 s = volume.spacing();
    const float step = 0.25f * std::min({s.x, s.y, s.z});
    HoleResult out;
    const float end = depthMm - radius;
    // Counted steps (u from the count, not accumulated, which stops moving once the step falls
    // under half u's ulp), the last at `end`.
    const int64_t steps = std::max<int64_t>(1, int64_t(std::ceil((end + radius) / step)));
    for (int64_t k = 0;; ++k) {
        const float u = k >= steps ? end : std::min(-radius + float(k) * step, end);
        pose.position = surface + dir * u;
        for (int i = 0; i < 1000; ++i) { // at most 20 s of drilling at one place
            const DrillResult r = driller.drill(volume, pose, 1.0f, 0.02f);
            out.changed.merge(r.changed);
            if (r.duraContact)
                out.touchedDura = true;
            if (r.voxelsChanged == 0 || r.duraContact)
                break;
        }
        if (out.touchedDura || u >= end)
            break;
    }
    return out;
}

std::vector<int64_t> removedByMaterial(const Volume& before, const Volume& after) {
    assert(before.dims() == after.dims() && "removedByMaterial: two volumes of one size");
    std::vector<int64_t> removed(kMaterialCount, 0);
    const uint8_t* mb = before.materialData();
    const uint8_t* ma = after.materialData();
    for (size_t i = 0; i < before.voxelCount(); ++i)
        if (mb[i] != ma[i] && ma[i] == uint8_t(Material::Air) && mb[i] < kMaterialCount)
            removed[mb[i]]++;
    return removed;
}

} // namespace trephine

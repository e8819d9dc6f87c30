#include "libsim/dirty_rect.h"

#include "libsim/volume.h"

#include <algorithm>
#include <cmath>

namespace trephine {

BoxMm dirtyBoxMm(const Volume& volume, const Box3i& changed, float stencilVoxels) {
    // Voxel v's faces sit at v and v + 1 in face coordinates; object space is
    // (face - dims / 2) * spacing (see Volume::voxelCenter).
    glm::dvec3 half = glm::dvec3(volume.dims()) * 0.5;
    glm::dvec3 s(volume.spacing());
    double g = stencilVoxels;
    return {(glm::dvec3(changed.lo) - g - half) * s, (glm::dvec3(changed.hi) + g - half) * s};
}

PixelRect dirtyScreenRect(const Camera& camera, const glm::dmat4& viewProj, const BoxMm& box) {
    const PixelRect window{0, 0, camera.width, camera.height};
    double x0 = INFINITY, y0 = INFINITY, x1 = -INFINITY, y1 = -INFINITY;
    for (int i = 0; i < 8; ++i) {
        glm::dvec3 p((i & 1) ? box.hi.x : box.lo.x, (i & 2) ? box.hi.y : box.lo.y,
                     (i & 4) ? box.hi.z : box.lo.z);
        WindowPoint wp = projectToWindow(viewProj, camera, p);
        // On or behind the eye plane the perspective divide flips or explodes: the box may cover
        // any part of the window.
        if (!(wp.w > 1e-6))
            return window;
        x0 = std::min(x0, wp.window.x), x1 = std::max(x1, wp.window.x);
        y0 = std::min(y0, wp.window.y), y1 = std::max(y1, wp.window.y);
    }
    // Pixel x is touched when its centre x + 0.5 lies in [x0, x1]; floor/ceil keep half a pixel
    // more on each side. Clamp in double before converting: far-off boxes project far away.
    auto clampD = [](double v, double lo, double hi) { return std::min(std::max(v, lo), hi); };
    int px0 = int(clampD(std::floor(x0), 0.0, camera.width));
    int px1 = int(clampD(std::ceil(x1), 0.0, camera.width));
    int py0 = int(clampD(std::floor(y0), 0.0, camera.height));
    int py1 = int(clampD(std::ceil(y1), 0.0, camera.height));
    return intersect(PixelRect{px0, py0, px1 - px0, py1 - py0}, window);
}

PixelRect dirtyScreenRect(const Camera& camera, const Volume& volume, const Box3i& changed,
                          float stencilVoxels) {
    if (changed.empty())
        return {};
    return dirtyScreenRect(camera, viewProjection(camera),
                           dirtyBoxMm(volume, changed, stencilVoxels));
}

} // namespace trephine

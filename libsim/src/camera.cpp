#include "libsim/camera.h"

#include "libsim/error.h"
#include "libsim/skull.h"
#include "libsim/volume.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fmt/format.h>
#include <glm/geometric.hpp>
#include <glm/gtc/matrix_transform.hpp>
#include <glm/trigonometric.hpp>

namespace trephine {

glm::mat4 viewMatrix(const Camera& camera) {
    return glm::lookAt(camera.eye, camera.target, camera.up);
}

glm::mat4 projectionMatrix(const Camera& camera) {
    return glm::perspective(glm::radians(camera.fovYDeg), camera.aspect(), camera.nearMm,
                            camera.farMm);
}

glm::dmat4 viewProjection(const Camera& camera) {
    return glm::dmat4(projectionMatrix(camera)) * glm::dmat4(viewMatrix(camera));
}

WindowPoint projectToWindow(const glm::dmat4& viewProj, const Camera& camera, glm::dvec3 point) {
    glm::dvec4 clip = viewProj * glm::dvec4(point, 1.0);
    glm::dvec3 ndc = glm::dvec3(clip) / clip.w;
    return {{(ndc.x * 0.5 + 0.5) * camera.width, (ndc.y * 0.5 + 0.5) * camera.height,
             ndc.z * 0.5 + 0.5},
            clip.w};
}

float windowDepth(const glm::dmat4& viewProj, glm::dvec3 point) {
    // Only the third and fourth rows of P * V matter for depth.
    double z = viewProj[0][2] * point.x + viewProj[1][2] * point.y + viewProj[2][2] * point.z +
               viewProj[3][2];
    double w = viewProj[0][3] * point.x + viewProj[1][3] * point.y + viewProj[2][3] * point.z +
               viewProj[3][3];
    double d = (z / w) * 0.5 + 0.5;
    return float(std::clamp(d, 0.0, 1.0));
}

double eyeZFromWindowDepth(const Camera& camera, double depth) {
    // glm::perspective: ndc_z = (-(f + n) z_e - 2 f n) / (-z_e) / (f - n) ... solved for z_e.
    double n = camera.nearMm, f = camera.farMm;
    double ndcZ = depth * 2.0 - 1.0;
    return -2.0 * f * n / ((f + n) - ndcZ * (f - n));
}

void fitNearFar(Camera& camera, glm::vec3 centre, float radius) {
    float distance = glm::length(camera.eye - centre);
    camera.nearMm = std::max(10.0f, distance - 1.5f * radius);
    camera.farMm = std::max(camera.nearMm + 1.0f, distance + 1.5f * radius);
}

float paperSpacingMm(int voxels, float projectedPx, float distanceMm, float fovYDeg, int windowPx) {
    // A face at distance z from the eye of half-width s/2 projects to (s/2) / z * focalPx pixels
    // either side of the centre, with focalPx = (windowPx / 2) / tan(fov / 2). The front face is at
    // z = distance - s/2. Solving (s/2) / (distance - s/2) = k with k = projectedPx / 2 / focalPx:
    // s/2 = k distance / (1 + k).
    double focalPx = (windowPx * 0.5) / std::tan(glm::radians(double(fovYDeg)) * 0.5);
    double k = projectedPx * 0.5 / focalPx;
    double side = 2.0 * k * distanceMm / (1.0 + k);
    return float(side / voxels);
}

std::vector<std::string> cameraPresetNames() {
    return {"paper", "working", "top", "front", "left", "back", "right", "bottom"};
}

namespace {

float boundingRadius(const Volume& volume) {
    return 0.5f * glm::length(volume.extentMm());
}

Camera overview(glm::vec3 direction, glm::vec3 up, glm::ivec2 size, const Volume& volume) {
    Camera c;
    c.fovYDeg = 45.0f;
    float radius = boundingRadius(volume);
    // The bounding sphere fits the smaller of the two fields of view with a little room.
    float halfFov = glm::radians(c.fovYDeg) * 0.5f;
    float aspect = float(size.x) / float(size.y);
    float halfFovMin = aspect < 1.0f ? std::atan(std::tan(halfFov) * aspect) : halfFov;
    float distance = radius / std::sin(halfFovMin) * 1.05f;
    c.eye = direction * distance;
    c.target = glm::vec3(0.0f);
    c.up = up;
    c.width = size.x;
    c.height = size.y;
    fitNearFar(c, glm::vec3(0.0f), radius);
    return c;
}

} // namespace

Camera cameraLookingAt(glm::vec3 site, glm::vec3 normal, float distanceMm, float fovYDeg,
                       glm::ivec2 size, const Volume& volume) {
    return cameraLookingAt(site, normal, distanceMm, fovYDeg, size, boundingRadius(volume));
}

Camera cameraLookingAt(glm::vec3 site, glm::vec3 normal, float distanceMm, float fovYDeg,
                       glm::ivec2 size, float boundingRadiusMm) {
    Camera c;
    glm::vec3 n = glm::normalize(normal);
    c.eye = site + n * distanceMm;
    c.target = site;
    glm::vec3 up = std::abs(n.z) > 0.9f ? glm::vec3(0, 1, 0) : glm::vec3(0, 0, 1);
    c.up = glm::normalize(up - n * glm::dot(up, n));
    c.fovYDeg = fovYDeg;
    c.width = size.x;
    c.height = size.y;
    fitNearFar(c, glm::vec3(0.0f), boundingRadiusMm);
    return c;
}

Camera orbitCamera(const Camera& base, float yawDeg, float pitchDeg, float distanceMm,
                   glm::ivec2 size, const Volume& volume) {
    return orbitCamera(base, yawDeg, pitchDeg, distanceMm, size, boundingRadius(volume));
}

Camera orbitCamera(const Camera& base, float yawDeg, float pitchDeg, float distanceMm,
                   glm::ivec2 size, float boundingRadiusMm) {
    const glm::vec3 dir = glm::normalize(base.eye - base.target);
    const glm::vec3 right = glm::normalize(glm::cross(base.up, dir));
    const glm::vec3 up = glm::cross(dir, right);
    const glm::mat4 yaw = glm::rotate(glm::mat4(1.0f), glm::radians(yawDeg), up);
    const glm::vec3 yawedRight = glm::vec3(yaw * glm::vec4(right, 0.0f));
    const glm::mat3 turn =
        glm::mat3(glm::rotate(glm::mat4(1.0f), glm::radians(pitchDeg), yawedRight) * yaw);
    Camera c = base;
    c.eye = base.target + glm::normalize(turn * dir) * distanceMm;
    c.up = glm::normalize(turn * up);
    c.width = size.x;
    c.height = size.y;
    fitNearFar(c, glm::vec3(0.0f), boundingRadiusMm);
    return c;
}

Camera cameraPreset(std::string_view name, const Volume& volume, glm::ivec2 size) {
    if (size.x <= 0 || size.y <= 0)
        throw Error("camera: window size must be positive");
    if (name == "paper") {
        Camera c;
        c.eye = glm::vec3(0.0f, 0.0f, kPaperDistanceMm);
        c.target = glm::vec3(0.0f);
        c.up = glm::vec3(0.0f, 1.0f, 0.0f);
        c.fovYDeg = kPaperFovYDeg;
        c.width = size.x;
        c.height = size.y;
        fitNearFar(c, glm::vec3(0.0f), boundingRadius(volume));
        return c;
    }
    if (name == "working") {
        SurfaceSite site = defaultBurrSite(volume);
        return cameraLookingAt(site.position, site.normal, 275.0f, 20.0f, size, volume);
    }
    if (name == "top")
        return overview({0, 0, 1}, {0, 1, 0}, size, volume);
    if (name == "bottom")
        return overview({0, 0, -1}, {0, 1, 0}, size, volume);
    if (name == "front")
        return overview({0, 1, 0}, {0, 0, 1}, size, volume);
    if (name == "back")
        return overview({0, -1, 0}, {0, 0, 1}, size, volume);
    if (name == "left")
        return overview({1, 0, 0}, {0, 0, 1}, size, volume);
    if (name == "right")
        return overview({-1, 0, 0}, {0, 0, 1}, size, volume);
    std::string names;
    for (const std::string& n : cameraPresetNames())
        names += (names.empty() ? "" : ", ") + n;
    throw Error("camera: unknown preset '" + std::string(name) + "' (choose one of " + names + ")");
}

std::string describe(const Camera& c) {
    return fmt::format("eye ({:.1f}, {:.1f}, {:.1f}) target ({:.1f}, {:.1f}, {:.1f}) up ({:.2f}, "
                       "{:.2f}, {:.2f}) fov {:g} near {:.1f} far {:.1f} {}x{}",
                       c.eye.x, c.eye.y, c.eye.z, c.target.x, c.target.y, c.target.z, c.up.x,
                       c.up.y, c.up.z, double(c.fovYDeg), c.nearMm, c.farMm, c.width, c.height);
}

} // namespace trephine

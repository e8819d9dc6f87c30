// Camera: the matrices a client uses, the depth mapping, the presets and the paper's spacing.
#include "libsim/camera.h"

#include "libsim/error.h"
#include "libsim/skull.h"
#include "libsim/volume.h"

#include <algorithm>
#include <cmath>
#include <glm/geometric.hpp>
#include <glm/gtc/matrix_transform.hpp>
#include <gtest/gtest.h>
#include <type_traits>

namespace trephine {
namespace {

// Serialisable later as plain bytes: no pointers, no virtuals.
static_assert(std::is_trivially_copyable_v<Camera> && std::is_standard_layout_v<Camera>);

Camera testCamera() {
    Camera c;
    c.eye = {40.0f, -250.0f, 90.0f};
    c.target = {0.0f, 0.0f, 5.0f};
    c.up = {0.0f, 0.0f, 1.0f};
    c.fovYDeg = 50.0f;
    c.nearMm = 100.0f;
    c.farMm = 500.0f;
    c.width = 320;
    c.height = 200;
    return c;
}

TEST(Camera, MatricesAreTheOnesAClientBuildsWithGlm) {
    Camera c = testCamera();
    EXPECT_EQ(viewMatrix(c), glm::lookAt(c.eye, c.target, c.up));
    EXPECT_EQ(projectionMatrix(c),
              glm::perspective(glm::radians(c.fovYDeg), 320.0f / 200.0f, c.nearMm, c.farMm));
    EXPECT_EQ(viewProjection(c), glm::dmat4(projectionMatrix(c)) * glm::dmat4(viewMatrix(c)));
}

TEST(Camera, TargetProjectsToTheWindowCentre) {
    Camera c = testCamera();
    WindowPoint p = projectToWindow(viewProjection(c), c, glm::dvec3(c.target));
    EXPECT_NEAR(p.window.x, 160.0, 1e-4); // float matrices
    EXPECT_NEAR(p.window.y, 100.0, 1e-4);
    EXPECT_GT(p.w, 0.0);
    EXPECT_GT(p.window.z, 0.0);
    EXPECT_LT(p.window.z, 1.0);
}

TEST(Camera, WindowDepthIsNdcZHalfPlusHalfAndInvertsToEyeZ) {
    Camera c = testCamera();
    glm::dmat4 vp = viewProjection(c);
    glm::dvec3 eye(c.eye);
    glm::dvec3 forward = glm::normalize(glm::dvec3(c.target) - eye);
    // On the near and far planes (along the axis) depth is 0 and 1.
    EXPECT_NEAR(windowDepth(vp, eye + forward * double(c.nearMm)), 0.0, 1e-6);
    EXPECT_NEAR(windowDepth(vp, eye + forward * double(c.farMm)), 1.0, 1e-6);
    for (double d : {120.0, 200.0, 263.7, 499.0}) {
        glm::dvec3 p = eye + forward * d;
        glm::dvec4 clip = vp * glm::dvec4(p, 1.0);
        EXPECT_EQ(windowDepth(vp, p), float(clip.z / clip.w * 0.5 + 0.5));
        // Back to eye z: -distance along the axis, to float precision of the stored depth.
        EXPECT_NEAR(eyeZFromWindowDepth(c, windowDepth(vp, p)), -d, d * d * 2e-9);
    }
}

TEST(Camera, PaperSpacingPutsTheFrontFaceOn300Pixels) {
    float s = paperSpacingMm();
    EXPECT_NEAR(s, 1.3274f, 1e-3f);
    // A 128^3 cube of that spacing, centred, seen by the paper camera from 330.2 mm.
    Volume v({128, 128, 128}, glm::vec3(s));
    Camera c = cameraPreset("paper", v, {500, 500});
    EXPECT_NEAR(glm::length(c.eye - c.target), kPaperDistanceMm, 1e-3f);
    EXPECT_EQ(c.fovYDeg, 60.0f);
    glm::dmat4 vp = viewProjection(c);
    double h = 64.0 * s;
    double minX = 1e9, maxX = -1e9, minY = 1e9, maxY = -1e9;
    for (int i = 0; i < 8; ++i) {
        glm::dvec3 corner((i & 1) ? h : -h, (i & 2) ? h : -h, (i & 4) ? h : -h);
        WindowPoint p = projectToWindow(vp, c, corner);
        minX = std::min(minX, p.window.x), maxX = std::max(maxX, p.window.x);
        minY = std::min(minY, p.window.y), maxY = std::max(maxY, p.window.y);
    }
    // The silhouette (all eight corners) is the front face: 300 x 300 pixels, centred.
    EXPECT_NEAR(maxX - minX, 300.0, 0.01);
    EXPECT_NEAR(maxY - minY, 300.0, 0.01);
    EXPECT_NEAR(minX, 100.0, 0.01);
    // The whole cube lies between near and far.
    EXPECT_LT(c.nearMm, kPaperDistanceMm - h * std::sqrt(3.0));
    EXPECT_GT(c.farMm, kPaperDistanceMm + h * std::sqrt(3.0));
}

TEST(Camera, EveryPresetSeesTheWholeVolumeBetweenNearAndFar) {
    Volume skull = makeSkull(48);
    glm::vec3 h = skull.extentMm() * 0.5f;
    for (const std::string& name : cameraPresetNames()) {
        SCOPED_TRACE(name);
        Camera c = cameraPreset(name, skull, {400, 300});
        EXPECT_EQ(c.width, 400);
        EXPECT_EQ(c.height, 300);
        EXPECT_GE(c.nearMm, 10.0f);
        glm::dmat4 vp = viewProjection(c);
        for (int i = 0; i < 8; ++i) {
            glm::dvec3 corner((i & 1) ? h.x : -h.x, (i & 2) ? h.y : -h.y, (i & 4) ? h.z : -h.z);
            WindowPoint p = projectToWindow(vp, c, corner);
            EXPECT_GT(p.w, double(c.nearMm)); // in front of the near plane
            EXPECT_GT(p.window.z, 0.0);
            EXPECT_LT(p.window.z, 1.0);
        }
        // The volume centre (paper, overviews) or the burr site (working) is on screen.
        WindowPoint centre = projectToWindow(vp, c, glm::dvec3(c.target));
        EXPECT_NEAR(centre.window.x, 200.0, 1e-4);
        EXPECT_NEAR(centre.window.y, 150.0, 1e-4);
    }
}

TEST(Camera, WorkingPresetLooksAtTheBurrSiteAlongItsNormal) {
    Volume skull = makeSkull(48);
    SurfaceSite site = defaultBurrSite(skull);
    Camera c = cameraPreset("working", skull, {500, 500});
    EXPECT_NEAR(glm::distance(c.target, site.position), 0.0f, 1e-4f);
    glm::vec3 toEye = glm::normalize(c.eye - c.target);
    EXPECT_GT(glm::dot(toEye, glm::normalize(site.normal)), 0.9999f);
    float distance = glm::distance(c.eye, c.target);
    EXPECT_GE(distance, 250.0f);
    EXPECT_LE(distance, 300.0f);
    EXPECT_NEAR(glm::dot(c.up, toEye), 0.0f, 1e-5f);
}

TEST(Camera, UnknownPresetIsAUserError) {
    Volume v({8, 8, 8}, glm::vec3(1.0f));
    try {
        cameraPreset("sideways", v, {100, 100});
        FAIL() << "expected Error";
    } catch (const Error& e) {
        std::string msg = e.what();
        EXPECT_NE(msg.find("sideways"), std::string::npos);
        EXPECT_NE(msg.find("paper"), std::string::npos);
        EXPECT_EQ(msg.find('\n'), std::string::npos);
    }
}

TEST(Camera, FitNearFarKeepsNearAtLeastTenMillimetres) {
    Camera c;
    c.eye = {0, 0, 50};
    fitNearFar(c, glm::vec3(0.0f), 100.0f);
    EXPECT_EQ(c.nearMm, 10.0f);
    EXPECT_EQ(c.farMm, 200.0f);
    c.eye = {0, 0, 400};
    fitNearFar(c, glm::vec3(0.0f), 100.0f);
    EXPECT_EQ(c.nearMm, 250.0f);
    EXPECT_EQ(c.farMm, 550.0f);
}

// The View panel's orbit and tilt: the up vector turns with the view, so one slider step never
// rolls the picture (cameraLookingAt's up, picked afresh from the direction, jumped 124 degrees
// between tilts -11.5 and -12 of the working view), and a tilt at orbit 90 still tilts (it turned
// about the unturned right vector, which the orbit had made the view direction).
TEST(Camera, OrbitingNeverRollsThePictureAndTiltWorksAtEveryOrbit) {
    const Volume skull = makeSkull(64);
    for (const char* preset : {"working", "top", "front"}) {
        SCOPED_TRACE(preset);
        const Camera base = cameraPreset(preset, skull, {256, 256});
        const float distance = glm::length(base.eye - base.target);
        const Camera same = orbitCamera(base, 0.0f, 0.0f, distance, {256, 256}, skull);
        EXPECT_LT(glm::length(same.eye - base.eye), 1e-3f);
        EXPECT_LT(glm::length(same.up - base.up), 1e-5f);
        for (float yaw : {-135.0f, -90.0f, -30.0f, 0.0f, 45.0f, 90.0f, 180.0f}) {
            Camera last = orbitCamera(base, yaw, -60.0f, distance, {256, 256}, skull);
            for (float pitch = -59.5f; pitch <= 60.0f; pitch += 0.5f) {
                const Camera c = orbitCamera(base, yaw, pitch, distance, {256, 256}, skull);
                const float turned =
                    glm::degrees(std::acos(std::clamp(glm::dot(c.up, last.up), -1.0f, 1.0f)));
                ASSERT_LT(turned, 1.0f) << "yaw " << yaw << " pitch " << pitch;
                EXPECT_NEAR(glm::dot(c.up, glm::normalize(c.eye - c.target)), 0.0f, 1e-4f);
                EXPECT_NEAR(glm::length(c.eye - c.target), distance, 1e-2f);
                last = c;
            }
            const glm::vec3 flat = glm::normalize(
                orbitCamera(base, yaw, 0.0f, distance, {256, 256}, skull).eye - base.target);
            const glm::vec3 tilted = glm::normalize(
                orbitCamera(base, yaw, 30.0f, distance, {256, 256}, skull).eye - base.target);
            EXPECT_NEAR(glm::degrees(std::acos(glm::dot(flat, tilted))), 30.0f, 0.1f)
                << "yaw " << yaw << ": a 30 degree tilt turns the view by 30 degrees";
        }
    }
}

} // namespace
} // namespace trephine

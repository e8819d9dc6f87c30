// The view a DBI is rendered for: a plain struct of floats that server and client turn into the
// same GL matrices (glm::lookAt, glm::perspective), plus the named presets (`paper`, `working`,
// ...).
#pragma once

#include <glm/mat4x4.hpp>
#include <glm/vec2.hpp>
#include <glm/vec3.hpp>
#include <string>
#include <string_view>
#include <vector>

namespace trephine {

class Volume;

// Object space of the volume is world space: the volume is centred on the origin (see
// Volume::voxelCenter). Right-handed, GL conventions; window pixel (x, y) has its centre at
// (x + 0.5, y + 0.5) with row 0 at the bottom, as glReadPixels returns it.
struct Camera {
    glm::vec3 eye{0.0f, 0.0f, 300.0f}; // mm
    glm::vec3 target{0.0f};            // mm
    glm::vec3 up{0.0f, 1.0f, 0.0f};
    float fovYDeg = 45.0f; // vertical field of view, degrees
    float nearMm = 10.0f;
    float farMm = 1000.0f;
    int width = 500; // window size in pixels
    int height = 500;

    float aspect() const { return float(width) / float(height); }
    bool operator==(const Camera&) const = default;
};

// glm::lookAt(eye, target, up): what a client passes to GL as its view matrix.
glm::mat4 viewMatrix(const Camera& camera);
// glm::perspective(radians(fovYDeg), width / height, nearMm, farMm).
glm::mat4 projectionMatrix(const Camera& camera);
// projection * view, widened to double after building the float matrices, so that the server
// computes depth from exactly the matrices a client holds, without extra rounding of its own.
glm::dmat4 viewProjection(const Camera& camera);

// Window coordinates (x, y in pixels, row 0 at the bottom; z = window depth in [0, 1]) of an
// object-space point, and w (the clip-space w, > 0 in front of the eye).
struct WindowPoint {
    glm::dvec3 window;
    double w;
};
WindowPoint projectToWindow(const glm::dmat4& viewProj, const Camera& camera, glm::dvec3 point);

// The GL window depth of an object-space point: ndc_z * 0.5 + 0.5 with clip = P * V * (p, 1)
// computed in double. Exactly what a float depth buffer holds for a fragment there.
float windowDepth(const glm::dmat4& viewProj, glm::dvec3 point);
// Inverse of the depth mapping: the eye-space z (negative in front of the camera) of a window
// depth under this camera's near/far.
double eyeZFromWindowDepth(const Camera& camera, double depth);

// Sets nearMm and farMm from the distance of the eye to a bounding sphere (centre, radius):
// near = distance - 1.5 radius (at least 10 mm), far = distance + 1.5 radius. Keeps depth
// precision where the bone is while nothing of the volume is ever clipped.
void fitNearFar(Camera& camera, glm::vec3 centre, float radius);

// --- Presets -------------------------------------------------------------------------------

// The paper's experiment (section 4.1): eye 330.2 mm (13 in) from the volume centre on +z looking
// down -z, up +y, 60 degrees vertical field of view; the window size is the caller's (the paper
// used 500x500).
inline constexpr float kPaperDistanceMm = 330.2f;
inline constexpr float kPaperFovYDeg = 60.0f;
inline constexpr int kPaperWindowPx = 500;
inline constexpr float kPaperProjectedPx = 300.0f;

// The voxel spacing (mm) at which a cube of `voxels` voxels a side, viewed face-on along an axis
// from `distanceMm` (eye to cube centre) with a vertical field of view fovYDeg in a window
// windowPx tall, has a front face `projectedPx` pixels wide. Face-on and on-axis the front face
// is the silhouette (the rest of the cube projects inside it). For the paper: 128 voxels ->
// about 1.3274 mm (a 169.9 mm cube).
float paperSpacingMm(int voxels = 128, float projectedPx = kPaperProjectedPx,
                     float distanceMm = kPaperDistanceMm, float fovYDeg = kPaperFovYDeg,
                     int windowPx = kPaperWindowPx);

// Names accepted by cameraPreset, in the order `--help` lists them.
std::vector<std::string> cameraPresetNames();

// A named view of `volume` in a window of `size` pixels:
//   paper   the paper's camera (see above); the caller sets the spacing (paperSpacingMm)
//   working looking at the skull's default burr site from 275 mm along its outward normal
//   top     from +z (vertex), anterior (+y) up on screen
//   front   from +y (anterior), +z up
//   left    from +x (the patient's left), +z up
//   back / right / bottom: the opposite views
// Overview presets frame the volume's bounding sphere in a 45 degree field of view. Near/far
// come from fitNearFar. An unknown name throws trephine::Error naming the choices.
Camera cameraPreset(std::string_view name, const Volume& volume, glm::ivec2 size);

// A view of `site` (an object-space point) from `distanceMm` along `normal`; up is +z made
// perpendicular to the normal (+y when the normal is nearly vertical).
Camera cameraLookingAt(glm::vec3 site, glm::vec3 normal, float distanceMm, float fovYDeg,
                       glm::ivec2 size, const Volume& volume);
// As above for a volume whose bounding sphere (at the origin) has this radius: a DBI client knows
// the volume's extent from the scene, never its voxels.
Camera cameraLookingAt(glm::vec3 site, glm::vec3 normal, float distanceMm, float fovYDeg,
                       glm::ivec2 size, float boundingRadiusMm);

// `base` orbited about its target: turned `yawDeg` about its up vector, then tilted `pitchDeg`
// about its right vector as the yaw left it, at `distanceMm` from the target; the up vector turns
// with the view, so the picture never rolls (cameraLookingAt's up, chosen afresh from the view
// direction, would roll it). Near/far from fitNearFar over the volume.
Camera orbitCamera(const Camera& base, float yawDeg, float pitchDeg, float distanceMm,
                   glm::ivec2 size, const Volume& volume);
Camera orbitCamera(const Camera& base, float yawDeg, float pitchDeg, float distanceMm,
                   glm::ivec2 size, float boundingRadiusMm);

// One line for logs: "eye (x, y, z) target (...) up (...) fov 60 near 110.1 far 550.3 500x500".
std::string describe(const Camera& camera);

} // namespace trephine

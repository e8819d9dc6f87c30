// The window's drilling devices without GL (tested headless): the mouse (the point of bone under
// the cursor, from the DBI's depth and the camera it was rendered with, and the tool pose placed
// there) and the scripted burr hole.
#pragma once

#include "libsim/camera.h"
#include "libsim/dbi.h"
#include "libsim/device.h"
#include "libsim/force_model.h"
#include "libsim/skull.h"
#include "libsim/tool.h"
#include "net/protocol.h"

#include <mutex>
#include <optional>

namespace trephine::ui {

// The object-space point shown at DBI pixel (px, py) (row 0 at the bottom), or nothing where the
// pixel shows no bone (depth 1) or lies outside the image.
std::optional<glm::vec3> pickSurface(const Dbi& dbi, const Camera& camera, int px, int py);

// Where the view ray through DBI pixel (px, py) meets the plane through `point` across `normal`;
// nothing when it runs parallel to the plane or meets it behind the eye.
std::optional<glm::vec3> rayOnPlane(const Camera& camera, int px, int py, glm::vec3 point,
                                    glm::vec3 normal);

// The tool touching `surface` from the eye's side, its shaft toward the eye, pushed `pushMm`
// further along the line of sight (negative: lifted off). A burr's centre sits one radius out so
// that the sphere touches the point; the perforator's apex sits on it.
ToolPose toolPoseAt(glm::vec3 surface, const Camera& camera, const ToolShape& shape, float pushMm);

// The outward surface normal at DBI pixel (px, py): the cross product of the bone points
// `radiusPx` pixels to either side (unprojected from their depths), turned toward the eye; nothing
// where any of them shows no bone. A radius of a few millimetres' worth of pixels smooths the
// voxels' steps and a small pit.
std::optional<glm::vec3> surfaceNormal(const Dbi& dbi, const Camera& camera, int px, int py,
                                       int radiusPx);

// The tool on `surface` with its shaft along `axis` (unit, out of the bone), pushed `pushMm`
// into it along the axis (negative: lifted off); as toolPoseAt but along the handpiece's own axis.
ToolPose toolPoseAlong(glm::vec3 surface, glm::vec3 axis, const ToolShape& shape, float pushMm);

// [SECTION] the handpiece's feed
// Holding the button advances the cutter along its axis as a hand pushing with a steady force
// would: no faster than the cutter's front can erode the densest bone it meets (one voxel layer
// of density 255 per 255 / (erosion rate x speed) seconds, libsim/drill.h's rates), and slowed
// in proportion as the bone pushes back (the force along the axis, from the server's haptic
// answer, against the hand's push): it stalls where the bone does not erode (dura) or pushes
// back as hard as the hand. Releasing ends the stroke; the next one starts at the surface again.
struct FeedConfig {
    float pushForceN = 2.5f;  // the hand's push along the shaft
    float liftMm = 8.0f;      // the cutter's clearance above the bone with the button up
    float maxDepthMm = 15.0f; // past any skull's bone: a stroke over a hole in air stops there
};
// The fastest feed (mm/s) the erosion allows a `kind` cutter at `speed` in voxels of `spacing`.
float maxFeedMmPerS(ToolKind kind, float speed, glm::vec3 spacing);

class Feed {
public:
    explicit Feed(FeedConfig config = {}) : m_config(config) {}
    // The button went down with the cutter touching `surface`, its shaft along `axis` (unit, out
    // of the bone), starting `startMm` deep (the push setting).
    void press(glm::vec3 surface, glm::vec3 axis, float startMm);
    void release() { m_held = false; }
    bool held() const { return m_held; }
    // One frame of `dt` seconds with `force` (N, on the tool) the bone's answer at the current
    // pose and `maxMmPerS` from maxFeedMmPerS: the depth advances by the feed rate times dt.
    // Returns the feed rate (mm/s) used.
    float advance(float dt, glm::vec3 force, float maxMmPerS);
    // The pointer moved while the button is held: the stroke follows it sideways, at its depth,
    // in the plane through the first contact across the axis (a groove, as a drill guided aside).
    void slideTo(glm::vec3 surface);
    glm::vec3 surface() const { return m_surface; }
    glm::vec3 axis() const { return m_axis; }
    float depthMm() const { return m_depthMm; } // cutter pushed below the first contact (mm)
    const FeedConfig& config() const { return m_config; }

private:
    FeedConfig m_config;
    bool m_held = false;
    glm::vec3 m_surface{0.0f}, m_axis{0, 0, 1};
    float m_depthMm = 0.0f;
};

// What the view says about the hole under the tool, from the DBI only (the client holds no
// voxels): its depth below the bone around it (the median height of a ring of picked points
// `ringMm` from the axis, over the point picked at `bottomPx`) and the layer its floor shows, by
// the colour's hue (cortical ivory, diploe marrow red, dura red: libsim's materialColor).
enum class HoleFloor : uint8_t { Unknown, Cortical, Diploe, Dura, Sinus, Artery };
struct HoleReading {
    float depthMm = 0.0f;
    HoleFloor floor = HoleFloor::Unknown;
};
std::optional<HoleReading> readHole(const Dbi& dbi, const Camera& camera, glm::ivec2 bottomPx,
                                    glm::vec3 axis, float ringMm);
// The layer a shaded DBI colour shows: green over red stays with the material under diffuse
// shading (ivory 0.96, marrow 0.69, dura 0.41).
HoleFloor floorOfColor(uint8_t r, uint8_t g, uint8_t b);
const char* holeFloorName(HoleFloor f);

// The window's tool as the haptic loop's device: the UI thread sets the pose each frame, the
// 1 kHz loop reads it, extrapolates the force there and sends tool states at 100 Hz.
class WindowDevice : public Device {
public:
    struct Tool {
        ToolKind kind = ToolKind::Burr;
        float diameterMm = 5.0f;
        float speed = 0.0f;
        bool drilling = false;
    };
    std::string name() const override { return "window mouse"; }
    DeviceState read(double) override;
    void setForce(glm::vec3) override {} // a mouse pushes nothing back
    // The frame's pose and tool, set at `frameTimeS` (seconds, any clock that only moves forward).
    void set(const DeviceState& s, const Tool& t, double frameTimeS);
    Tool tool() const;
    // The tool state the haptic loop sends for the frame's tool held at `pose`.
    net::ToolState toolAt(const ToolPose& pose) const;
    // The tool's velocity (mm/s) from the last two frames' poses and their frame times
    // (VelocityEstimate: 0 after a gap or a jump), not from the haptic loop's ticks: the pose
    // changes only once a frame.
    glm::vec3 velocity() const;

private:
    mutable std::mutex m_mutex;
    DeviceState m_state;
    Tool m_tool;
    VelocityEstimate m_estimate;
    glm::vec3 m_velocity{0.0f};
};

} // namespace trephine::ui

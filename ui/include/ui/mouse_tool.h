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

#include <mutex>
#include <optional>

namespace trephine::ui {

// The object-space point shown at DBI pixel (px, py) (row 0 at the bottom), or nothing where the
// pixel shows no bone (depth 1) or lies outside the image.
std::optional<glm::vec3> pickSurface(const Dbi& dbi, const Camera& camera, int px, int py);

// The tool touching `surface` from the eye's side, its shaft toward the eye, pushed `pushMm`
// further along the line of sight (negative: lifted off). A burr's centre sits one radius out so
// that the sphere touches the point; the perforator's apex sits on it.
ToolPose toolPoseAt(glm::vec3 surface, const Camera& camera, const ToolShape& shape, float pushMm);

// The scripted burr hole (`--script burrhole`) at time t (s): plunge at the site, widen in a
// spiral, lift out along the hole's axis and rest the drill to one side. The tool moves
// continuously, as a hand would (at most about 40 mm/s), so forces extrapolated along it are
// ones a hand could meet.
struct ScriptPose {
    glm::vec3 position;
    glm::vec3 axis;
    bool drilling;
    bool done;
};
ScriptPose burrholePose(const SurfaceSite& site, double t);

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

// The trainee's scripts (docs/scripts.md), one trajectory per name in every shell: the built-in
// burr hole the window, the headless trainee and the update study drill (`--script burrhole`),
// the demo's perforator feed, and CSV trajectories. Poses in the volume's frame, time in seconds.
#pragma once

#include "libsim/skull.h"
#include "net/trainee_core.h"

#include <glm/vec3.hpp>

#include <string>
#include <vector>

namespace trephine::net {

// The scripted burr hole at time t (s): a 5 mm burr plunges at the site to 2 mm, widens the hole
// in a spiral, lifts out along its axis and rests to one side, done after kBurrholeSeconds. The
// tool moves continuously, as a hand would (at most about 40 mm/s), so forces extrapolated along
// it are ones a hand could meet.
struct ScriptPose {
    glm::vec3 position;
    glm::vec3 axis;
    bool drilling;
    bool done;
};
ScriptPose burrholePose(const SurfaceSite& site, double t);
inline constexpr double kBurrholeSeconds = 4.9;
inline constexpr float kBurrholeDiameterMm = 5.0f;

// The burr hole as tool states at 100 Hz for `durationS` (its whole length by default; a shorter
// run stops drilling at its end).
std::vector<ScriptSample> burrholeScript(const SurfaceSite& site,
                                         double durationS = kBurrholeSeconds);

// The demo's perforator: 1 mm above the site, fed in along its normal at `feed` mm/s, drilling,
// tool states at 100 Hz, for `seconds`.
std::vector<ScriptSample> feedScript(const SurfaceSite& site, float feed, double seconds);

// A CSV trajectory: time_s,x,y,z,qw,qx,qy,qz,speed,tool with tool `NAME:D` or `NAME` (a tool of
// the catalogue, at its usual size); '#' comments and a header line are skipped. Throws Error
// with the file, the line and what is wrong.
std::vector<ScriptSample> csvScript(const std::string& path);

} // namespace trephine::net

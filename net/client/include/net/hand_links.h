// What HandLinks (net/protocol.h) make a force device feel: a trainee whose instructor holds it
// and guides its hand is pulled by a bounded spring toward that instructor's tool; an instructor
// who feels a participant feels that participant's force. Worked out from a snapshot on any
// thread; the force is the haptic thread's (TraineeForce).
#pragma once

#include "net/client_thread.h"

#include <glm/vec3.hpp>
#include <optional>

namespace trephine::net {

struct HandGuideConfig {
    // A soft spring and its damping: the instructor leads, the trainee can always resist (a
    // relaxed hand of 0.15 kg settles on it in about 0.2 s without overshoot).
    double stiffnessNPerMm = 0.2;
    double dampingNsPerMm = 0.012;
    double maxForceN = 1.5;
    // The pull fades in when a guide starts and out when it ends, over this: taking or handing
    // back the hand never jolts it (DeviceGuard alone would let 1.5 N on in two ticks).
    double rampS = 0.25;
};

// [Trainee] The tool position of the instructor that holds this client and guides its hand, if
// one does and its tool is known.
std::optional<glm::vec3> guideTarget(const ClientSnapshot& s);
// [Instructor] The participant whose forces this client feels (0: its own).
uint16_t feltParticipant(const ClientSnapshot& s);
// The guide's pull at device position p moving at v (mm/s): spring and damper, at most maxForceN.
glm::vec3 guideForce(glm::vec3 target, glm::vec3 p, glm::vec3 v, const HandGuideConfig& c = {});

// The guide's pull tick by tick (haptic thread): guideForce toward the target scaled by a gain that
// ramps up over rampS while there is a target and down to zero after, toward the last one.
class GuideRamp {
public:
    // `target` is the guide's target now (none: no guide); `now` in seconds.
    glm::vec3 force(std::optional<glm::vec3> target, glm::vec3 p, glm::vec3 v, double now,
                    const HandGuideConfig& c);
    bool pulling() const { return m_gain > 0.0; }

private:
    double m_gain = 0.0, m_lastS = 0.0;
    bool m_ticked = false;
    glm::vec3 m_target{0.0f};
};

} // namespace trephine::net

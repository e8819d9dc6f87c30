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
};

// [Trainee] The tool position of the instructor that holds this client and guides its hand, if
// one does and its tool is known.
std::optional<glm::vec3> guideTarget(const ClientSnapshot& s);
// [Instructor] The participant whose forces this client feels (0: its own).
uint16_t feltParticipant(const ClientSnapshot& s);
// The guide's pull at device position p moving at v (mm/s): spring and damper, at most maxForceN.
glm::vec3 guideForce(glm::vec3 target, glm::vec3 p, glm::vec3 v, const HandGuideConfig& c = {});

} // namespace trephine::net

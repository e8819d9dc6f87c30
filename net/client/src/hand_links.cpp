#include "net/hand_links.h"

#include "libsim/haptics.h"

#include <algorithm>

namespace trephine::net {

namespace {

uint16_t selfOf(const ClientSnapshot& s) {
    return s.welcome ? s.welcome->clientId : 0;
}

} // namespace

std::optional<glm::vec3> guideTarget(const ClientSnapshot& s) {
    const uint16_t self = selfOf(s);
    auto me = s.participants.find(self);
    const std::optional<HandLinks> links = s.newest.get<HandLinks>();
    if (!self || me == s.participants.end() || !me->second.takenOverBy || !links)
        return std::nullopt;
    const uint16_t holder = me->second.takenOverBy;
    for (const HandLink& l : links->list)
        if (l.instructor == holder && l.guides) {
            auto tool = s.others.find(holder);
            if (tool != s.others.end())
                return tool->second.position;
        }
    return std::nullopt;
}

uint16_t feltParticipant(const ClientSnapshot& s) {
    const uint16_t self = selfOf(s);
    if (const std::optional<HandLinks> links = s.newest.get<HandLinks>())
        for (const HandLink& l : links->list)
            if (l.instructor == self && self)
                return l.feels;
    return 0;
}

glm::vec3 guideForce(glm::vec3 target, glm::vec3 p, glm::vec3 v, const HandGuideConfig& c) {
    const glm::vec3 f = float(c.stiffnessNPerMm) * (target - p) - float(c.dampingNsPerMm) * v;
    return clampForce(f, float(c.maxForceN));
}

glm::vec3 GuideRamp::force(std::optional<glm::vec3> target, glm::vec3 p, glm::vec3 v, double now,
                           const HandGuideConfig& c) {
    const double dt = m_ticked ? std::max(now - m_lastS, 0.0) : 0.0;
    m_ticked = true;
    m_lastS = now;
    if (target)
        m_target = *target;
    const double step = c.rampS > 0.0 ? dt / c.rampS : 1.0;
    m_gain = std::clamp(m_gain + (target ? step : -step), 0.0, 1.0);
    if (m_gain == 0.0) {
        m_ticked = target.has_value(); // faded out: the next guide ramps from its first tick
        return glm::vec3(0.0f);
    }
    return float(m_gain) * guideForce(m_target, p, v, c);
}

} // namespace trephine::net

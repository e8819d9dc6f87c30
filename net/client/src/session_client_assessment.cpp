// The session client's handlers of the assessment's messages (net/assessment_protocol.h).
#include "net/session_client.h"

namespace trephine::net {

bool SessionClient::onSafetyWarning(std::span<const uint8_t> data) {
    SafetyWarning w;
    if (!decodeMessage(data, w))
        return false;
    ++m_warningsReceived;
    m_warnings[w.clientId] = w;
    m_warningLog.push_back(w);
    if (m_warningLog.size() > kMaxWarningLog)
        m_warningLog.pop_front();
    return true;
}

bool SessionClient::onAssessmentSnapshot(std::span<const uint8_t> data) {
    AssessmentSnapshot a;
    if (!decodeMessage(data, a))
        return false;
    ++m_snapshots;
    m_assessment = std::move(a);
    return true;
}

} // namespace trephine::net

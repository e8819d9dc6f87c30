// The session client's side of a replay's timeline (net/replay_protocol.h).
#include "net/session_client.h"

namespace trephine::net {

bool SessionClient::onReplayState(std::span<const uint8_t> data, uint64_t nowUs) {
    ReplayState s;
    if (!decodeMessage(data, s))
        return false;
    m_replay = s;
    m_replayReceivedUs = nowUs;
    return true;
}

uint64_t SessionClient::replayPosition(uint64_t nowUs) const {
    if (!m_replay)
        return 0;
    return replayPositionAfter(*m_replay,
                               nowUs > m_replayReceivedUs ? nowUs - m_replayReceivedUs : 0);
}

void SessionClient::controlReplay(ReplayControl c) {
    send(c);
}

} // namespace trephine::net

// The session client's side of live role codes (net/session_codes.h).
#include "net/session_client.h"

namespace trephine::net {

bool SessionClient::onCodes(std::span<const uint8_t> data) {
    Codes m;
    if (!decodeMessage(data, m) || m.op != Codes::Op::Current)
        return false; // a request is the server's to receive
    m_codes = std::move(m);
    return true;
}

void SessionClient::newCode(Role role) {
    Codes m;
    m.op = Codes::Op::Issue;
    m.role = role;
    send(m);
}

} // namespace trephine::net

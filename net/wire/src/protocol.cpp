#include "net/protocol.h"

namespace trephine::net {

std::string refuseReasonText(uint32_t disconnectData) {
    uint32_t version = disconnectData >> 8;
    switch (RefuseReason(disconnectData & 0xff)) {
    case RefuseReason::None:
        return "the connection closed";
    case RefuseReason::Version:
        return "the server speaks protocol version " + std::to_string(version) +
               " and this client version " + std::to_string(kProtocolVersion) +
               ": use the same Trephine build on both ends";
    case RefuseReason::Malformed:
        // The server counts what failed to decode or to open: on a sealed connection mostly
        // datagrams damaged or forged on the way, which this client never sent.
        return "the server received malformed or forged datagrams on this connection (a faulty "
               "network or an on-path attacker) and closed it";
    case RefuseReason::ServerFull:
        return "the server is full";
    case RefuseReason::Shutdown:
        return "the server is shutting down";
    case RefuseReason::BadHello:
        return "the server did not understand our hello";
    case RefuseReason::VolumeTooLarge:
        return "the volume is too large to send whole in this volume codec: use --sync dbi, or "
               "a compressing --volume-codec";
    case RefuseReason::WrongCode:
        switch (CodeRefusal(version)) {
        case CodeRefusal::None:
            return "this session needs a code: give the one the server printed (--code)";
        case CodeRefusal::TraineeAsInstructor:
            return "that is the trainee code: the instructor's role needs the instructor code";
        case CodeRefusal::ServerOpen:
            return "the server runs an open session (no codes, nothing encrypted): not joining it "
                   "with --code";
        default:
            return "wrong session code";
        }
    case RefuseReason::Removed:
        return "the instructor removed you from the session";
    case RefuseReason::TooManyAttempts:
        return "too many wrong codes from this address: try again in " + std::to_string(version) +
               " s";
    case RefuseReason::Busy:
        return "the server is busy: every place for joining is taken (retrying)";
    case RefuseReason::Idle:
        return "the server dropped us for saying nothing for too long";
    case RefuseReason::Retry:
        return "the server asked this client to connect again with a cookie, and did not take it "
               "(does the address change between tries?)";
    case RefuseReason::ViewsFull:
        return "the server serves as many view pixels as it can: try a smaller window";
    }
    return "the server closed the connection (reason " + std::to_string(disconnectData) + ")";
}

} // namespace trephine::net

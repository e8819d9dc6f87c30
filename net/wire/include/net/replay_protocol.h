// The replay timeline's two messages (`trephine replay FILE --serve`): ReplayState (where the
// replay is) and ReplayControl (play, pause, seek, speed). docs/protocol.md and
// docs/recording.md describe them; the server keeps the timeline in net/replay_feed.h.
#pragma once

#include "net/protocol.h"

#include <cstdint>

namespace trephine::net {

// The speeds a replay plays at (times the recorded pace).
inline constexpr float kMinReplaySpeed = 1e-3f;
inline constexpr float kMaxReplaySpeed = 1e6f;

// Server -> every participant of a replay (Channel::Control, reliable): where its timeline is,
// at the welcome, on every change (play, pause, seek, speed, the end reached) and every
// kReplayStateIntervalUs while it plays. A window moves its cursor on from `positionUs` at
// `speed` while `playing`, from when the message arrived, up to `durationUs`.
struct ReplayState {
    static constexpr MessageType kType = MessageType::ReplayState;
    uint64_t positionUs = 0; // session time (µs from the log's first record)
    uint64_t durationUs = 0; // session time of the log's last record
    float speed = 1.0f;
    bool playing = false;
    // Seeks done so far: a window's own seek shows until the state that answers it arrives.
    uint32_t seeks = 0;

    template <typename S>
    bool serialize(S& s) {
        return s.integer(positionUs) && s.integer(durationUs) && positionUs <= durationUs &&
               serializeFinite(s, speed) && speed >= kMinReplaySpeed && speed <= kMaxReplaySpeed &&
               s.boolean(playing) && s.integer(seeks);
    }
};
inline constexpr uint64_t kReplayStateIntervalUs = 500'000;

// Where a replay is `elapsedUs` after `s` was true: on at its speed while it plays, up to the end.
inline uint64_t replayPositionAfter(const ReplayState& s, uint64_t elapsedUs) {
    if (!s.playing)
        return s.positionUs;
    const double pos = double(s.positionUs) + double(elapsedUs) * double(s.speed);
    return pos >= double(s.durationUs) ? s.durationUs : uint64_t(pos);
}

// Client -> server (Channel::Control, reliable): drives the replay every window watches. Any
// participant may (a replay serves no one's own session); a server that is not serving a log
// ignores it (counted in ServerCounters::replayControlsRefused). Seek positions past the end go
// to the end; a seek backwards rebuilds the session from its start (docs/recording.md).
struct ReplayControl {
    static constexpr MessageType kType = MessageType::ReplayControl;
    enum class Op : uint8_t { Play = 0, Pause = 1, Seek = 2, Speed = 3 };
    Op op = Op::Play;
    uint64_t positionUs = 0; // Seek
    float speed = 1.0f;      // Speed

    template <typename S>
    bool serialize(S& s) {
        return s.ranged(op, Op::Play, Op::Speed) && s.integer(positionUs) &&
               serializeFinite(s, speed) && speed >= kMinReplaySpeed && speed <= kMaxReplaySpeed;
    }
};

} // namespace trephine::net

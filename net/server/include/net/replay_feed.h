// Plays a session log into a live SessionServer (`trephine replay FILE --serve`): ReplayPlayer
// hands out the log's records as their recorded time comes round on a timeline that windows
// play, pause, seek and speed up (net/replay_protocol.h), and the server applies them through
// the session policy (SessionPolicy::replayed) and the simulation step, so windows connected to
// it watch the session being drilled, with the recorded participants' tools and names.
// docs/recording.md.
#pragma once

#include "net/replay_protocol.h"
#include "net/server_config.h"
#include "net/session_log.h"

#include <cstdint>
#include <span>
#include <vector>

namespace trephine::net {

// Each record's time in the session (µs from its first record): a Resume starts a new server
// clock, which continues from where the stretch before it ended.
std::vector<uint64_t> sessionTimesUs(std::span<const LogRecord> records);

// A replay's timeline: the log's records handed out as their session time comes round at the
// chosen speed, with play, pause, seek and speed changes, all at wall times passed in. A seek
// behind what was already given asks for a rewind: the session is rebuilt from its start
// volume and the records up to the new position are given again (checkpoints would only make
// that faster; the simulation reaches the same voxels either way, drilling being deterministic).
class ReplayPlayer {
public:
    // Paused at the start unless `playing`. `speed` within [kMinReplaySpeed, kMaxReplaySpeed];
    // throws Error otherwise.
    ReplayPlayer(std::vector<LogRecord> records, double speed, bool playing, uint64_t nowUs);

    struct Due {
        bool rewind = false; // rebuild from the start first, then apply `records`
        std::vector<LogRecord> records;
    };
    // The records due at `nowUs` (the log's order), not given before. At the end it pauses.
    Due advance(uint64_t nowUs);
    // Play from the current position (from the start once at the end).
    void play(uint64_t nowUs);
    void pause(uint64_t nowUs);
    // To session time `positionUs` (past the end: the end); the next advance() gives what that
    // needs.
    void seek(uint64_t positionUs, uint64_t nowUs);
    void setSpeed(double speed, uint64_t nowUs); // throws Error outside the range
    // Applies a window's control; false (nothing changed) for a speed out of range.
    bool control(const ReplayControl& c, uint64_t nowUs);

    uint64_t positionUs(uint64_t nowUs) const;
    uint64_t durationUs() const { return m_times.empty() ? 0 : m_times.back(); }
    bool playing() const { return m_playing; }
    double speed() const { return m_speed; }
    // Every record given (the position is at the end).
    bool done() const { return m_next == m_records.size(); }
    size_t given() const { return m_next; }
    size_t size() const { return m_records.size(); }
    uint32_t seeks() const { return m_seeks; }
    ReplayState state(uint64_t nowUs) const;

private:
    void anchor(uint64_t nowUs); // the position now becomes the anchor

    std::vector<LogRecord> m_records;
    std::vector<uint64_t> m_times;
    double m_speed;
    bool m_playing;
    uint64_t m_anchorPosUs = 0, m_anchorNowUs = 0; // the position at a wall time
    size_t m_next = 0;
    bool m_rewind = false;
    uint32_t m_seeks = 0;
};

// The header of a session on `volume` served with `config` (logHeaderOf, with the server's
// volume name, drilling and assessment settings, scene and starting marks).
LogHeader makeLogHeader(const Volume& volume, const ServerConfig& config,
                        const std::string& volumeSpec, bool embed, uint64_t startUnixUs);
// The server's settings for serving a log's session: its scene, starting marks, volume name
// and drilling settings, no recorder. Throws Error when the scene in the header does not read.
ServerConfig replayServerConfig(const LogHeader& header, ServerConfig base);

} // namespace trephine::net

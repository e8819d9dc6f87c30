// Plays a session log into a live SessionServer (`trephine replay FILE --serve`): ReplayFeed
// hands out the log's records as their recorded time comes round at a chosen speed, and
// SessionServer::replay() applies them through the session policy (SessionPolicy::replayed) and
// the simulation step, so windows connected to the server watch the session being drilled, with
// the recorded participants' tools and names. docs/recording.md.
#pragma once

#include "net/server_config.h"
#include "net/session_log.h"

#include <cstdint>
#include <span>
#include <vector>

namespace trephine::net {

// Each record's time in the session (µs from its first record): a Resume starts a new server
// clock, which continues from where the stretch before it ended.
std::vector<uint64_t> sessionTimesUs(std::span<const LogRecord> records);

class ReplayFeed {
public:
    // `speed` > 0: 2 plays the session in half its recorded time. Throws Error otherwise.
    ReplayFeed(std::vector<LogRecord> records, double speed);
    // The records whose time has come `elapsedUs` of wall time after the start, not given
    // before, in the log's order (time passed in).
    std::vector<LogRecord> due(uint64_t elapsedUs);
    bool done() const { return m_next == m_records.size(); }
    // Wall time the whole log takes at this speed.
    uint64_t durationUs() const;
    size_t given() const { return m_next; }
    size_t size() const { return m_records.size(); }

private:
    std::vector<LogRecord> m_records;
    std::vector<uint64_t> m_times;
    double m_speed;
    size_t m_next = 0;
};

// The server's settings for serving a log's session: its scene, starting marks, volume name
// and drilling settings, no recorder. Throws Error when the scene in the header does not read.
ServerConfig replayServerConfig(const LogHeader& header, ServerConfig base);

} // namespace trephine::net

// The session log (`trephine server --record FILE`): an append-only file of everything that
// changed the session, in the order the server applied it, so a session can be replayed bit for
// bit (net/session_replay.h), resumed after a crash, or exported. Each record is framed with its
// length and a CRC-32; a damaged stretch is skipped (the records after it are kept), a torn tail
// dropped, each said in one line.
// docs/recording.md is the format's reference (versioned: kLogVersion).
#pragma once

#include "libsim/box.h"
#include "libsim/distance_field.h"
#include "libsim/volume.h"
#include "net/events.h"
#include "net/executor.h"
#include "net/protocol.h"

#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <span>
#include <string>
#include <vector>

namespace trephine::net {

inline constexpr uint8_t kLogMagic[8] = {'T', 'R', 'E', 'P', 'H', 'L', 'O', 'G'};
// The format (kLogVersion) and each record (LogRecord: a time and an event) are net/events.h's.
// The file's fixed start (magic, version) and each record's frame (length, CRC-32).
inline constexpr size_t kLogPreambleBytes = 12, kLogFrameBytes = 8;

// How the session began: the volume (its spec and a content hash, or the voxels themselves when
// the spec cannot regenerate them), the scene every client got, the starting marks, and the
// simulation settings drilling depends on, and the assessment's zones.
struct LogHeader {
    uint64_t startUnixUs = 0; // wall clock when the server started
    std::string volumeSpec;   // as the server was given it
    std::string volumeName;   // the welcome's label
    glm::ivec3 dims{0};
    glm::vec3 spacing{1.0f};
    uint32_t densityCrc = 0, materialCrc = 0; // CRC-32 of the starting voxels as given
    std::vector<uint8_t> embedded; // zstd of every density then material byte; empty: from spec
    float maxStepS = 0.05f, maxSweepMm = 10.0f;
    std::vector<uint8_t> scene; // the Scene message, as clients got it
    std::vector<AnnotationInfo> marks;
    // The assessment's zones (v2; a v1 log reads the server's defaults, which it was made with
    // unless --caution-mm/--danger-mm were given).
    float cautionMm = 3.0f, dangerMm = 1.0f, clampMm = DistanceField::kDefaultClampMm;

    // `version`: the log's format (a reader passes the file's; a writer writes kLogVersion).
    template <typename S>
    bool serialize(S& s, uint32_t version = kLogVersion) {
        uint16_t markCount = uint16_t(std::min<size_t>(marks.size(), kMaxAnnotations));
        if (!(s.integer(startUnixUs) && s.string(volumeSpec, 4096) &&
              s.string(volumeName, kMaxVolumeNameBytes) &&
              s.ranged(dims.x, 1, int(kMaxVolumeDim)) && s.ranged(dims.y, 1, int(kMaxVolumeDim)) &&
              s.ranged(dims.z, 1, int(kMaxVolumeDim)) && serializeSpacing(s, spacing) &&
              s.integer(densityCrc) && s.integer(materialCrc) &&
              s.blob(embedded, kMaxLogRecordBytes) && serializeFinite(s, maxStepS) &&
              serializeFinite(s, maxSweepMm) && s.blob(scene, kMaxLogRecordBytes) &&
              s.ranged(markCount, uint16_t(0), kMaxAnnotations)))
            return false;
        if constexpr (S::kReading)
            marks.assign(markCount, AnnotationInfo{});
        for (AnnotationInfo& m : marks)
            if (!m.serialize(s))
                return false;
        return version < 2 || (serializeFinite(s, cautionMm) && serializeFinite(s, dangerMm) &&
                               serializeFinite(s, clampMm));
    }
};

// [SECTION] the starting volume

// The header's volume part for a session on `volume`: with `embed`, the voxels travel in the log
// (a file or a resumed session, which no spec regenerates); else only their hash does. The
// server's settings are added by makeLogHeader (net/replay_feed.h).
LogHeader logHeaderOf(const Volume& volume, const std::string& volumeSpec, bool embed,
                      uint64_t startUnixUs);
// The starting volume: the embedded voxels, or `open(volumeSpec)` checked against the hash.
// Throws Error (one line) when they are not the recorded ones.
Volume logStartVolume(const LogHeader& header,
                      const std::function<Volume(const std::string&)>& open);

// [SECTION] writing

// Appends framed records with one write(2) a call, so a record is in the file (the page cache)
// before the caller goes on to send what it caused. Its owner calls tick() with the time: every
// `syncIntervalMs` it posts an fdatasync of what was written to the executor, and in between,
// every kWritebackIntervalMs, a writeback of the full pages without a journal commit (an
// fdatasync's commit makes concurrent appends wait for milliseconds; docs/recording.md), so the
// simulation and network threads never wait for the disk.
class SessionRecorder {
public:
    static constexpr int kDefaultSyncIntervalMs = 1000;
    static constexpr int kWritebackIntervalMs = 100;

    // A new log at `path` (refused when something is there) starting with `header`, synced. The
    // syncs run on `syncer` (none: a WorkerExecutor "trephine-sync" of its own).
    static std::unique_ptr<SessionRecorder> create(const std::string& path, LogHeader header,
                                                   int syncIntervalMs = kDefaultSyncIntervalMs,
                                                   std::unique_ptr<Executor> syncer = {});
    // An existing log to append to, which must be `intactBytes` long: all intact (a damaged one
    // is made so by repairSessionLog first; nothing here cuts a file). Its records are written in
    // the file's format `version`, so an older log stays one format.
    static std::unique_ptr<SessionRecorder> append(const std::string& path, uint64_t intactBytes,
                                                   uint32_t version = kLogVersion,
                                                   int syncIntervalMs = kDefaultSyncIntervalMs,
                                                   std::unique_ptr<Executor> syncer = {});
    ~SessionRecorder();
    SessionRecorder(const SessionRecorder&) = delete;
    SessionRecorder& operator=(const SessionRecorder&) = delete;

    // [Any thread] Appends the records in one write(2). After a failed write nothing more is
    // written: false, and error() says why (the session goes on unrecorded; said once on stderr).
    bool write(std::span<const LogRecord> records);
    // [The owner's thread] Time passes: posts a sync or a writeback when one is due and
    // something was written since (none while the last one posted still runs). The first call
    // starts the cadence.
    void tick(uint64_t nowUs);
    // fdatasync now, on the caller's thread.
    void sync();
    std::string error() const;
    uint64_t bytes() const;
    uint64_t records() const;
    uint64_t syncs() const;
    uint64_t writebacks() const; // writebacks of full pages done
    const std::string& path() const { return m_path; }

private:
    SessionRecorder(std::string path, int fd, uint64_t bytes, int syncIntervalMs, uint32_t version,
                    std::unique_ptr<Executor> syncer);
    bool writeAll(const uint8_t* data, size_t n);
    void writeBack(uint64_t written);

    std::string m_path;
    int m_fd = -1;
    uint64_t m_syncIntervalUs;
    uint32_t m_version; // the format its records are written in
    mutable std::mutex m_mutex;
    std::vector<uint8_t> m_buffer;
    uint64_t m_bytes = 0, m_records = 0, m_synced = 0, m_syncs = 0, m_writebacks = 0;
    uint64_t m_writtenBack = 0; // the posted tasks' own: full pages handed to writeback
    std::string m_error;
    // tick()'s: when the next sync and writeback are due (0: not started).
    uint64_t m_nextSyncUs = 0, m_nextWritebackUs = 0;
    std::atomic<bool> m_posted{false};  // a posted sync or writeback has not finished
    std::unique_ptr<Executor> m_syncer; // last: its tasks go before the members they use
};

// [SECTION] reading

// A stretch of a log that holds no intact record: from a damaged frame to the next intact one,
// or to the end (a torn or corrupt tail).
struct LogDamage {
    uint64_t offset = 0, bytes = 0;
    size_t recordsBefore = 0; // intact records before it
    size_t records = 0;       // records in it, as their own lengths chain through it (0: unknown)
    std::string why;          // its first frame's problem: "torn: ..." or "corrupt: ..."
    bool tail = false;        // nothing intact after it
};

struct LogContents {
    LogHeader header;
    uint32_t version = 0;
    std::vector<LogRecord> records; // every intact one, in file order
    std::vector<LogDamage> damage;  // in file order; empty: the file is whole
    uint64_t intactBytes = 0;       // the file's bytes less its damage
    uint64_t fileBytes = 0;
    // The damage said, a line a stretch ('\n' between): where, how many bytes, why, and how
    // many records were kept after it. Empty: the file is whole.
    std::string stopped;
};

// Reads a log. At a damaged frame it scans on byte by byte to the next offset where a frame
// checks (its length fits, its payload reads as a record, its CRC matches) and goes on from
// there. Throws Error (one line naming `name`) when not even the header is intact.
LogContents parseSessionLog(std::span<const uint8_t> bytes, const std::string& name);
// The same for the file at `path`; refused (Error) when it is no regular file: a FIFO would block.
LogContents readSessionLog(const std::string& path);

// Makes the damaged log at `path`, as `log` read it, fit to append to: first keeps it aside whole,
// byte for byte, as PATH.damaged-N (the first N with no file there), then replaces `path` with its
// intact frames only (log.intactBytes). Returns the name kept aside; "" when `log` had no damage
// (nothing done). Throws Error (one line) when the file changed since or cannot be written.
std::string repairSessionLog(const std::string& path, const LogContents& log);

} // namespace trephine::net

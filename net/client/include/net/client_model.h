// The client model (Tracy's shape: the model is a library, the GUI draws it): the histories and
// figures a trainee's panels plot and its report states, folded from ClientThread's snapshots,
// applied updates and the haptic loop's ticks. The window and the headless trainee both feed one,
// so both report the same figures from the same code. Times are seconds on the caller's clock.
#pragma once

#include "libsim/dbi.h"
#include "libsim/haptics.h"
#include "libsim/stats.h"
#include "net/client_thread.h"
#include "net/protocol.h"

#include <nlohmann/json.hpp>

#include <array>
#include <cstdint>
#include <deque>
#include <glm/vec3.hpp>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace trephine::net {

// Image updates over the last seconds: latency, bytes, compression, rate.
struct NetworkHistory {
    struct Update {
        double t = 0;
        double latencyUs = -1;
        uint32_t bytes = 0, rawBytes = 0;
        bool full = false;
    };
    double windowS = 10.0;
    std::deque<Update> updates;
    // Per-second series for the plots (oldest first), kept to `seriesLength` points.
    size_t seriesLength = 60;
    std::vector<float> imageKbitPerS, toolKbitPerS, hapticKbitPerS, updatesPerS, rttMs;

    void addUpdate(const Update& u);
    // Appends one point per series from the 1 s rates (bytes/s) and the latest round trip (us).
    void addSecond(double imageBytesPerS, double toolBytesPerS, double hapticBytesPerS,
                   double updatesInS, double rttUs);
    // Drops updates older than windowS before `now`.
    void expire(double now);
    double updateRate(double now) const; // updates per second over the last second
    double compressionRatio() const;     // raw / wire bytes over the window (1 when none)
    // Counts of latencies in `buckets` equal bins over [0, maxUs); larger ones go in the last.
    std::vector<float> latencyHistogram(int buckets, double maxUs) const;
    double latencyPercentile(double p) const; // -1 when none
    // The histogram's caption: p50 and p99 in ms, "-" before any was measured. Named
    // "delivery" (cause on the server -> applied here, before drawing): "update latency" is the
    // Comparison panel's, cause to screen (docs/ui.md).
    std::string latencyCaption(double maxUs) const;
};

// Forces over the last seconds: the server's samples (f at P_N) and the extrapolated force the
// client computes between them.
struct ForceHistory {
    struct Sample {
        double t = 0;
        glm::vec3 f{0.0f};
    };
    double windowS = 5.0;
    std::deque<Sample> server, extrapolated;

    void addServer(double t, glm::vec3 f);
    void addExtrapolated(double t, glm::vec3 f);
    void expire(double now);
    double serverRate() const; // samples per second over the window held
    // One component (0..2 x, y, z; 3 magnitude) of a series, oldest first.
    static std::vector<float> series(const std::deque<Sample>& s, int component);
    // The same over time: n points evenly spaced in [t0, t1], each the newest sample at or before
    // its time (held; before the first sample, the first), so that series at different rates
    // (f at tens a second, F at 1 kHz) share one time axis. Empty when the series is.
    static std::vector<float> resample(const std::deque<Sample>& s, int component, double t0,
                                       double t1, int n);
    // One scale for every plot of this history: the largest |f| and |F| held, rounded up to 1, 2
    // or 5 times a power of ten, at least 0.5 N, so that plots side by side compare.
    float scaleN() const;
};

// [Instructor] one force history per other participant, from the newest relayed model of each
// (ClientSnapshot::relayedModels). A participant with no new model for windowS is dropped, and one
// whose model is no longer listed (it left) at once.
struct ParticipantForces {
    double windowS = 5.0;
    std::map<uint16_t, ForceHistory> byClient;
    std::map<uint16_t, uint32_t> lastSequence; // tool sequence of the last model taken

    // Adds a server sample at `now` for each participant whose model is new (by tool sequence);
    // returns how many were added.
    int update(double now, const std::map<uint16_t, HapticModel>& models);
    void expire(double now);
};

// BB_screen of each update, fading out, and the recent ones as a list.
struct DirtyBoxHistory {
    struct Box {
        double t = 0;
        PixelRect rect;
        uint32_t sequence = 0, bytes = 0;
        double latencyUs = -1;
        bool full = false;
    };
    double fadeS = 1.5;
    size_t keep = 64;
    std::deque<Box> boxes; // newest last

    // A full update first forgets the boxes before it (they belong to the picture it replaces).
    void add(const Box& b);
    // 1 when new, falling linearly to 0 at fadeS.
    float alpha(const Box& b, double now) const;
    // Boxes still visible at `now`.
    std::vector<Box> visible(double now) const;
    // The overlay's boxes: the newest `n` visible rectangles (full updates left out), newest
    // last: drilling adds dozens a second at one place, and all of them would hide the burr.
    std::vector<Box> overlay(double now, size_t n = 8) const;
};

// [Comparison] the figures the study reports, measured live for both designs (DBI and replicated
// volume), kept per design: while one design runs, the other keeps its last measured figures.
// The model records one point a second for the design that is active; the panel only plots.
enum class SyncDesign : uint8_t { Dbi = 0, Volume = 1 };
inline constexpr int kSyncDesignCount = 2;
const char* syncDesignName(SyncDesign d); // "DBI (server renders)", "Volume (local copy)"

// Bytes and latencies are of the second's incremental updates (full ones, sent at a join, a
// switch or a view change, left out); -1: none that second (plotted as 0; the table keeps the
// last second that had some, "-" until one has).
struct ComparisonFigures {
    double updatesPerS = 0;        // image or volume updates applied per second
    double bytesPerUpdate = -1;    // on the wire, mean over the last second
    double rawBytesPerUpdate = -1; // before compression
    double latencyP50Ms = -1;      // cause at the server -> on the client's screen
    double latencyP99Ms = -1;
    double frameMs = 0;  // the client's frame time (display)
    double hapticHz = 0; // the haptic loop's achieved rate
};

struct ComparisonHistory {
    struct Series {
        std::vector<float> updatesPerS, bytesPerUpdate, rawBytesPerUpdate, latencyP50Ms,
            latencyP99Ms, frameMs, hapticHz; // oldest first, at most seriesLength points
        ComparisonFigures last;              // the newest figures recorded (see above)
        double lastT = -1;                   // when they were recorded (-1: never)
        size_t points = 0;                   // points ever recorded
    };
    size_t seriesLength = 120;
    SyncDesign active = SyncDesign::Dbi; // the design of the newest record
    Series designs[kSyncDesignCount];

    // Appends one point to `design`'s series (capped), makes it the active design.
    void record(SyncDesign design, double now, const ComparisonFigures& figures);
    const Series& series(SyncDesign d) const { return designs[int(d)]; }
    bool measured(SyncDesign d) const { return series(d).lastT >= 0; }
    // Seconds since `d` was last recorded (-1: never).
    double ageS(SyncDesign d, double now) const;
    // DBI over volume for a figure both designs have measured (e.g. updatesPerS), 0 otherwise.
    double ratio(double ComparisonFigures::*figure) const;
};

SyncDesign designOf(Sync s);
Sync syncOf(SyncDesign d);

// What the report adds to the model's figures: the shell's own facts.
struct ClientReportExtras {
    nlohmann::ordered_json session =
        nlohmann::ordered_json::object(); // server, codec, view, script, ... as given
    double durationS = 0;
    double toolRateHz = 0, hapticRateHz = 0; // asked for
    HapticLoopStats haptics;
    uint64_t localForceTicks = 0, serverForceTicks = 0;
};

// Every figure a trainee shows, folded from what its client core publishes.
class ClientModel {
public:
    NetworkHistory network;
    ForceHistory forces;
    ParticipantForces participants; // [Instructor] others' forces
    DirtyBoxHistory boxes;
    ComparisonHistory comparison;
    // Incremental updates applied (full ones count in updates only): wire and raw bytes, and
    // latency from the cause at the server to applied here.
    SampleWindow updateBytes{65536}, updateRawBytes{65536}, updateLatencyUs{65536};
    uint64_t updates = 0, fullUpdates = 0;

    // Each frame or poll: the newest snapshot. Takes new force models, relayed ones, and once a
    // second the network series.
    void addSnapshot(const std::shared_ptr<const ClientSnapshot>& snap, double now);
    // An applied image update (the window: one it uploaded).
    void addRect(const AppliedRect& r, double now);
    // An applied voxel box and its BB_screen (empty when not known).
    void addVolumeBox(const AppliedVolumeBox& b, const PixelRect& screen, double now);
    // The haptic loop's recent ticks as the extrapolated force series, the newest at `now` (the
    // loop keeps its own clock).
    void setHapticTicks(const std::vector<HapticSample>& ticks, double now);
    // An incremental update on screen at `drawnUs` (the window: the end of the frame that first
    // drew it; headless: when applied): its latency counts up to then.
    void addDrawn(SyncDesign design, double latencyUs, uint64_t appliedUs, uint64_t drawnUs,
                  uint32_t bytes, uint32_t rawBytes);
    // A frame's time in the design it drew (ms); headless shells have none.
    void addFrame(SyncDesign design, double frameMs);
    // At most once a second: the Comparison point for the design feeding the picture, when
    // `record` (a picture is shown and no switch is under way: the second measures the wait).
    void tickComparison(double now, SyncDesign picture, bool record, uint64_t hapticTicks);

    // The newest snapshot taken while connected (its figures outlive the connection).
    const ClientSnapshot* session() const { return m_session.get(); }
    // The report: the session's counts and figures, the update windows, the haptic loop's, the
    // comparison per design and `extras.session`'s fields (docs/session.md lists them).
    nlohmann::ordered_json report(const ClientReportExtras& extras) const;

private:
    struct LiveSecond {
        std::vector<double> latencyMs;
        double bytes = 0, rawBytes = 0;
        int updates = 0;
    };
    std::shared_ptr<const ClientSnapshot> m_snap, m_session;
    uint64_t m_hapticSeen = 0;
    double m_nextSecond = -1;
    uint64_t m_updatesAtLastSecond = 0;
    std::array<std::vector<double>, kSyncDesignCount> m_frameMs;
    std::array<LiveSecond, kSyncDesignCount> m_live;
    uint64_t m_ticksAtLastSecond = 0;
    double m_lastSecondAt = -1;
    bool m_framed = false; // frames were added: a second without one records no point
};

// {"count", "mean", "min", "p50", "p99", "max"} of a window (-1 for each figure when empty).
nlohmann::ordered_json windowJson(const SampleWindow& w);

} // namespace trephine::net

// The session server's figures as plain data (ServerReport: counters, per-peer and per-mode
// figures, timing windows) and the one place they are turned into JSON (toJson). The server's
// parts record into a ReportBook, a mutex around one ServerReport, so the accessors and the
// report read consistent figures from any thread.
#pragma once

#include "libsim/stats.h"
#include "net/admission.h"
#include "net/assessment_metrics.h"
#include "net/net_stats.h"
#include "net/protocol.h"
#include "net/security_counters.h"

#include <nlohmann/json.hpp>

#include <array>
#include <cstdint>
#include <map>
#include <mutex>
#include <string>

namespace trephine::net {

// What the server sent in one sync mode, and how many connected clients use it now.
struct ModeTotals {
    uint64_t clients = 0;
    uint64_t updates = 0, fullUpdates = 0; // messages sent (image or volume updates)
    uint64_t bytes = 0, rawBytes = 0;      // payload bytes on the wire / before compression
};

// Session-wide counts (SessionServer's accessors of the same names read them).
struct ServerCounters {
    uint64_t clients = 0; // connections now, with or without a hello
    uint64_t malformedKicks = 0;
    uint64_t toolStatesApplied = 0, toolStatesDropped = 0;
    uint64_t renders = 0;
    uint64_t viewsReused = 0; // new views given a kept one (StepConfig::keepViewUs)
    uint64_t pixelsKept = 0; // changed rectangles' pixels erosion could not reach: not re-rendered
    uint64_t rendererFallbacks = 0; // the configured renderer failed: the CPU's renders since
    uint64_t codingsShared = 0; // image updates given another client's coding of the same pixels
    // The simulation's waits for the network to take what it posted (StepConfig::letSend), and
    // of them those that reached SendPasses::kMaxWaitUs.
    uint64_t sendWaits = 0, sendWaitsBounded = 0;
    uint64_t hapticModelsSent = 0, hapticRelaysSent = 0;
    uint64_t refusedFull = 0, helloTimeouts = 0, viewsRefused = 0;
    uint64_t annotationsRefused = 0, takeOversRefused = 0, drillingPaused = 0;
    uint64_t handLinksRefused = 0;
    uint64_t replayControlsRefused = 0; // ReplayControl to a server not serving a log
    int64_t peakInFlightBytes = 0;      // the most one client's updates held by ENet at once
};

// Refusals and budgets that keep the session serving those who belong (docs/session.md,
// "Availability"); the server's report lists them under "availability".
struct AvailabilityCounters {
    AdmissionCounts admission;   // CONNECT datagrams dropped, handshakes reset (net/admission.h)
    uint64_t refusedBusy = 0;    // connections refused: too many waiting to be admitted
    uint64_t idleTimeouts = 0;   // participants sent away for saying nothing (idleTimeoutS)
    uint64_t viewsDeferred = 0;  // view requests held back by the peer's render budget
    uint64_t viewsCoalesced = 0; // of which replaced by a newer one before it was due
    uint64_t viewsOverTotal = 0; // views refused: all views together would pass maxTotalViewPixels
    uint64_t refusedViewTotal = 0; // hellos refused for the same reason (RefuseReason::ViewsFull)
    uint64_t controlCoalesced = 0; // rosters, marks, views replaced by a newer one while queued
    uint64_t controlDropped = 0;   // pongs not sent: the peer's control backlog was over budget
    uint64_t namesRepaired = 0;    // hello names that were not UTF-8 text, or already taken
    uint64_t receivedDropped = 0;  // messages dropped: the peer had FairInbox's most waiting
    int64_t peakControlBytes = 0;  // the most control bytes ENet held for one peer at once
};

// One peer's figures, kept after it leaves.
struct PeerReport {
    std::string name;
    Role role = Role::Trainee;
    bool hello = false;
    uint64_t bytesIn = 0, bytesOut = 0, messagesIn = 0, messagesOut = 0;
    uint64_t malformed = 0, hapticModels = 0, hapticRelays = 0, toolStates = 0, viewsRefused = 0;
    uint64_t viewRequests = 0; // well-formed, refused or not
    uint64_t chargedUs = 0;    // the simulation thread's time spent for it (net/fair_share.h)
    uint64_t netChargedUs = 0; // the network thread's (and its code hashing), FairInbox
    uint64_t connectedUs = 0, disconnectedUs = 0; // disconnectedUs 0: still connected
    bool kicked = false;
    Sync sync = Sync::Dbi;
    uint64_t syncSwitches = 0;

    // Said hello, was not sent away and has not left.
    bool participating() const { return hello && !kicked && disconnectedUs == 0; }
};

// One sync mode's updates: what went out, and the server's stage times.
struct ModeReport {
    ModeTotals sent; // `clients` is counted from the peers (ServerReport::modeTotals)
    SampleWindow erodeUs{65536}, renderUs{65536}, encodeUs{65536};
};

struct ServerReport {
    uint16_t port = 0;
    std::string volume;
    size_t maxClients = 0;
    ServerCounters counters;
    AvailabilityCounters availability;
    std::map<uint16_t, PeerReport> peers; // every peer that ever connected, by id
    std::array<ModeReport, 2> modes;      // by Sync
    SampleWindow forceComputeUs{65536};
    SampleWindow hapticServiceUs{65536}; // tool state received -> its HapticModel ready
    // The assessment (net/assessment.h): its structures and zones, and every participant's
    // metrics by client id (refreshed with each snapshot, final at each leave).
    AssessmentSummary assessment;
    std::map<uint16_t, ParticipantMetrics> participants;
    SecurityCounters security; // net/session_gate.h

    // The totals of `mode` with the participants using it now.
    ModeTotals modeTotals(Sync mode) const;
};

// The report as JSON, in the order docs/session.md lists the fields; `stats` gives the channel
// totals and the malformed count.
nlohmann::ordered_json toJson(const ServerReport& report, const NetStats& stats);
// toJson as text, two spaces an indent. Peer names come from the wire and the volume's name from
// the user: bytes that are not UTF-8 are replaced, never a reason to lose the report.
std::string toJsonText(const ServerReport& report, const NetStats& stats);
// Any report's JSON as text, as toJsonText writes it (`trephine replay --report` too).
std::string jsonText(const nlohmann::ordered_json& j);

// A ServerReport behind a mutex: the network and simulation threads record, anyone reads.
class ReportBook {
public:
    template <typename F>
    void record(F&& f) {
        std::lock_guard lock(m_mutex);
        f(m_report);
    }
    template <typename F>
    auto read(F&& f) const {
        std::lock_guard lock(m_mutex);
        return f(static_cast<const ServerReport&>(m_report));
    }
    void count(uint64_t ServerCounters::*counter, uint64_t n = 1) {
        record([&](ServerReport& r) { r.counters.*counter += n; });
    }
    uint64_t counter(uint64_t ServerCounters::*counter) const {
        return read([&](const ServerReport& r) { return r.counters.*counter; });
    }
    // Records into peer `id`'s figures (made when first named).
    template <typename F>
    void peer(uint16_t id, F&& f) {
        record([&](ServerReport& r) { f(r.peers[id]); });
    }

private:
    mutable std::mutex m_mutex;
    ServerReport m_report;
};

} // namespace trephine::net

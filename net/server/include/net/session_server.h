// The session server: it owns the ENet host and the queues between its parts, and is a pump: each
// pass feeds every connection, message and tick to the session policy (net/session_policy.h) and
// sends what it answers, hands each batch of events to the simulation step (net/sim_step.h),
// which drills, renders and posts to the outbox (net/outbox.h), and sends what the outbox lets
// go. Tests pump it with their own time (pump()); start() runs the network pass and the
// simulation pass on two threads ("trephine-net", "trephine-sim") with the steady clock. Every
// figure goes to one report (net/server_report.h). Each client syncs by DBI (rectangles of its
// view) or by volume (the replicated-volume baseline), chosen in its hello and switched live.
// docs/session.md describes the parts, threads and queues.
#pragma once

#include "libsim/box.h"
#include "libsim/camera.h"
#include "libsim/dbi.h"
#include "libsim/volume.h"
#include "net/enet_host.h"
#include "net/net_stats.h"
#include "net/protocol.h"
#include "net/replay_protocol.h"
#include "net/server_config.h"
#include "net/server_report.h"
#include "net/session_log.h"

#include <atomic>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <thread>
#include <vector>

namespace trephine::net {

class SessionServer {
public:
    // Binds the port at once (throws trephine::Error when it cannot); threads start in start().
    SessionServer(Volume volume, ServerConfig config);
    ~SessionServer();
    SessionServer(const SessionServer&) = delete;
    SessionServer& operator=(const SessionServer&) = delete;

    uint16_t port() const;
    // The runner: starts the named threads "trephine-net" and "trephine-sim", which pump the
    // session with the steady clock (and a worker thread that codes large full images apart).
    void start();
    // One pass of the whole session at `nowUs` on the caller's thread, instead of start(): take
    // every datagram waiting and what the replay has due, apply one batch of what arrived (or
    // one slice of a large view), then send what the outbox lets go and what the policy has due.
    // Time is only what is passed in (it never goes back; the steady clock before the first
    // pump). Does nothing once started or stopped; a pumped server cannot be started.
    void pump(uint64_t nowUs);
    // Stops: peers are disconnected (RefuseReason::Shutdown), every queued tool state is applied,
    // then saveOnExit is written. Idempotent; the threads end first when start() ran.
    void stop();

    // Cuts a box of voxels (volume indices) to air on the simulation thread, exactly like a tool
    // update: density 0 and Material::Air in the box (clipped to the volume), BB_volume = the
    // box, cause time = now (the submit time), then BB_screen updates to every client. Thread-safe.
    void submitBoxCut(const Box3i& box);
    // Writes voxels wholesale (studies restore a cut box with it): density and material bytes of
    // every voxel of `box` (x fastest; box.count() each, box inside the volume, known materials:
    // throws trephine::Error otherwise), then updates like a cut. Volume clients get the box with
    // its material bytes (VolumeUpdate::materials), since materials cannot be derived here.
    void submitVoxels(const Box3i& box, std::vector<uint8_t> density,
                      std::vector<uint8_t> material);
    // Serves a session log's timeline (`trephine replay --serve`, net/replay_feed.h): its records
    // are played into this session as their participants did them (SessionPolicy::replayed) when
    // their time comes round, paused at the start unless `playing`; windows play, pause, seek and
    // change the speed (ReplayControl), and all of them are told where it is (ReplayState). A
    // seek backwards rebuilds from the volume this server was made with, which must be the log's
    // start (logStartVolume). Call before start(), with ServerConfig::replay set.
    void serveLog(std::vector<LogRecord> records, double speed, bool playing);
    // [Thread-safe] A timeline control, as a window sends it (applied on the network thread).
    void controlReplay(const ReplayControl& control);
    // [Thread-safe] The timeline at the network thread's last pass (none: not serving a log).
    std::optional<ReplayState> replayState() const;
    // The paper's DBI way, for comparison: on every change re-render each view whole, then send
    // BB_screen of it (the default renders only BB_screen; the pixels are the same).
    void setFullRenderUpdates(bool on);

    // [Inspection, thread-safe]
    // A fresh full render of the current volume for a view (what a converged client holds).
    Dbi renderView(const ViewSpec& view);
    Volume volumeSnapshot();
    // True when no event waits for the simulation (a paced mode switch included), none is being
    // applied, and the outbox holds no update and no noted change.
    bool idle();
    // The figures of the report (ServerCounters, PeerReport, ModeTotals), read under its lock.
    ServerCounters counters() const;
    size_t clientCount() const { return size_t(counters().clients); }
    // The most bytes of image and volume updates ENet held for one client at once (see
    // ServerConfig::maxInFlightBytes), over the session.
    int64_t peakInFlightBytes() const { return counters().peakInFlightBytes; }
    uint64_t malformedTotal() const;
    uint64_t disconnectedForMalformed() const { return counters().malformedKicks; }
    uint64_t toolStatesApplied() const { return counters().toolStatesApplied; }
    // What renders the views now, and whether the configured renderer failed (the CPU's since).
    std::string rendererName() const;
    uint64_t rendererFallbacks() const { return counters().rendererFallbacks; }
    uint64_t toolStatesDropped() const { return counters().toolStatesDropped; }
    uint64_t rendersDone() const { return counters().renders; }
    uint64_t hapticModelsSent() const { return counters().hapticModelsSent; }
    // HapticRelay messages sent: each force model answered, once per instructor other than its
    // tool's own client.
    uint64_t hapticRelaysSent() const { return counters().hapticRelaysSent; }
    // After stop() with ServerConfig::saveOnExit: where the final volume went (saveOnExit, or an
    // emergency copy in the temporary folder when that failed; empty when neither could be
    // written; the marks went to marksPathFor of it) and why saveOnExit failed (empty when it did
    // not).
    const std::string& savedTo() const { return m_savedTo; }
    const std::string& saveError() const { return m_saveError; }
    // After stop() with ServerConfig::debriefDir: the debriefs written (Markdown files).
    const std::vector<std::string>& debriefs() const { return m_debriefs; }
    uint64_t refusedFull() const { return counters().refusedFull; }
    // Connections closed for saying no hello within ServerConfig::helloTimeoutS.
    uint64_t helloTimeouts() const { return counters().helloTimeouts; }
    uint64_t viewsRefused() const { return counters().viewsRefused; }
    // Annotate messages not applied: from trainees, or adds beyond kMaxAnnotations.
    uint64_t annotationsRefused() const { return counters().annotationsRefused; }
    // TakeOver messages not applied: from trainees, of a client that is not a listed trainee, or
    // of a trainee another instructor holds.
    uint64_t takeOversRefused() const { return counters().takeOversRefused; }
    // HandLinks messages not applied: from trainees, or feeling someone not in the session.
    uint64_t handLinksRefused() const { return counters().handLinksRefused; }
    // Drilling tool states whose cutting the server paused: a trainee taken over, or an
    // instructor holding nobody (their tools still touch the bone).
    uint64_t drillingPaused() const { return counters().drillingPaused; }
    // The gate's figures (net/session_gate.h): handshakes, refusals, sealed messages dropped.
    SecurityCounters security() const;
    const NetStats& stats() const;
    // Updates sent per sync mode (Dbi: image updates; Volume: volume updates) and the clients in
    // each mode now. Both modes share the transport and the channel statistics above.
    ModeTotals modeTotals(Sync mode) const;
    // Server statistics as JSON (toJson of the report, net/server_report.h): per channel totals
    // and rates, per peer (current and departed) bytes, messages, malformed counts, haptic
    // models, refusals; force compute time.
    std::string reportJson() const;

private:
    struct Impl;
    void networkLoop();
    void simulationLoop();
    void saveSession();
    void writeDebriefs();

    std::unique_ptr<Impl> m_impl;
    ServerConfig m_config;
    std::atomic<bool> m_stop{false};
    std::atomic<bool> m_started{false};
    std::string m_savedTo, m_saveError;
    std::vector<std::string> m_debriefs;
    std::thread m_netThread;
    std::thread m_simThread;
};

} // namespace trephine::net

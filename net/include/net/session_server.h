// The session server: one network thread owns the ENet host (hello/welcome, views, tool-state
// relay, pings, malformed-input policy) and one simulation thread owns the volume (drilling,
// BB_volume -> BB_screen per distinct view, rendering, encoding). They talk through mutex-guarded
// queues: tool and view events one way, coalesced image and volume updates the other. Each client
// syncs by DBI (rectangles of its view) or by volume (the replicated-volume baseline: the whole
// volume at join or switch, then the BB_volume voxels), chosen in its hello and switched live.
// docs/session.md describes the threads, queues and coalescing.
#pragma once

#include "libsim/box.h"
#include "libsim/camera.h"
#include "libsim/dbi.h"
#include "libsim/volume.h"
#include "net/enet_host.h"
#include "net/net_stats.h"
#include "net/protocol.h"
#include "net/scene.h"

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

namespace trephine::net {

struct ServerConfig {
    uint16_t port = 7777; // 0: any free port (tests); see SessionServer::port()
    // Participants at once; one more is refused with RefuseReason::ServerFull (ENet keeps a few
    // spare peer slots so the refusal can be said).
    size_t maxClients = 16;
    // The largest view (width x height pixels) served: a larger hello is refused (BadHello), a
    // larger view request is dropped and counted (viewsRefused()).
    int64_t maxViewPixels = 2048 * 2048;
    // Answer each tool state with a HapticModel (Channel::Haptic), relayed to every instructor as
    // a HapticRelay.
    bool hapticModels = true;
    std::string volumeName; // sent in the welcome, as a label
    // The scene every client gets right after its welcome (net/scene.h), and that saveOnExit
    // writes beside the volume (scenePathFor). Null: built from the volume at construction.
    std::shared_ptr<const Scene> scene;
    // When set, stop() writes the final volume here (saveVolume) and the instructors' marks
    // beside it (marksPathFor(saveOnExit), net/marks_file.h), so a later server can start from
    // both.
    std::string saveOnExit;
    // The marks the session starts with (a saved session's, readMarksFile): ids 1..n, author 0.
    std::vector<AnnotationInfo> marks;
    int malformedLimit = 50; // a peer that sends more malformed packets is disconnected
    int renderThreads = 0;   // 0: hardware concurrency
    float maxStepS = 0.05f;  // longest drilling step taken from one tool state to the next
    // Between two drilling tool states the cutter sweeps the path in sub-steps of at most a
    // quarter voxel (sweepPoses); a move longer than this is a jump, drilled at its end only.
    float maxSweepMm = 10.0f;
    // Tool states waiting for the simulation, at most; more are dropped and counted
    // (toolStatesDropped) until it catches up, as a lossy link would (tool states travel
    // unreliable, newest wins). A client sending them faster than the simulation can drill would
    // otherwise grow the queue without bound.
    size_t maxQueuedToolStates = 4096;
    // A client whose image and volume updates ENet still holds (queued, or not acknowledged) come
    // to more than this many bytes gets no more for now: its next update waits in the server's
    // outbox, where newer changes merge into it, so a slow link's backlog stays bounded (about
    // this plus one update) and the client catches up with one merged update.
    int64_t maxInFlightBytes = 4 << 20;
    // A connection that has not said hello after this many seconds is closed (BadHello): it
    // would otherwise hold one of the maxClients slots for good.
    float helloTimeoutS = 5.0f;
};

// The marks (Annotations) go to every participant at most this often, the whole list once.
inline constexpr uint64_t kAnnotationsIntervalUs = 50000;
// The roster (Participants) likewise after a design switch or a take-over (joins and leaves go
// out at once).
inline constexpr uint64_t kRosterIntervalUs = 50000;
// A client's sync mode switches reach the simulation at most this often; one that comes sooner
// waits, and the latest mode is applied then (each switch to volume encodes the whole volume).
inline constexpr uint64_t kSyncSwitchIntervalUs = 250000;

// What the server sent in one sync mode, and how many connected clients use it now.
struct ModeTotals {
    uint64_t clients = 0;
    uint64_t updates = 0, fullUpdates = 0; // messages sent (image or volume updates)
    uint64_t bytes = 0, rawBytes = 0;      // payload bytes on the wire / before compression
};

class SessionServer {
public:
    // Binds the port at once (throws trephine::Error when it cannot); threads start in start().
    SessionServer(Volume volume, ServerConfig config);
    ~SessionServer();
    SessionServer(const SessionServer&) = delete;
    SessionServer& operator=(const SessionServer&) = delete;

    uint16_t port() const;
    // Starts the named threads "trephine-net" and "trephine-sim".
    void start();
    // Stops both threads: the network thread disconnects peers (RefuseReason::Shutdown), the
    // simulation thread applies every queued tool state, then saveOnExit is written. Idempotent.
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
    // The paper's DBI way, for comparison: on every change re-render each view whole, then send
    // BB_screen of it (the default renders only BB_screen; the pixels are the same).
    void setFullRenderUpdates(bool on) { m_fullRender = on; }

    // [Inspection, thread-safe]
    // A fresh full render of the current volume for a view (what a converged client holds).
    Dbi renderView(const ViewSpec& view);
    Volume volumeSnapshot();
    // True when no tool state, view event or paced mode switch waits and no image update is
    // queued or unsent.
    bool idle();
    size_t clientCount() const { return m_clientCount.load(); }
    // The most bytes of image and volume updates ENet held for one client at once (see
    // ServerConfig::maxInFlightBytes), over the session.
    int64_t peakInFlightBytes() const { return m_peakInFlight.load(); }
    uint64_t malformedTotal() const { return m_stats.malformed(); }
    uint64_t disconnectedForMalformed() const { return m_malformedKicks.load(); }
    uint64_t toolStatesApplied() const { return m_toolStatesApplied.load(); }
    uint64_t toolStatesDropped() const { return m_toolStatesDropped.load(); }
    uint64_t rendersDone() const { return m_renders.load(); }
    uint64_t hapticModelsSent() const { return m_hapticSent.load(); }
    // HapticRelay messages sent: each force model answered, once per instructor other than its
    // tool's own client.
    uint64_t hapticRelaysSent() const { return m_hapticRelayed.load(); }
    // After stop() with ServerConfig::saveOnExit: where the final volume went (saveOnExit, or an
    // emergency copy in the temporary folder when that failed; empty when neither could be
    // written; the marks went to marksPathFor of it) and why saveOnExit failed (empty when it did
    // not).
    const std::string& savedTo() const { return m_savedTo; }
    const std::string& saveError() const { return m_saveError; }
    uint64_t refusedFull() const { return m_refusedFull.load(); }
    // Connections closed for saying no hello within ServerConfig::helloTimeoutS.
    uint64_t helloTimeouts() const { return m_helloTimeouts.load(); }
    uint64_t viewsRefused() const { return m_viewsRefused.load(); }
    // Annotate messages not applied: from trainees, or adds beyond kMaxAnnotations.
    uint64_t annotationsRefused() const { return m_annotationsRefused.load(); }
    // TakeOver messages not applied: from trainees, of a client that is not a listed trainee, or
    // of a trainee another instructor holds.
    uint64_t takeOversRefused() const { return m_takeOversRefused.load(); }
    // Drilling tool states whose cutting the server paused: a trainee taken over, or an
    // instructor holding nobody (their tools still touch the bone).
    uint64_t drillingPaused() const { return m_drillingPaused.load(); }
    const NetStats& stats() const { return m_stats; }
    // Updates sent per sync mode (Dbi: image updates; Volume: volume updates) and the clients in
    // each mode now. Both modes share the transport and the channel statistics above.
    ModeTotals modeTotals(Sync mode) const;
    // Server statistics as JSON: per channel totals and rates, per peer (current and departed)
    // bytes, messages, malformed counts, haptic models, refusals; force compute time.
    std::string reportJson() const;

private:
    struct Impl;
    void networkLoop();
    void simulationLoop();

    std::unique_ptr<Impl> m_impl;
    ServerConfig m_config;
    NetStats m_stats;
    std::atomic<bool> m_stop{false};
    std::atomic<bool> m_started{false};
    std::atomic<size_t> m_clientCount{0};
    std::atomic<uint64_t> m_malformedKicks{0};
    std::atomic<uint64_t> m_toolStatesApplied{0};
    std::atomic<uint64_t> m_toolStatesDropped{0};
    std::atomic<uint64_t> m_renders{0};
    std::atomic<int64_t> m_peakInFlight{0};
    std::atomic<uint64_t> m_hapticSent{0};
    std::atomic<uint64_t> m_hapticRelayed{0};
    std::string m_savedTo, m_saveError;
    std::vector<uint8_t> m_sceneMessage; // m_config.scene, encoded once
    std::atomic<uint64_t> m_refusedFull{0};
    std::atomic<uint64_t> m_helloTimeouts{0};
    std::atomic<uint64_t> m_viewsRefused{0};
    std::atomic<uint64_t> m_annotationsRefused{0};
    std::atomic<uint64_t> m_takeOversRefused{0};
    std::atomic<uint64_t> m_drillingPaused{0};
    std::atomic<bool> m_fullRender{false};
    std::thread m_netThread;
    std::thread m_simThread;
};

} // namespace trephine::net

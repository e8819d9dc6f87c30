// What a session server is made with (ServerConfig) and the intervals its session policy paces
// broadcasts and mode switches by. Shared by the server and its parts (net/session_policy.h,
// net/outbox.h, net/sim_step.h).
#pragma once

#include "libsim/dbi_renderer.h"
#include "net/admission.h"
#include "net/enet_host.h"
#include "net/protocol.h"
#include "net/scene.h"

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace trephine::net {

class SessionRecorder;

struct ServerConfig {
    uint16_t port = 7777; // 0: any free port (tests); see SessionServer::port()
    // Participants at once; one more is refused with RefuseReason::ServerFull (ENet keeps a few
    // spare peer slots so the refusal can be said). A classroom of 64 trainees and their
    // instructors joins without a flag.
    size_t maxClients = 72;
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
    // What renders the views: empty, the CPU ray caster; `trephine server --renderer gpu` sets
    // the GPU's (libsim_gpu/gpu_renderer.h).
    DbiRendererFactory renderer;
    float maxStepS = 0.05f; // longest drilling step taken from one tool state to the next
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
    // The assessment's zones (net/assessment.h): a cutter within cautionMm of a critical
    // structure is in Caution, within dangerMm in Danger (0 < danger < caution < 20 mm).
    float cautionMm = 3.0f;
    float dangerMm = 1.0f;
    // When set, stop() writes a Markdown debrief with SVG plots per participant here
    // (net/debrief.h).
    std::string debriefDir;
    // Role codes (docs/security.md): a client proves one in the handshake, its role is the
    // code's, and every message after it is sealed. Both empty: an open session where anyone who
    // reaches the port joins with the role its hello names, in the clear (`trephine server
    // --open`; tests). Either form of a code (normaliseCode) works.
    std::string traineeCode, instructorCode;

    // [Availability] What peers may hold, whatever they send (docs/session.md, "Availability").
    // Connections not yet admitted: ENet slots beyond maxClients, per-address limits, handshakes.
    AdmissionLimits admission;
    // A participant that sends nothing at all for this long is sent away (RefuseReason::Idle).
    // Clients ping every 0.25 s while welcomed, so only a dead or hostile peer stays silent.
    float idleTimeoutS = 60.0f;
    // Control-channel bytes ENet may hold for one peer: beyond it the roster, the marks and
    // followed views wait as their latest state only, and pongs are not sent.
    int64_t controlBudgetBytes = 256 << 10;
    // View pixels a peer may have rendered per second (a token bucket holding two of the largest
    // views); a request beyond it waits, the newest one only, until its pixels are due.
    double viewPixelsPerS = 8.0 * 1024 * 1024;
    // All participants' views together (w x h each): a view that would pass it is refused. The
    // server keeps about 40 bytes a pixel of view (frame, hit cache, coded copies). Room for
    // maxClients at the default 500 x 500 view (18 M) and a few full-screen views beside them.
    int64_t maxTotalViewPixels = 32 << 20;
    // How the host sizes each peer's reliable window (docs/protocol.md, "The reliable window").
    BulkWindow bulkWindow;
    // When set, every change to the session is appended here (net/session_log.h) before anything
    // it caused is sent to a client.
    std::shared_ptr<SessionRecorder> recorder;
    // Serving a session log (`trephine replay --serve`): the windows are watchers, whose drills
    // never cut (they touch the bone as paused burrs), and any of them drives the timeline.
    bool replay = false;
};

// The marks (Annotations) go to every participant at most this often, the whole list once.
inline constexpr uint64_t kAnnotationsIntervalUs = 50000;
// The roster (Participants) likewise after a design switch or a take-over (joins and leaves go
// out at once).
inline constexpr uint64_t kRosterIntervalUs = 50000;
// A client's sync mode switches reach the simulation at most this often; one that comes sooner
// waits, and the latest mode is applied then (each switch to volume encodes the whole volume).
inline constexpr uint64_t kSyncSwitchIntervalUs = 250000;
// The network thread's scans of every slot and peer (handshakes to reset, network charges) run
// once in this period, and the policy's walk over every peer (timeouts, deferred views, paced
// switches) at least this often, sooner when it knows something falls due; not on each of the
// thread's ~1000 passes a second: under a reconnecting flood (328 slots) they were most of its
// time.
inline constexpr uint64_t kScanPeriodUs = 10000;

} // namespace trephine::net

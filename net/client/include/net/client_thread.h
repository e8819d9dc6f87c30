// ClientThread: a SessionClient run on its own named network thread ("net-client"), for windows.
// Other threads hand it commands through a bounded queue and read what it publishes without
// blocking: an immutable snapshot (connection, view, others' tools, statistics) swapped whole, and
// a queue of applied rectangles (the pixels a window re-uploads with glTexSubImage2D), and in
// volume sync mode with renderLocally off, a queue of applied voxel boxes (3D texture
// sub-uploads) plus guarded read access to the local volume for a haptic thread.
#pragma once

#include "libsim/dbi.h"
#include "net/assessment_protocol.h"
#include "net/net_stats.h"
#include "net/protocol.h"
#include "net/session_client.h"

#include <array>
#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <shared_mutex>
#include <string>
#include <thread>
#include <variant>
#include <vector>

namespace trephine::net {

enum class LinkState : uint8_t { Connecting, Connected, Retrying, Stopped };
const char* linkStateName(LinkState s);

// One image update as the window needs it: where, the pixels, and the figures for the panels. In
// the volume design with renderLocally on, each voxel update re-renders the client's view, and the
// whole view is published as the update's rectangle.
struct AppliedRect {
    PixelRect rect;    // DBI pixels, row 0 at the bottom
    Dbi pixels;        // rect.w x rect.h patch taken from the client's DBI after applying
    bool full = false; // a whole-window refresh: pixels is the whole DBI
    uint32_t sequence = 0;
    uint32_t viewId = 0;
    ViewSpec view;         // the view of viewId: the camera the pixels were rendered with
    uint32_t bytes = 0;    // payload on the wire
    uint32_t rawBytes = 0; // before compression
    double latencyUs = -1; // cause at the server -> applied here (-1: unknown or full)
    uint64_t appliedUs = 0;
};

// What an applied rectangle is to the picture a client shows, one rule for every shell (the
// window, the headless trainee): the whole picture of a view of `viewSize` (a full image), a
// rectangle of the picture held (of its view, inside it), or nothing of it (the placeholder
// view's, or a view left behind).
enum class PicturePart { Whole, Rect, None };
struct HeldPicture {
    uint32_t viewId = 0;
    glm::ivec2 size{0};
};
PicturePart picturePart(const AppliedRect& r, glm::ivec2 viewSize,
                        const std::optional<HeldPicture>& held);

// One volume update as a window needs it (volume mode, renderLocally off): the box and its voxels
// after applying, or the whole volume on a full update.
struct AppliedVolumeBox {
    Box3i box; // voxels; the whole volume when full
    bool full = false;
    glm::ivec3 dims{0};                     // of the whole volume
    glm::vec3 spacing{1.0f};                // mm per voxel
    std::vector<uint8_t> density, material; // box.count() bytes each, x fastest
    uint32_t sequence = 0;
    uint32_t bytes = 0, rawBytes = 0;
    double latencyUs = -1; // cause at the server -> applied here (-1: unknown or full)
    uint64_t appliedUs = 0;
};

// Per-sync-mode figures for the Comparison panel; each mode's stay while the other is active.
struct ModeFigures {
    uint64_t updatesApplied = 0;
    double updateRatePerS = 0;              // over the latest tick (1 s; longer after a stall)
    double meanBytes = 0, meanRawBytes = 0; // per update
    double latencyP50Us = -1, latencyP99Us = -1;
    double applyP50Us = -1, clientRenderP50Us = -1;
    // The server's stages and the transmission (p50, us; -1: none measured).
    double erodeP50Us = -1, serverRenderP50Us = -1, encodeP50Us = -1, transmitP50Us = -1;
    bool operator==(const ModeFigures&) const = default;
};

// What the UI reads each frame. Immutable once published.
struct ClientSnapshot {
    LinkState state = LinkState::Connecting;
    std::string closeReason; // why the last connection ended, empty if none did
    // Set when this client ended it over a malformed message of the server's (closeReason is
    // serverFaultText of it), not the server or the network.
    std::optional<ServerFault> fault;
    int attempts = 0; // connection attempts so far
    // Times the server refused the volume design (its whole volume does not fit a message,
    // RefuseReason::VolumeTooLarge): the thread then asks for DBI on the next connection instead
    // of reconnecting into the same refusal for good.
    int volumeRefusals = 0;
    uint64_t publishedUs = 0;
    std::optional<Welcome> welcome;
    // The server's scene (presets, sites, the surgical field), null until it arrives and between
    // connections; a window keeps what it built until a scene with another id comes.
    std::shared_ptr<const ReceivedScene> scene;
    uint16_t viewingAs = 0; // [Instructor] whose camera the view follows (0: its own)
    ViewSpec view;
    uint32_t viewId = 0;
    bool hasFullImage = false;   // a picture of the view: its exact full image or its preview
    bool waitingForView = false; // a requested view has no picture yet
    std::map<uint16_t, ToolState> others;
    // Everyone in the session (this client included) by client id: names, roles, designs.
    std::map<uint16_t, ParticipantInfo> participants;
    // The instructors' marks on the skull, by increasing id.
    std::vector<AnnotationInfo> annotations;
    // [Assessment] The newest zone warning per tool (own; an instructor's, everyone's) and the
    // newest metrics (own; an instructor's, everyone's).
    std::map<uint16_t, SafetyWarning> warnings;
    AssessmentSnapshot assessment;
    // [Replay] The timeline of the log the server serves, its position as of publishedUs (none:
    // a live session); replayPositionAfter moves it on.
    std::optional<ReplayState> replay;
    // [Instructor] The session's codes, to read out (none: a trainee, or an open session).
    std::optional<Codes> codes;
    // The server's other state, each kind's newest message (SessionClient::newest).
    MessageStore newest;
    std::optional<HapticModel> hapticModel; // latest force model (when the client offers it)
    uint64_t hapticModels = 0;
    // [Instructor] the newest relayed force model of every other participant, by client id.
    std::map<uint16_t, HapticModel> relayedModels;
    uint64_t hapticRelays = 0;
    // ENet's coarse loss estimate (NetStats::packetLoss, -1: unknown) and packets lost in its
    // current 10 s interval.
    double packetLoss = -1;
    uint64_t packetsLost = 0;
    // Statistics.
    uint64_t updatesApplied = 0, fullUpdates = 0, updatesRejected = 0, toolStatesSent = 0,
             relaysReceived = 0, malformed = 0;
    uint64_t malformedImages = 0; // image updates among the malformed (SessionClient's)
    uint64_t viewsRefused = 0;    // views asked for that the server does not serve (too large)
    std::optional<ViewRefusal> viewRefusal; // the newest, until the next view request
    double rttUs = -1, rttP50Us = -1;
    double hapticRoundTripP50Us = -1, hapticRoundTripP99Us = -1; // tool state -> its force model
    uint64_t lastHeardUs = 0; // steadyNowUs() of the last datagram from the server (0: none yet)
    double latencyP50Us = -1, latencyP99Us = -1;
    double meanBytes = 0, meanRawBytes = 0; // per update
    std::string codec;                      // image updates (DBI mode)
    std::string volumeCodec; // volume box updates (volume mode; a full copy is zstd when raw)
    Sync sync = Sync::Dbi;   // the mode feeding the picture
    Sync requestedSync = Sync::Dbi;   // differs from sync while a switch waits for its full update
    std::array<ModeFigures, 2> modes; // by Sync
    std::array<ChannelRates, size_t(Channel::Count)> rates{}; // latest 1 s tick
    std::deque<std::array<ChannelRates, size_t(Channel::Count)>> rateHistory;

    // Every field equal: the scene by identity (immutable, one object per arrival), the server's
    // messages by their wire bytes (one encoding per value), the rest by value.
    bool operator==(const ClientSnapshot& o) const;
};

// What a window draws from a snapshot, apart from the rectangles and boxes: equal, a redraw shows
// the same picture, so ClientThread's onNews stays quiet (figures and statistics are left out).
struct DrawnPart {
    struct Tool { // others' tools as drawn: no sequence, time or speed
        glm::vec3 position{0};
        glm::quat orientation{1, 0, 0, 0};
        bool drilling = false;
        uint8_t toolKind = 0;
        float diameterMm = 0;
        bool operator==(const Tool&) const = default;
    };
    struct Timeline { // a replay's, whose cursor moves by itself while it plays
        bool playing = false;
        uint32_t seeks = 0;
        float speed = 1.0f;
        uint64_t durationUs = 0, positionUs = 0; // positionUs: 0 while playing
        bool operator==(const Timeline&) const = default;
    };
    LinkState state = LinkState::Connecting;
    std::string closeReason;
    int attempts = 0;
    std::shared_ptr<const ReceivedScene> scene;
    bool welcomed = false;
    uint16_t viewingAs = 0;
    ViewSpec view;
    uint32_t viewId = 0;
    bool waitingForView = false;
    std::optional<ViewRefusal> viewRefusal;
    Sync sync = Sync::Dbi, requestedSync = Sync::Dbi;
    std::map<uint16_t, ParticipantInfo> participants;
    std::vector<AnnotationInfo> annotations;
    std::optional<Timeline> replay;
    std::optional<Codes> codes;
    MessageStore newest;
    std::map<uint16_t, Tool> others;
    bool operator==(const DrawnPart&) const = default;
};
DrawnPart drawnPart(const ClientSnapshot& s);
// Why the server does not serve a view of `width` x `height` ("" when it does): larger than any it
// serves (the client refuses it; restart with a smaller `sizeOption`), or past the session's
// total of view pixels (the server refused it, ViewRefused, and the last view stays). Every shell
// says it in these words.
std::string viewNotServedText(const ClientSnapshot& snap, int width, int height,
                              const std::string& sizeOption);

struct ClientThreadConfig {
    ClientConfig client;
    std::string address = "127.0.0.1:7777"; // HOST:PORT
    double retryS = 2.0;                    // wait before reconnecting after a failure or drop
    double connectTimeoutS = 5.0;
    size_t maxQueuedRects = 256; // beyond this the queue is replaced by one full copy of the DBI
    // Commands waiting for the network thread, at most (more are refused): room for a whole
    // list of marks at once (an undo of a cleared list re-adds them all in one frame) and more.
    size_t maxCommands = 4 * kMaxAnnotations;
    // Called on the network thread for every force model as it arrives (e.g. HapticLoop::setModel,
    // which is thread-safe); must be quick.
    std::function<void(const HapticModel&)> onHapticModel;
    // Called on the network thread when there is something new to show: an applied rectangle or
    // voxel box, or a snapshot that differs from the last in what a window draws (link state,
    // scene, view, others' tools, participants, marks). A window waiting for events while idle
    // wakes on it (e.g. glfwPostEmptyEvent); must be quick and thread-safe.
    std::function<void()> onNews;
};

class ClientThread {
public:
    explicit ClientThread(ClientThreadConfig config);
    ~ClientThread(); // stops
    ClientThread(const ClientThread&) = delete;
    ClientThread& operator=(const ClientThread&) = delete;

    void start();
    // Disconnects gracefully and joins the thread. Idempotent.
    void stop();

    // Commands: never block; false when the queue is full (the command is dropped). Tool states
    // replace a queued tool state (newest wins).
    bool sendToolState(const ToolState& t);
    bool requestView(const ViewSpec& v);
    bool ping();
    // Switches the sync mode live (kept across reconnects).
    bool requestSync(Sync mode);
    // [Instructor] Adds, removes or clears marks (SessionClient::annotate).
    bool annotate(const Annotate& a);
    // A plain request (SessionClient::send), e.g. TakeOver or Remove.
    bool send(ClientRequest r);
    // [Instructor] Takes over a trainee or hands back (0) (SessionClient::takeOver).
    bool takeOver(uint16_t trainee);
    // [Instructor] Watches through a participant's camera (0: its own) (SessionClient::viewAs).
    bool viewAs(uint16_t id);
    // [Instructor] Removes a participant, or lets the removed rejoin (SessionClient::remove).
    bool remove(Remove m);
    // [Replay] Plays, pauses, seeks or changes the speed (SessionClient::controlReplay).
    bool controlReplay(const ReplayControl& c);
    // [Instructor] Asks for a new code of `role` (SessionClient::newCode). A new instructor code
    // is also this thread's for its reconnects.
    bool newCode(Role role);

    // The latest snapshot (never null after construction).
    std::shared_ptr<const ClientSnapshot> snapshot() const;
    // Moves out the rectangles applied since the last call, oldest first.
    std::vector<AppliedRect> drainRects();
    // Total rectangles published (tests wait on it).
    uint64_t rectsPublished() const { return m_rectsPublished.load(); }
    // Volume mode with client.renderLocally off: the boxes applied since the last call, oldest
    // first (bounded like the rectangles: overflow becomes one full copy of the volume).
    std::vector<AppliedVolumeBox> drainVolumeBoxes();
    uint64_t volumeBoxesPublished() const { return m_boxesPublished.load(); }
    // Runs fn on the local volume under a shared lock (the network thread takes it exclusively
    // only while it writes voxels, never while it renders); false, without calling fn, when no
    // volume is held. For a haptic thread: e.g. ForceModel::compute(volume, pose) inside fn.
    bool withLocalVolume(const std::function<void(const Volume&)>& fn) const;

private:
    struct ViewCmd {
        ViewSpec view;
    };
    struct PingCmd {};
    struct SyncCmd {
        Sync sync;
    };
    using Command =
        std::variant<ToolState, ViewCmd, PingCmd, SyncCmd, Annotate, ViewAs, ClientRequest>;

    // The 1 s rate tick's state for one connection (network thread only).
    struct RateClock {
        uint64_t lastTickUs = 0;
        uint64_t nextTickUs = 0;
        std::array<std::array<uint64_t, 4>, size_t(Channel::Count)> lastTotals{};
        std::array<uint64_t, 2> lastModeUpdates{};
    };

    // The network thread: connects, runs the connection, waits and retries until stopped.
    void run();
    // A client connecting to the address, or none (m_closeReason says why).
    std::unique_ptr<SessionClient> connectClient(const ClientConfig& cc);
    // One connection's life, from the callbacks to its close (its reason kept for the retry).
    void runConnection(SessionClient& client, const ClientConfig& cc);
    void installCallbacks(SessionClient& client, bool renderLocally);
    void pollUntilClosed(SessionClient& client, const ClientConfig& cc);
    // The UI's queued commands, sent on this connection.
    void runCommands(SessionClient& client, bool renderLocally);
    // The whole DBI / volume, when the UI dropped its queue (pushRect, pushBox).
    void publishFullCopies(const SessionClient& c, uint64_t nowUs);
    void tickRates(const SessionClient& c, uint64_t nowUs, RateClock& clock);
    bool push(Command c);
    void publish(const SessionClient* c, uint64_t nowUs);
    void pushRect(AppliedRect r);
    void pushBox(AppliedVolumeBox b);

    ClientThreadConfig m_config;
    std::atomic<bool> m_stop{false};
    std::thread m_thread;

    mutable std::mutex m_cmdMutex;
    std::deque<Command> m_commands;

    mutable std::mutex m_snapMutex; // guards only the pointer swap
    std::shared_ptr<const ClientSnapshot> m_snapshot;

    std::mutex m_rectMutex;
    std::vector<AppliedRect> m_rects;
    std::atomic<uint64_t> m_rectsPublished{0};
    std::atomic<bool> m_needFull{false};

    std::mutex m_boxMutex;
    std::vector<AppliedVolumeBox> m_boxes;
    std::atomic<uint64_t> m_boxesPublished{0};
    std::atomic<bool> m_needFullVolume{false};

    // Guards m_localClient and writes to its volume (SessionClient::setVolumeMutex).
    mutable std::shared_mutex m_volumeRw;
    const SessionClient* m_localClient = nullptr;

    // Network-thread state.
    LinkState m_state = LinkState::Connecting;
    std::string m_closeReason;
    std::optional<ServerFault> m_fault; // of the last connection, as m_closeReason
    int m_attempts = 0;
    int m_volumeRefusals = 0;
    uint32_t m_toolSequence = 0; // carried from one connection to the next (run() only)
    std::optional<ViewSpec> m_wantedView;
    std::optional<Sync> m_wantedSync;
    std::optional<std::string> m_wantedCode; // an instructor's newest code (reconnects)
    std::array<double, 2> m_modeRates{};
    std::optional<HapticModel> m_haptic;
    uint64_t m_hapticModels = 0;
    double m_lastRttUs = -1;
    std::deque<std::array<ChannelRates, size_t(Channel::Count)>> m_rateHistory;
};

} // namespace trephine::net

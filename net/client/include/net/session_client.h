// The session client, usable without a window: connects (protocol version in the connect data),
// says hello, holds the DBI of its view, applies image updates, keeps the others' relayed tool
// poses and its statistics. In volume sync mode (the replicated-volume baseline) it holds the
// volume instead, applies voxel boxes and re-renders its view locally into the same DBI.
// Poll-driven: the caller's thread runs poll(), so tests pump a server and clients in one process;
// the headless trainee drives it from its script loop.
#pragma once

#include "libsim/box.h"
#include "libsim/camera.h"
#include "libsim/dbi.h"
#include "libsim/renderer.h"
#include "libsim/volume.h"
#include "net/assessment_protocol.h"
#include "net/enet_host.h"
#include "net/messages.h"
#include "net/net_stats.h"
#include "net/protocol.h"
#include "net/replay_protocol.h"
#include "net/scene.h"
#include "net/secure_channel.h"

#include <cstdint>
#include <deque>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <shared_mutex>
#include <string>

namespace trephine {
class ThreadPool;
} // namespace trephine

namespace trephine::net {

struct ClientConfig {
    std::string name = "trainee";
    Role role = Role::Trainee;
    Codec codec = Codec::Lz4;
    ViewSpec view;
    uint32_t protocolVersion = kProtocolVersion; // tests connect with a wrong one
    // How the picture is kept in sync: Dbi (the server renders) or Volume (the baseline: the
    // client holds the volume and renders it). Switch live with SessionClient::requestSync.
    Sync sync = Sync::Dbi;
    // Encoding of volume box updates: Raw (the paper's 1 byte per voxel) or Lz4 / Zstd.
    Codec volumeCodec = Codec::Raw;
    // Volume mode: re-render the whole view with the CPU Renderer into dbi() after each update.
    // A window that ray-casts the volume on the GPU itself sets false.
    bool renderLocally = true;
    int renderThreads = 0;        // the local render's ThreadPool (0: hardware concurrency)
    size_t recordCapacity = 4096; // UpdateRecords kept (the newest)
    // The role's code the server printed (docs/security.md): proven in a handshake, then every
    // message is sealed; a client with a code will not join an open session. Empty: join an open
    // session (a session with codes refuses it: "this session needs a code").
    std::string code;
    // The client's time in microseconds: its runner's clock (the steady clock when empty). Tests
    // pass their own to reach a retry or a timeout without waiting.
    std::function<uint64_t()> clock;
};

// Why a client ended its session itself: a message of the server's that it cannot go without (its
// welcome, its scene, the full image or volume its picture waits for) was malformed.
struct ServerFault {
    MessageType type = MessageType::Welcome;
    std::string detail; // what was wrong with it, e.g. "37 bytes that do not decode"
};
// "HOST sent a malformed scene (DETAIL)": the session's failure text, the one place it is made.
std::string serverFaultText(const std::string& server, const ServerFault& fault);

// A view the server refused (ViewRefused): its size, and the pixels the server had free for it.
struct ViewRefusal {
    int width = 0, height = 0;
    uint32_t freePixels = 0;
    bool operator==(const ViewRefusal&) const = default;
};

// A request the client sends as it is, with nothing of its own state to follow: any message of
// the table a client sends, except those listed here, which have methods of their own that keep
// the client's state (its hello and handshake, views, design, tool states, pings, view-as, marks).
template <typename M>
inline constexpr bool kKeepsClientState =
    std::is_same_v<M, Hello> || std::is_same_v<M, Handshake> || std::is_same_v<M, ViewRequest> ||
    std::is_same_v<M, SyncMode> || std::is_same_v<M, ToolState> || std::is_same_v<M, Ping> ||
    std::is_same_v<M, ViewAs> || std::is_same_v<M, Annotate>;
template <typename M>
struct IsPlainRequest
    : std::bool_constant<receives(Side::Server, messageInfo(M::kType).direction) &&
                         !kKeepsClientState<M>> {};
using ClientRequest = MessageVariant<IsPlainRequest>;

// Server state the client keeps whole in newest() with no handler of its own: a control message
// the server sends that a newer one replaces (the table's newest wins). One with a handler (the
// roster, the marks, ...) is kept by it instead.
template <typename M>
struct IsStoredState : std::bool_constant<receives(Side::Client, messageInfo(M::kType).direction) &&
                                          messageInfo(M::kType).newestWins &&
                                          messageInfo(M::kType).channel == Channel::Control> {};

class SessionClient {
public:
    explicit SessionClient(ClientConfig config);
    ~SessionClient();
    SessionClient(const SessionClient&) = delete;
    SessionClient& operator=(const SessionClient&) = delete;

    // Starts connecting; progress happens in poll(). The hello goes out once connected.
    // `serverName` names the server in failure texts (empty: the address).
    void connect(const ENetAddress& address, std::string serverName = {});
    // One pass at `nowUs`, without waiting: a Busy retry that is due, every pending event, the
    // statistics' tick; flushes sends. Returns the number of events handled.
    int pump(uint64_t nowUs);
    // Sends what is queued and waits up to timeoutMs for traffic (a runner's wait before pump).
    void wait(uint32_t timeoutMs) { m_host.wait(timeoutMs); }
    // wait(timeoutMs), then pump() at the client's clock (ClientConfig::clock).
    int poll(uint32_t timeoutMs) {
        wait(timeoutMs);
        return pump(m_config.clock());
    }
    // Graceful disconnect (waits up to timeoutMs for the server to acknowledge).
    void disconnect(uint32_t timeoutMs = 200);

    bool connected() const { return m_peer && m_connected; }
    bool welcomed() const { return m_welcome.has_value(); }
    bool closed() const { return m_closed; }
    // Why the connection closed (refuseReasonText, or serverFaultText of fault()), empty while
    // connected.
    const std::string& closeReason() const { return m_closeReason; }
    // The first malformed message the session could not go without: the client then closed the
    // connection at once, rather than wait for what would not come. None otherwise.
    const std::optional<ServerFault>& fault() const { return m_fault; }
    // Image updates dropped as malformed; one after the first picture costs a rectangle only.
    uint64_t malformedImages() const { return m_malformedImages; }
    // The disconnect's data (a RefuseReason when the server closed the connection), 0 while open.
    uint32_t closeCode() const { return m_closeCode; }
    // Refusals with Busy before the welcome: the server is there but its places for joining are
    // taken, so the client connects again by itself after a wait of 0.25 s doubling to 2 s.
    uint32_t busyRefusals() const { return m_busyRefusals; }
    // Its code offer sent and not answered yet: the server may hold it for its turn
    // (docs/security.md, "Guessing online"), up to about kMaxOfferWaitS.
    bool offerPending() const { return m_spake.has_value(); }
    static constexpr double kMaxOfferWaitS = 30.0;
    const Welcome& welcome() const { return *m_welcome; }
    // The server's scene (net/scene.h: extent, camera presets, sites, landmarks, the surgical
    // field), null until it arrives right after the welcome. Immutable: a reconnect's new client
    // gets its own, so a holder may keep the pointer. A DBI client needs nothing else of the
    // volume; no client opens a file the server names.
    std::shared_ptr<const ReceivedScene> scene() const { return m_scene; }
    // Scene messages received and kept (a malformed one counts as malformed instead).
    uint64_t scenesReceived() const { return m_scenes; }
    // steadyNowUs() of the last thing heard from the server (its connect, any datagram, a
    // fragment included, and the end of handling each message); connect() starts it. A server that
    // died without a word is noticed by ENet only after 5 to 30 s; one answering sendPing() every
    // 0.1 s but silent for seconds is gone.
    uint64_t lastHeardUs() const { return m_lastHeardUs; }

    // The DBI of the current view (background until the first full update arrives). In volume
    // mode it is the local render (when renderLocally), so it is the picture in both modes.
    const Dbi& dbi() const { return m_dbi; }

    // [Sync mode] The mode whose updates currently feed the picture. A switch asked for with
    // requestSync takes effect when the server's first full update of the new mode arrives (the
    // whole volume, or a full DBI); until then the old mode's updates keep being applied.
    Sync sync() const { return m_sync; }
    Sync requestedSync() const { return m_wantSync; }
    bool switchingSync() const { return m_wantSync != m_sync; }
    // Sends SyncMode (no-op when already in, or switching to, that mode).
    void requestSync(Sync mode);
    // The local copy of the server's volume in volume mode (null before the first full volume
    // and after a switch back to DBI).
    const Volume* localVolume() const { return m_volume.get(); }
    // [Volume mode, renderLocally] the local view's hit cache (its resumed() count).
    const HitCache& localHitCache() const { return m_hitCache; }
    // Writes to the local volume hold this mutex exclusively (null: no lock), so another thread
    // (haptics) may read localVolume() under a shared lock; reads on the polling thread need none.
    void setVolumeMutex(std::shared_mutex* mutex) { m_volumeMutex = mutex; }
    const ViewSpec& view() const { return m_view; }
    uint32_t viewId() const { return m_viewId; }
    // True once the exact full image of the current view (the latest requested one) has been
    // applied; hasPicture() already from its half-size preview (ImageUpdate::preview).
    bool hasFullImage() const { return hasPicture() && m_exactViewId == m_viewId; }
    bool hasPicture() const { return m_hasFull && m_requestedViewId == m_viewId; }

    // Sends our tool; sequence and clientTimeUs are filled in when zero. Returns the sequence.
    uint32_t sendToolState(ToolState state);
    // The last sequence sendToolState filled in; continueToolSequence(s): the next one is s + 1.
    // A reconnecting client carries its count on, so that what keeps the newest force model by
    // tool sequence (NewestModel) does not take the new connection's answers for old ones.
    uint32_t toolSequence() const { return m_toolSequence; }
    void continueToolSequence(uint32_t last) { m_toolSequence = last; }
    // Asks for a new view; the DBI switches when its full image arrives. Returns the request id.
    // In volume mode the view switches at once (rendered locally) and the server is told, so a
    // switch to DBI gets this view. A view larger than the welcome's maxViewPixels, which the
    // server would drop, or one the wire refuses (ViewSpec::serialize: no direction, an eye or
    // far plane beyond the limits), is refused here: nothing changes, nothing is sent, it returns
    // 0 and counts in viewsRefused().
    uint32_t requestView(const ViewSpec& view);
    uint64_t viewsRefused() const { return m_viewsRefused; }
    // The newest view the server refused (ViewRefused: all views together would pass its total):
    // its size and the pixels the server had free for it. The view held before stays.
    const std::optional<ViewRefusal>& viewRefusal() const { return m_viewRefusal; }
    // The view a hello would ask for now: the newest request still waiting, else the view held.
    const ViewSpec& viewAskedFor() const {
        return m_requested.empty() ? m_view : m_requested.rbegin()->second;
    }
    void sendPing();
    // [Instructor] Adds a mark, removes one or clears them all (Annotate); the server applies it
    // and sends everyone the new list. A trainee's are refused by the server. Labels are cut to
    // kMaxNameLength bytes.
    void annotate(Annotate a);
    // [Instructor] Takes over a trainee (its client id) or hands back (0): see TakeOver. The
    // roster (participants()) says when it took effect; a trainee's are refused by the server.
    void takeOver(uint16_t trainee);
    // [Instructor] Watches through participant `id`'s camera (0: its own again): the server sends
    // that participant's view whenever it changes, and each is asked for (requestView) at this
    // client's own window size. A trainee's are ignored by the server.
    void viewAs(uint16_t id);
    uint16_t viewingAs() const { return m_viewAs; }
    // [Instructor] Removes participant `id` from the session, or lets every removed one join
    // again (Remove); the server refuses a trainee's.
    void remove(Remove m);
    // [Instructor] Asks the server for a new code of `role` (Codes); the server refuses a
    // trainee's. codes(): the session's codes as the server last sent them (only instructors
    // are sent them; none in an open session). session_client_codes.cpp.
    void newCode(Role role);
    const std::optional<Codes>& codes() const { return m_codes; }
    // Sends a plain request (IsPlainRequest) on the table's channel. The server answers, if at
    // all, with state that newest() or a handler keeps.
    template <typename M>
    requires IsPlainRequest<M>::value void send(M m) {
        send(messageInfo(M::kType).channel, encodeMessage(m));
    }
    void send(const ClientRequest& r) {
        std::visit([this](const auto& m) { send(m); }, r);
    }
    // The newest server state of each kind kept without a handler (IsStoredState).
    const MessageStore& newest() const { return m_newest; }
    // ParticipantView messages received (of the participant viewed as, or a stale one).
    uint64_t participantViewsReceived() const { return m_participantViews; }

    // The latest relayed tool of every other participant, by client id.
    const std::map<uint16_t, ToolState>& others() const { return m_others; }
    // Everyone in the session, this client included, by client id, as the server's newest
    // Participants message listed them (empty before the first).
    const std::map<uint16_t, ParticipantInfo>& participants() const { return m_participants; }
    // Participants messages received.
    uint64_t rostersReceived() const { return m_rosters; }
    // The session's marks, as the server's newest Annotations message listed them (by id).
    const std::vector<AnnotationInfo>& annotations() const { return m_annotations; }
    uint64_t annotationListsReceived() const { return m_annotationLists; }
    // [Assessment] The newest SafetyWarning about each tool this client hears of (its own; an
    // instructor's, everyone's), by client id; every one received, oldest first (the newest
    // kMaxWarningLog); and the newest AssessmentSnapshot (own figures, or everyone's).
    static constexpr size_t kMaxWarningLog = 256;
    const std::map<uint16_t, SafetyWarning>& warnings() const { return m_warnings; }
    const std::deque<SafetyWarning>& warningLog() const { return m_warningLog; }
    uint64_t warningsReceived() const { return m_warningsReceived; }
    const AssessmentSnapshot& assessment() const { return m_assessment; }
    uint64_t snapshotsReceived() const { return m_snapshots; }
    // [Replay] The newest ReplayState of the log this server serves (none: it serves a live
    // session), and steadyNowUs() when it arrived; replayPosition() moves it on to `nowUs`.
    const std::optional<ReplayState>& replay() const { return m_replay; }
    uint64_t replayPosition(uint64_t nowUs) const;
    // [Replay] Plays, pauses, seeks or changes the speed of the replay every window watches.
    void controlReplay(ReplayControl c);
    uint64_t relaysReceived() const { return m_relays; }
    uint64_t updatesApplied() const { return m_updatesApplied; }
    uint64_t fullUpdates() const { return m_fullUpdates; }
    uint64_t updatesRejected() const { return m_rejected; }
    // Predicted image updates whose base differed from our pixels (not applied). The first asks
    // for a full image of the newest view asked for; the others until it arrives ask nothing.
    uint64_t resyncs() const { return m_resyncs; }
    // Predicted image updates applied (coded against our own pixels, net/image_delta.h).
    uint64_t predictedApplied() const { return m_predicted; }
    // Rectangles after a full image (ImageUpdate::fullSequence) ignored: not on the full image we
    // hold, no newer than the last image applied (a repeat is acknowledged again), or chained on
    // an image we lack (reported as unusable). And ImageAcks sent.
    uint64_t lossyIgnored() const { return m_lossyIgnored; }
    uint64_t imageAcksSent() const { return m_acksSent; }
    uint64_t toolStatesSent() const { return m_toolSent; }
    uint32_t lastUpdateSequence() const { return m_lastSequence; }
    NetStats& stats() { return m_stats; }
    const NetStats& stats() const { return m_stats; }

    // [Haptics and UI hooks] Callbacks run on the thread that calls poll(), inside poll().
    // Called with each HapticModel received on Channel::Haptic (arrivalUs: steadyNowUs() when it
    // was handled). Models are newest-wins on the wire; an older one may arrive after a newer one.
    using HapticCallback = std::function<void(const HapticModel&, uint64_t arrivalUs)>;
    void setHapticCallback(HapticCallback callback) { m_hapticCallback = std::move(callback); }
    // The newest HapticModel received (by tool sequence), if any.
    std::optional<HapticModel> latestHapticModel() const { return m_latestHaptic; }
    uint64_t hapticModelsReceived() const { return m_hapticModels; }
    // [Instructor] The newest force model of every other participant, relayed by the server
    // (HapticRelay, sent only to instructors), by client id; newest by tool sequence wins.
    const std::map<uint16_t, HapticModel>& relayedModels() const { return m_relayedModels; }
    uint64_t hapticRelaysReceived() const { return m_hapticRelays; }
    // Called with each relayed model received (client id, model, arrival as steadyNowUs()).
    using RelayCallback =
        std::function<void(uint16_t clientId, const HapticModel&, uint64_t arrivalUs)>;
    void setRelayCallback(RelayCallback callback) { m_relayCallback = std::move(callback); }
    // Called after each ImageUpdate has been applied to the DBI: `rect` is the changed rectangle
    // in DBI pixels (row 0 at the bottom, as GL), `full` when the whole DBI was replaced (a join
    // or a view switch: the DBI's size may have changed).
    using UpdateCallback =
        std::function<void(const ImageUpdate& meta, const PixelRect& rect, bool full)>;
    void setUpdateCallback(UpdateCallback callback) { m_updateCallback = std::move(callback); }

    // Called after each VolumeUpdate has been applied (and, with renderLocally, the view
    // re-rendered): `box` in voxels; `full` when the whole volume was replaced.
    using VolumeCallback =
        std::function<void(const VolumeUpdate& meta, const Box3i& box, bool full)>;
    void setVolumeCallback(VolumeCallback callback) { m_volumeCallback = std::move(callback); }
    uint64_t volumeUpdatesApplied() const { return m_volumeUpdates; }

    // Per-update records of both modes (the newest recordCapacity), oldest first, and a hook
    // called with each as it is made.
    const std::deque<UpdateRecord>& updateRecords() const { return m_records; }
    void clearUpdateRecords() { m_records.clear(); }
    using RecordCallback = std::function<void(const UpdateRecord&)>;
    void setRecordCallback(RecordCallback callback) { m_recordCallback = std::move(callback); }

    // [Security] Microseconds from the connection to the handshake's end (the code's hash
    // included; 0 until then, and without a code). Sealed messages dropped: forged or replayed.
    uint64_t handshakeUs() const { return m_handshakeUs; }
    bool sealed() const { return m_secure.has_value(); }
    uint64_t sealedDropped() const { return m_sealedDropped; }

    // [Test hooks] Sends raw bytes on a channel, bypassing every check (and the seal).
    bool sendRaw(Channel channel, std::span<const uint8_t> bytes);
    // Sees every message as it goes on the wire (sealed, when the session is).
    using SendTap = std::function<void(Channel, std::span<const uint8_t>)>;
    void setSendTapForTest(SendTap tap) { m_sendTap = std::move(tap); }
    // Flips one colour bit of our DBI at (x, y): a copy the server no longer knows.
    void damagePixelForTest(int x, int y) { m_dbi.color(x, y)[0] ^= 1; }

private:
    void onEvent(const ENetEvent& ev, uint64_t nowUs);
    // Before the welcome, a Busy or Retry refusal connects again (true) instead of closing.
    bool retryAfter(uint32_t disconnectData);
    void onReceive(Channel channel, std::span<const uint8_t> data, uint64_t nowUs);
    bool handleMessage(std::span<const uint8_t> data, uint64_t nowUs);
    // Every server message that could not be used ends here: counted, and when the session cannot
    // go without it (essential), the connection closes at once with serverFaultText.
    void dropMalformed(uint8_t type, size_t bytes);
    std::optional<MessageType> essential(uint8_t type) const;
    // What a handler knew of the message it dropped (reset before each message).
    struct Dropped {
        const char* why = nullptr; // what was wrong; null: it did not decode
        std::optional<bool> full;  // [image, volume] it decoded: whether it was a full one
    };
    bool reject(const char* why) {
        m_dropped.why = why;
        return false;
    }
    // Whether the picture waits for a full image (a view, a switch to DBI) or a full volume.
    bool waitingForImage() const {
        return m_wantSync == Sync::Dbi && (m_sync != Sync::Dbi || !hasFullImage());
    }
    bool waitingForVolume() const {
        return m_wantSync == Sync::Volume && (m_sync != Sync::Volume || !m_volume);
    }
    // The handshake's steps (docs/security.md), then the hello once it may go.
    bool onHandshake(std::span<const uint8_t> data);
    void sayHello();
    void sendHandshake(Handshake m);
    // One per message type, each decoding its message; false for a malformed or rejected one.
    bool onWelcome(std::span<const uint8_t> data, uint64_t nowUs);
    bool onViewRefused(std::span<const uint8_t> data);
    void forgetRefusedRequests();
    void takeLocalView(uint32_t id, const ViewSpec& view);
    uint32_t resyncRequest();
    bool onScene(std::span<const uint8_t> data);
    bool onParticipantView(std::span<const uint8_t> data);
    bool onParticipants(std::span<const uint8_t> data);
    bool onAnnotations(std::span<const uint8_t> data);
    bool onToolRelay(std::span<const uint8_t> data);
    bool onImageUpdate(std::span<const uint8_t> data, uint64_t nowUs);
    bool onVolumeUpdate(std::span<const uint8_t> data, uint64_t nowUs);
    bool onHapticModel(std::span<const uint8_t> data, uint64_t nowUs);
    bool onHapticRelay(std::span<const uint8_t> data, uint64_t nowUs);
    bool onPong(std::span<const uint8_t> data, uint64_t nowUs);
    bool onSafetyWarning(std::span<const uint8_t> data);      // session_client_assessment.cpp
    bool onAssessmentSnapshot(std::span<const uint8_t> data); // session_client_assessment.cpp
    bool onReplayState(std::span<const uint8_t> data, uint64_t nowUs); // session_client_replay.cpp
    bool onCodes(std::span<const uint8_t> data);                       // session_client_codes.cpp
    bool applyImage(const ImageUpdate& u, uint64_t nowUs);
    bool lossyApplies(const ImageUpdate& u);
    void acknowledgeImage(uint32_t sequence, uint32_t unusable = 0);
    // u's pixels into `patch`; false when they do not decode. `stale`: nothing to show (a
    // predicted update coded against pixels other than ours: asks for the whole view again).
    bool decodeImagePatch(const ImageUpdate& u, const ViewSpec& view, bool switching, Dbi& patch,
                          bool& stale);
    // An applied image's figures (statistics, its UpdateRecord).
    void recordImage(const ImageUpdate& u, uint64_t startUs, uint64_t nowUs);
    bool applyVolume(const VolumeUpdate& u, uint64_t nowUs);
    // A full update's volume in place of ours (the renderer keeps its address); a box's voxels
    // into ours, gridUs the renderer's brick-grid update. False when they do not decode.
    bool placeFullVolume(const VolumeUpdate& u);
    bool placeVolumeBox(const VolumeUpdate& u, const Box3i& box, double& gridUs);
    // Volume sync from the full volume (or the switch's) on: a view asked for is ours at once.
    void enterVolumeSync();
    // Volume mode: the whole view rendered from the local volume into m_dbi.
    void renderLocal();
    void record(UpdateRecord r);
    double transmitUs(uint64_t sentServerUs, uint64_t receivedUs) const;
    void send(Channel ch, const std::vector<uint8_t>& bytes);

    ClientConfig m_config;
    Host m_host;
    ENetPeer* m_peer = nullptr;
    bool m_connected = false;
    bool m_closed = false;
    uint32_t m_closeCode = 0;
    uint64_t m_lastHeardUs = 0;
    uint32_t m_lastReceiveTime = 0; // ENet's stamp of the peer's last datagram (ms, its clock)
    std::string m_closeReason;
    ENetAddress m_address{}; // the server's, for a retry after Busy
    uint32_t m_busyRefusals = 0;
    uint32_t m_cookieRetries = 0; // connections again with the server's cookie (Retry)
    uint64_t m_retryAtUs = 0;     // when to connect again after Busy (0: not waiting)
    std::string m_serverName;     // how failure texts name the server
    std::optional<ServerFault> m_fault;
    Dropped m_dropped;
    uint64_t m_malformedImages = 0;
    std::optional<Welcome> m_welcome;
    std::shared_ptr<const ReceivedScene> m_scene;
    uint64_t m_scenes = 0;

    ViewSpec m_view; // the view the DBI holds
    uint32_t m_viewId = 0;
    std::map<uint32_t, ViewSpec> m_requested; // views asked for, not yet received in full
    // [Volume sync] views taken at once and sent, the one the server held before them first: a
    // refused one gives way to the newest left. The newest few (older ones are superseded).
    static constexpr size_t kVolumeViewsKept = 16;
    std::map<uint32_t, ViewSpec> m_volumeViews;
    uint32_t m_requestedViewId = 0;
    uint32_t m_nextRequestId = 1;
    Dbi m_dbi;
    bool m_hasFull = false;
    std::optional<uint32_t> m_exactViewId; // the view of the last exact full image applied

    std::map<uint16_t, ToolState> m_others;
    std::map<uint16_t, ParticipantInfo> m_participants;
    // Volume updates that arrived before the welcome (another channel may overtake it), applied
    // when it comes; at most this many, of at most this many payload bytes in all.
    static constexpr size_t kMaxEarlyVolumeUpdates = 8;
    static constexpr size_t kMaxEarlyVolumeBytes = 2 * kMaxPayloadBytes;
    std::vector<VolumeUpdate> m_earlyVolume;
    size_t m_earlyVolumeBytes = 0;
    uint64_t m_rosters = 0;
    std::vector<AnnotationInfo> m_annotations;
    uint64_t m_annotationLists = 0;
    std::map<uint16_t, SafetyWarning> m_warnings;
    std::deque<SafetyWarning> m_warningLog;
    uint64_t m_warningsReceived = 0;
    AssessmentSnapshot m_assessment;
    uint64_t m_snapshots = 0;
    std::optional<ReplayState> m_replay;
    std::optional<Codes> m_codes;
    MessageStore m_newest;
    uint64_t m_replayReceivedUs = 0;
    // Whether relays of `id` are kept: everyone until the first roster, then whom it lists (a relay
    // on the tool or haptic channel can trail the reliable roster that dropped its sender).
    bool listed(uint16_t id) const { return m_rosters == 0 || m_participants.count(id) > 0; }
    uint32_t m_toolSequence = 0;
    uint32_t m_lastSequence = 0;
    HapticCallback m_hapticCallback;
    RelayCallback m_relayCallback;
    std::map<uint16_t, HapticModel> m_relayedModels;
    uint64_t m_hapticRelays = 0;
    UpdateCallback m_updateCallback;
    VolumeCallback m_volumeCallback;
    RecordCallback m_recordCallback;
    std::deque<UpdateRecord> m_records;
    Sync m_sync = Sync::Dbi, m_wantSync = Sync::Dbi;
    // The newest update sequence applied in each mode: a switch accepts only a full update newer
    // than everything of the mode it leaves (the two channels are not ordered with each other).
    std::optional<uint32_t> m_lastImageSeq, m_lastVolumeSeq; // of the last update applied
    // The sequence of the full image of m_viewId we hold: lossy rectangles apply on it only.
    uint32_t m_fullSequence = 0;
    uint64_t m_lossyIgnored = 0, m_acksSent = 0;
    std::unique_ptr<Volume> m_volume;
    std::unique_ptr<ThreadPool> m_pool;
    std::unique_ptr<Renderer> m_renderer;
    HitCache m_hitCache; // the local view's first hits (volume mode, renderLocally)
    std::shared_mutex* m_volumeMutex = nullptr;
    uint64_t m_volumeUpdates = 0;
    std::optional<HapticModel> m_latestHaptic;
    uint64_t m_hapticModels = 0;
    uint64_t m_resyncs = 0, m_predicted = 0;
    // The view request a base mismatch made, until a full image of it (or of a newer one) comes.
    std::optional<uint32_t> m_resyncRequestId;
    uint64_t m_relays = 0, m_updatesApplied = 0, m_fullUpdates = 0, m_rejected = 0, m_toolSent = 0;
    uint64_t m_viewsRefused = 0;
    std::optional<ViewRefusal> m_viewRefusal;
    uint16_t m_viewAs = 0;
    uint64_t m_participantViews = 0;
    NetStats m_stats;
    std::string m_code; // normalised; empty: none
    std::optional<SpakeClient> m_spake;
    std::optional<SecureChannel> m_secure;
    uint64_t m_connectedUs = 0, m_handshakeUs = 0, m_sealedDropped = 0;
    uint32_t m_localRefusal = 0; // why we closed ourselves (RefuseReason data), 0: we did not
    SendTap m_sendTap;
};

} // namespace trephine::net

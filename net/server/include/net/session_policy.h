// The session server's policy: who is in the session and what they may do. Hello and welcome,
// roles, the roster, the instructors' marks, take-overs, the haptic answer and its relays, the
// malformed-input rule, and pacing. It owns no socket and reads no clock: the server's network
// thread drives it with connect / receive / disconnect / update and the time, and it answers
// with what to send, whom to send away and what the simulation must do (PolicyOutput). Tests
// drive it the same way, in one thread.
#pragma once

#include "libsim/force_model.h"
#include "libsim/volume.h"
#include "net/budgets.h"
#include "net/enet_host.h"
#include "net/events.h"
#include "net/protocol.h"
#include "net/replay_protocol.h"
#include "net/server_config.h"
#include "net/server_report.h"
#include "net/session_codes.h"
#include "net/view_follow.h"

#include <atomic>
#include <cstdint>
#include <functional>
#include <map>
#include <optional>
#include <set>
#include <span>
#include <vector>

namespace trephine::net {

// The one pacing rule: something that changes as fast as a peer can send goes out at most once
// every `intervalUs`, as its latest state; an urgent change goes at the next pass. It paces the
// roster, the marks and each peer's mode switches.
class Pacer {
public:
    explicit Pacer(uint64_t intervalUs) : m_intervalUs(intervalUs) {}
    void mark(bool urgent = false) {
        m_pending = true;
        m_urgent = m_urgent || urgent;
    }
    // True (and counted as gone) when it should go at time `now`.
    bool due(uint64_t now) {
        if (!m_pending || (!m_urgent && m_sent && now - m_sentUs < m_intervalUs))
            return false;
        m_pending = m_urgent = false;
        m_sent = true;
        m_sentUs = now;
        return true;
    }
    bool pending() const { return m_pending; }
    // When a pending mark is due (0: at once).
    uint64_t dueAtUs() const { return m_urgent || !m_sent ? 0 : m_sentUs + m_intervalUs; }
    void cancel() { m_pending = m_urgent = false; }

private:
    uint64_t m_intervalUs;
    bool m_pending = false, m_urgent = false, m_sent = false;
    uint64_t m_sentUs = 0;
};

// What the policy asks of the server after one call, in order.
struct PolicyOutput {
    struct Message {
        std::vector<uint16_t> to;
        Channel channel = Channel::Control;
        std::vector<uint8_t> bytes;
    };
    struct Disconnect {
        uint16_t client = 0;
        uint32_t data = 0; // the RefuseReason (with the protocol version for Version)
    };
    std::vector<Message> messages;
    std::vector<Disconnect> disconnects;
    // For the simulation, in order (time 0: stamped when the server queues them).
    std::vector<LogRecord> events;
    // What the policy decided (names and roles, marks, take-overs), for the session log: the
    // server writes it, and the events, before it sends the messages (net/session_log.h).
    std::vector<LogRecord> log;
    bool flush = false;     // send at once (a haptic answer), not at the next service
    bool malformed = false; // the message received was malformed (counted by the server)
    // An instructor's Remove (net/session_gate.h keeps them): whom it removed (also in
    // disconnects), and whether it let the removed join again.
    std::vector<uint16_t> removed;
    bool allowRejoin = false;
    // [Codes] Instructors' requests for new codes (net/session_codes.h: issueCodes).
    std::vector<CodeRequest> newCodes;
    // [Replay] Windows' timeline controls, for the server's ReplayPlayer (net/replay_feed.h).
    std::vector<ReplayControl> replayControls;
    // Clients' acknowledgements of lossy images, for the outbox (Outbox::acknowledge).
    std::vector<std::pair<uint16_t, ImageAck>> imageAcks;
};

class SessionPolicy {
public:
    // The force at a tool state's pose, as the server computes it (on the volume, under its
    // voxel lock), with when it was done and how long it took.
    struct ForceAnswer {
        ForceResult force;
        uint64_t doneUs = 0;
        uint64_t computeUs = 0;
    };
    using ForceFn = std::function<ForceAnswer(const ToolState&, glm::vec3 velocity)>;

    // `dims` and `spacing` are the volume's, for the welcome.
    SessionPolicy(const ServerConfig& config, glm::ivec3 dims, glm::vec3 spacing, ReportBook& book,
                  ForceFn force);

    // A new connection with ENet's connect data: its id, or 0 when refused (the output then says
    // why in a disconnect of client 0).
    uint16_t connect(uint32_t connectData, uint64_t now, PolicyOutput& out);
    // A message from client `id` (one that has connected and was not sent away).
    PolicyOutput receive(uint16_t id, std::span<const uint8_t> message, uint64_t now);
    // A message from `id` dropped before it was read (forged, replayed: net/session_gate.h):
    // counted as malformed, under the same limit.
    PolicyOutput reject(uint16_t id, uint64_t now);
    // Client `id` proved the code of `role`: its hello's role is replaced by it.
    void authenticate(uint16_t id, Role role);
    void disconnect(uint16_t id, uint64_t now, PolicyOutput& out);
    // Time passes: hello timeouts, and whatever paced message is due.
    void update(uint64_t now, PolicyOutput& out);
    // The gate refused `id` (a wrong code, a removed address): sent away with `data`.
    void refuse(uint16_t id, uint32_t data, uint64_t now, PolicyOutput& out);
    // A volume client whose whole volume fits no message: sent away, saying why.
    void refuseVolume(uint16_t id, uint64_t now, PolicyOutput& out);
    // The server stops: everyone is told so and counts as gone from `now`.
    void goodbye(uint64_t now, PolicyOutput& out);
    // [Replay] Records of a session log played into this live session as their participants
    // did them (`trephine replay --serve`, net/replay_feed.h): the recorded participants are
    // listed in the roster under replayedId(), their tools drilled by the simulation and relayed
    // to everyone (each one's newest state of the batch: a seek's thousands are not sent), their
    // marks and take-overs applied. Defined in replay_feed.cpp.
    void replayed(std::span<const LogRecord> records, uint64_t now, PolicyOutput& out);
    // [Replay] Back to the log's start before records are played again (a seek backwards): the
    // recorded participants leave the simulation and the roster, their take-overs end, the marks
    // are the log's starting ones again (the watchers' own stay). The server rewrites the voxels.
    void rewindReplay(PolicyOutput& out);
    // [Replay] The timeline now, sent to every participant and to each newcomer at its welcome.
    void replayState(ReplayState state, PolicyOutput& out);
    // The id a recorded client plays under: above the ids connect() gives while fewer than
    // 32768 have joined (connect() skips one in use either way).
    static uint16_t replayedId(uint16_t recorded) { return uint16_t(0x8000u | recorded); }

    // [Codes] The gate issued `code` for `role`: every instructor is sent the session's codes.
    // Defined in session_codes.cpp.
    void codeIssued(Role role, const std::string& code, PolicyOutput& out);

    // Connected and not sent away: its updates are still wanted.
    bool live(uint16_t id) const;
    // Admitted into the session (its hello accepted) and not sent away: it holds one of the
    // maxClients places; until then it holds one of the admission's waiting slots.
    bool admitted(uint16_t id) const;
    // The gate holds `id`'s code offer for its turn (SessionGate::held): its hello is not late,
    // and the hello timeout counts from `now` on.
    void holdHelloClock(uint16_t id, uint64_t now);
    size_t peerCount() const { return m_peers.size(); }
    // Bytes of client `id`'s updates that ENet still holds (Host::send counts into it).
    Host::InFlight inFlight(uint16_t id) const;
    // [Any thread] A mode switch waits for its interval: the simulation has work to come.
    bool switchWaiting() const { return m_switchesWaiting.load() > 0; }
    const std::map<uint32_t, AnnotationInfo>& marks() const { return m_marks; }
    const std::shared_ptr<const Scene>& scene() const { return m_config.scene; }

private:
    struct Peer {
        bool hello = false;
        Hello helloMsg;
        Sync sync = Sync::Dbi;          // the hello's, then the latest SyncMode
        Codec volumeCodec = Codec::Lz4; // likewise
        Host::InFlight inFlight = std::make_shared<std::atomic<int64_t>>(0);
        int malformed = 0;
        bool kicked = false;
        uint64_t connectedUs = 0;
        Pacer modeSwitch{kSyncSwitchIntervalUs}; // each switch to volume encodes the volume
        VelocityEstimate toolVelocity;           // from its tool states' positions and times
        uint8_t colour = 0;          // its participantPalette() index, given at its hello
        std::optional<Role> proven;  // the role its code proved (none: open session)
        uint64_t heardUs = 0;        // its last message (idle timeout)
        RateBudget viewPixels{0, 0}; // ServerConfig::viewPixelsPerS
        std::optional<ViewRequest> waitingView; // over budget: the newest, until it is due
        int64_t pixels = 0;                     // of its view now (maxTotalViewPixels)
    };

    bool handle(uint16_t id, Peer& p, std::span<const uint8_t> data, uint64_t now,
                PolicyOutput& out);
    bool hello(uint16_t id, Peer& p, std::span<const uint8_t> data, uint64_t now,
               PolicyOutput& out);
    // The welcome point: what a newcomer is sent once its hello is accepted.
    void welcome(uint16_t id, uint64_t now, PolicyOutput& out);
    bool toolState(uint16_t id, Peer& p, std::span<const uint8_t> data, uint64_t now,
                   PolicyOutput& out);
    // Returns the force's magnitude (N).
    float answerHaptic(uint16_t id, Peer& p, const ToolState& t, uint64_t now, PolicyOutput& out);
    bool syncMode(uint16_t id, Peer& p, std::span<const uint8_t> data, uint64_t now,
                  PolicyOutput& out);
    bool annotate(uint16_t id, const Peer& p, std::span<const uint8_t> data, uint64_t now,
                  PolicyOutput& out);
    bool takeOver(uint16_t id, const Peer& p, std::span<const uint8_t> data, uint64_t now,
                  PolicyOutput& out);
    bool handLink(uint16_t id, const Peer& p, std::span<const uint8_t> data);
    void kick(uint16_t id, Peer& p, RefuseReason why, PolicyOutput& out, uint64_t now);
    void replayOne(const LogRecord& r, uint64_t now, PolicyOutput& out,
                   std::map<uint16_t, ToolState>& tools);
    void replayMark(const MarkEvent& e);
    void replayResume(PolicyOutput& out);
    void replayedLeave(PolicyOutput& out);
    bool remove(uint16_t id, const Peer& p, std::span<const uint8_t> data, uint64_t now,
                PolicyOutput& out);
    // [Codes] session_codes.cpp: an instructor's request, and the codes sent to `to` (nothing in
    // an open session).
    bool codes(uint16_t id, const Peer& p, std::span<const uint8_t> data, PolicyOutput& out);
    void sendCodes(std::vector<uint16_t> to, PolicyOutput& out) const;
    void countMalformed(uint16_t id, Peer& p, PolicyOutput& out, uint64_t now);
    void pushSwitch(uint16_t id, Peer& p, uint64_t now, PolicyOutput& out);

    // Participants (said hello, not sent away) other than `except`, with `role` when given.
    std::vector<uint16_t> participants(uint16_t except = 0, const Role* role = nullptr) const;
    std::vector<uint8_t> rosterMessage() const;
    std::vector<uint8_t> marksMessage() const;
    HandLinks handLinksInForce() const;
    bool mayCut(uint16_t id, Role role) const;
    bool releaseTakeOvers(uint16_t id);
    bool viewTooLarge(const ViewSpec& v) const;
    // [Availability] availability.cpp: admission counts, idle timeouts, the view budget.
    size_t admittedCount() const;
    int64_t freeViewPixels(uint16_t id) const;
    bool overViewTotal(uint16_t id, const ViewSpec& v) const;
    // A view request over the total: answered (ViewRefused), counted; the peer keeps its view.
    void refuseView(uint16_t id, uint32_t requestId, PolicyOutput& out);
    void applyView(uint16_t id, Peer& p, const ViewRequest& r, PolicyOutput& out);
    bool viewRequest(uint16_t id, Peer& p, const ViewRequest& r, uint64_t now, PolicyOutput& out);
    void updateAvailability(uint64_t now, PolicyOutput& out);
    // update walks every peer no later than `us` (a timeout, a deferred view or a paced switch
    // due then; 0: at its next call, as when a view grows and a waiting one may no longer fit).
    void walkBy(uint64_t us) { m_walkUs = std::min(m_walkUs, us); }
    uint64_t helloTimeoutUs() const { return uint64_t(double(m_config.helloTimeoutS) * 1e6); }
    uint64_t idleTimeoutUs() const { return uint64_t(double(m_config.idleTimeoutS) * 1e6); }
    std::string uniqueName(uint16_t id, const std::string& name);
    void countSwitches();

    ServerConfig m_config;
    glm::ivec3 m_dims;
    glm::vec3 m_spacing;
    std::vector<uint8_t> m_sceneMessage; // m_config.scene, encoded once
    ViewFollowers m_follow; // every participant's view, and the instructors viewing as one
    ReportBook& m_book;
    ForceFn m_force;
    std::map<uint16_t, Peer> m_peers; // increasing ids, as the roster wants
    uint16_t m_nextId = 1;
    std::map<uint32_t, AnnotationInfo> m_marks; // by id
    uint32_t m_nextMarkId = 1;
    std::map<uint16_t, uint16_t> m_takenOver; // trainee -> the instructor holding it
    // Each instructor's HandLink as it asked (handLinksInForce: as it holds), sent with the
    // roster while any is in force and once more when the last ends.
    std::map<uint16_t, HandLink> m_handLinks;
    bool m_handLinksListed = false;
    // Joins and leaves go out at once: the others keep a newcomer's relayed tool only once a
    // roster lists it. Design switches and take-overs are paced.
    Pacer m_roster{kRosterIntervalUs};
    Pacer m_marksOut{kAnnotationsIntervalUs};
    std::atomic<int> m_switchesWaiting{0}; // read by SessionServer::idle() on any thread
    // update's next walk over every peer: when the first timeout, deferred view or paced switch
    // it knows of falls due (walkBy), kScanPeriodUs after the last at the latest.
    uint64_t m_walkUs = 0;
    // [Replay] The recorded participants now in the session, by replayedId(); the simulation
    // clients they joined; the log's mark ids -> this session's.
    struct Replayed {
        Role role = Role::Trainee;
        std::string name;
        Sync sync = Sync::Dbi;
    };
    std::map<uint16_t, Replayed> m_replayed;
    std::set<uint16_t> m_replayJoined;
    std::map<uint32_t, uint32_t> m_replayMarks;
    std::vector<uint8_t> m_replayState; // the newest ReplayState, encoded (empty: no replay)
};

} // namespace trephine::net

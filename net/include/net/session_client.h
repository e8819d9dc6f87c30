// The session client, usable without a window: connects (protocol version in the connect data),
// says hello, holds the DBI of its view, applies image updates, keeps the others' relayed tool
// poses and its statistics. Poll-driven: the caller's thread runs poll(), so tests pump a server
// and clients in one process; the headless trainee drives it from its script loop.
#pragma once

#include "libsim/camera.h"
#include "libsim/dbi.h"
#include "net/enet_host.h"
#include "net/net_stats.h"
#include "net/protocol.h"

#include <cstdint>
#include <functional>
#include <map>
#include <optional>
#include <string>

namespace trephine::net {

struct ClientConfig {
    std::string name = "trainee";
    Role role = Role::Trainee;
    Codec codec = Codec::Lz4;
    ViewSpec view;
    uint32_t protocolVersion = kProtocolVersion; // tests connect with a wrong one
};

class SessionClient {
public:
    explicit SessionClient(ClientConfig config);
    ~SessionClient();
    SessionClient(const SessionClient&) = delete;
    SessionClient& operator=(const SessionClient&) = delete;

    // Starts connecting; progress happens in poll(). The hello goes out once connected.
    void connect(const ENetAddress& address);
    // Services the network for up to timeoutMs, handles every pending event, flushes sends.
    // Returns the number of events handled.
    int poll(uint32_t timeoutMs);
    // Graceful disconnect (waits up to timeoutMs for the server to acknowledge).
    void disconnect(uint32_t timeoutMs = 200);

    bool connected() const { return m_peer && m_connected; }
    bool welcomed() const { return m_welcome.has_value(); }
    bool closed() const { return m_closed; }
    // Why the server closed the connection (refuseReasonText), empty while connected.
    const std::string& closeReason() const { return m_closeReason; }
    const Welcome& welcome() const { return *m_welcome; }

    // The DBI of the current view (background until the first full update arrives).
    const Dbi& dbi() const { return m_dbi; }
    const ViewSpec& view() const { return m_view; }
    uint32_t viewId() const { return m_viewId; }
    // True once a full image of the current view (the latest requested one) has been applied.
    bool hasFullImage() const { return m_hasFull && m_requestedViewId == m_viewId; }

    // Sends our tool; sequence and clientTimeUs are filled in when zero. Returns the sequence.
    uint32_t sendToolState(ToolState state);
    // Asks for a new view; the DBI switches when its full image arrives. Returns the request id.
    uint32_t requestView(const ViewSpec& view);
    void sendPing();

    // The latest relayed tool of every other participant, by client id.
    const std::map<uint16_t, ToolState>& others() const { return m_others; }
    uint64_t relaysReceived() const { return m_relays; }
    uint64_t updatesApplied() const { return m_updatesApplied; }
    uint64_t fullUpdates() const { return m_fullUpdates; }
    uint64_t updatesRejected() const { return m_rejected; }
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

    // [Test hooks] Sends raw bytes on a channel, bypassing every check.
    bool sendRaw(Channel channel, std::span<const uint8_t> bytes);

private:
    void onEvent(const ENetEvent& ev);
    bool handleMessage(std::span<const uint8_t> data, uint64_t nowUs);
    bool applyImage(const ImageUpdate& u, uint64_t nowUs);
    void send(Channel ch, const std::vector<uint8_t>& bytes);

    ClientConfig m_config;
    Host m_host;
    ENetPeer* m_peer = nullptr;
    bool m_connected = false;
    bool m_closed = false;
    std::string m_closeReason;
    std::optional<Welcome> m_welcome;

    ViewSpec m_view; // the view the DBI holds
    uint32_t m_viewId = 0;
    std::map<uint32_t, ViewSpec> m_requested; // views asked for, not yet received in full
    uint32_t m_requestedViewId = 0;
    uint32_t m_nextRequestId = 1;
    Dbi m_dbi;
    bool m_hasFull = false;

    std::map<uint16_t, ToolState> m_others;
    uint32_t m_toolSequence = 0;
    uint32_t m_lastSequence = 0;
    HapticCallback m_hapticCallback;
    RelayCallback m_relayCallback;
    std::map<uint16_t, HapticModel> m_relayedModels;
    uint64_t m_hapticRelays = 0;
    UpdateCallback m_updateCallback;
    std::optional<HapticModel> m_latestHaptic;
    uint64_t m_hapticModels = 0;
    uint64_t m_relays = 0, m_updatesApplied = 0, m_fullUpdates = 0, m_rejected = 0, m_toolSent = 0;
    NetStats m_stats;
};

} // namespace trephine::net

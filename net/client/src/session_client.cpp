#include "net/session_client.h"

#include "libsim/dbi_preview.h"
#include "libsim/error.h"
#include "libsim/renderer.h"
#include "libsim/thread_pool.h"
#include "net/codec.h"
#include "net/image_delta.h"
#include "net/messages.h"
#include "net/view.h"

#include <sodium.h>

#include <cstdlib>
#include <mutex>
#include <utility>

namespace trephine::net {

std::string serverFaultText(const std::string& server, const ServerFault& fault) {
    const char* what = "message";
    switch (fault.type) {
    case MessageType::Welcome:
        what = "welcome";
        break;
    case MessageType::Scene:
        what = "scene";
        break;
    case MessageType::ImageUpdate:
        what = "image";
        break;
    case MessageType::VolumeUpdate:
        what = "volume";
        break;
    default:
        break;
    }
    return server + " sent a malformed " + what + " (" + fault.detail + ")";
}

SessionClient::SessionClient(ClientConfig config)
    : m_config(std::move(config)), m_host(Host::client()), m_view(m_config.view),
      m_dbi(m_config.view.width, m_config.view.height), m_sync(m_config.sync),
      m_wantSync(m_config.sync) {
    if (!m_config.clock)
        m_config.clock = steadyNowUs;
    if (!m_config.code.empty())
        m_code = normaliseCode(m_config.code, "--code");
}

SessionClient::~SessionClient() {
    if (connected())
        disconnect(50);
}

void SessionClient::connect(const ENetAddress& address, std::string serverName) {
    m_serverName = serverName.empty() ? formatAddress(address) : std::move(serverName);
    m_address = address;
    m_peer = m_host.connect(address, m_config.protocolVersion);
    m_lastHeardUs = m_config.clock();
    if (!m_peer)
        throw Error("cannot connect to " + formatAddress(address) + ": no free ENet peer");
}

void SessionClient::send(Channel ch, const std::vector<uint8_t>& bytes) {
    // With a code nothing leaves in the clear but the handshake.
    if (!connected() || bytes.empty() || (!m_code.empty() && !m_secure))
        return;
    const std::vector<uint8_t> sealed =
        m_secure ? m_secure->seal(ch, bytes) : std::vector<uint8_t>{};
    const std::vector<uint8_t>& wire = m_secure ? sealed : bytes;
    if (m_sendTap)
        m_sendTap(ch, wire);
    if (const size_t queued = m_host.send(m_peer, ch, wire))
        m_stats.countOut(ch, queued);
}

void SessionClient::sendHandshake(Handshake m) {
    const std::vector<uint8_t> bytes = encodeMessage(m);
    if (m_sendTap)
        m_sendTap(Channel::Control, bytes);
    if (connected() && m_host.send(m_peer, Channel::Control, bytes)) {
        m_stats.countOut(Channel::Control, bytes.size());
        m_host.flush();
    }
}

void SessionClient::remove(Remove m) {
    send(m);
}

bool SessionClient::sendRaw(Channel channel, std::span<const uint8_t> bytes) {
    // Raw bytes, unsealed: tests replay what the tap saw, or send what no code would.
    if (!connected())
        return false;
    return m_host.send(m_peer, channel, bytes) > 0;
}

int SessionClient::pump(uint64_t nowUs) {
    if (m_retryAtUs && nowUs >= m_retryAtUs) {
        m_retryAtUs = 0;
        m_peer = m_host.connect(m_address, m_config.protocolVersion);
        m_lastHeardUs = nowUs;
    }
    int n = m_host.service(0, [&](const ENetEvent& ev) { onEvent(ev, nowUs); });
    if (m_peer && m_connected) {
        // Any datagram counts as heard, a fragment of a large update too: ENet stamps the peer
        // whenever it receives (a whole message may take seconds on a slow link).
        if (m_peer->lastReceiveTime != m_lastReceiveTime) {
            m_lastReceiveTime = m_peer->lastReceiveTime;
            m_lastHeardUs = std::max(m_lastHeardUs, nowUs);
        }
        // ENet's own estimate, refreshed about every ENET_PEER_PACKET_LOSS_INTERVAL (10 s).
        m_stats.packetLoss = double(m_peer->packetLoss) / double(ENET_PEER_PACKET_LOSS_SCALE);
        m_stats.packetsLost = m_peer->packetsLost;
    }
    m_stats.tick(nowUs);
    return n;
}

void SessionClient::disconnect(uint32_t timeoutMs) {
    if (m_retryAtUs) { // waiting to connect again after Busy: it does not
        m_retryAtUs = 0;
        m_closed = true;
    }
    if (!m_peer)
        return;
    if (m_connected) {
        enet_peer_disconnect(m_peer, 0);
        uint64_t deadline = m_config.clock() + uint64_t(timeoutMs) * 1000;
        while (m_connected && m_config.clock() < deadline)
            poll(5);
    }
    if (m_connected)
        enet_peer_reset(m_peer);
    m_connected = false;
    m_closed = true;
    m_peer = nullptr;
}

void SessionClient::onEvent(const ENetEvent& ev, uint64_t nowUs) {
    switch (ev.type) {
    case ENET_EVENT_TYPE_CONNECT: {
        m_connected = true;
        m_lastHeardUs = m_connectedUs = nowUs;
        disableThrottle(m_peer);
        // Without a code the hello goes at once (an open session); with one, it goes sealed
        // after the handshake that the server's Challenge starts.
        if (m_code.empty())
            sayHello();
        return;
    }
    case ENET_EVENT_TYPE_DISCONNECT:
        if (!m_welcome && !m_localRefusal && retryAfter(ev.data))
            return;
        m_connected = false;
        m_closed = true;
        m_closeCode = m_localRefusal ? m_localRefusal : ev.data;
        m_closeReason = refuseReasonText(m_closeCode);
        m_peer = nullptr;
        return;
    case ENET_EVENT_TYPE_RECEIVE: {
        m_lastHeardUs = std::max(m_lastHeardUs, nowUs);
        const auto channel = Channel(std::min<int>(ev.channelID, int(Channel::Count) - 1));
        m_stats.countIn(channel, ev.packet->dataLength);
        onReceive(channel, {ev.packet->data, ev.packet->dataLength}, nowUs);
        // And once handled: applying a large update (a whole volume, its first render) takes
        // long, and that is no silence of the server's.
        m_lastHeardUs = m_config.clock();
        return;
    }
    default:
        return;
    }
}

bool SessionClient::retryAfter(uint32_t disconnectData) {
    const auto reason = RefuseReason(disconnectData & 0xff);
    // A Retry more than a few times in a row is a cookie that does not hold: ended as refused.
    if (reason != RefuseReason::Busy && (reason != RefuseReason::Retry || m_cookieRetries >= 3))
        return false;
    // Not joined yet, and told to come back: a fresh connection (and handshake).
    m_connected = false;
    m_peer = nullptr;
    m_spake.reset();
    m_secure.reset();
    m_closeReason = refuseReasonText(disconnectData);
    if (reason == RefuseReason::Retry) {
        ++m_cookieRetries;
        m_peer = m_host.connect(m_address, m_config.protocolVersion, disconnectData >> 8);
        m_lastHeardUs = m_config.clock();
        if (!m_peer) {
            m_closed = true;
            m_closeCode = disconnectData;
            m_closeReason = "the server asks for an admission cookie that this client's ENet "
                            "cannot send (it chooses connect IDs itself)";
        }
        return true;
    }
    // Busy: after a wait, with jitter so a class refused together does not come back together.
    m_cookieRetries = 0;
    const uint32_t waitUs = std::min(2000000u, 250000u << std::min(m_busyRefusals, 3u));
    ++m_busyRefusals;
    m_retryAtUs = m_config.clock() + waitUs / 2 + randombytes_uniform(waitUs / 2);
    return true;
}

void SessionClient::sayHello() {
    Hello h;
    h.role = m_config.role;
    h.name = m_config.name;
    h.codec = m_config.codec;
    h.sync = m_wantSync; // a switch asked for before the connection rides on the hello
    h.volumeCodec = m_config.volumeCodec;
    h.view = m_config.view;
    send(Channel::Control, encodeMessage(h));
    // A view asked for before the connection went nowhere: ask again, after the hello.
    if (!m_requested.empty()) {
        ViewRequest r;
        r.requestId = m_requested.rbegin()->first;
        r.view = m_requested.rbegin()->second;
        send(Channel::Control, encodeMessage(r));
    }
    sendPing();
}

void SessionClient::onReceive(Channel channel, std::span<const uint8_t> data, uint64_t nowUs) {
    m_dropped = {};
    if (m_secure) {
        std::vector<uint8_t> plain;
        if (m_secure->open(channel, data, plain) != SecureChannel::Opened::Ok) {
            // Forged or damaged on the way: nothing the server said, so nothing to end on.
            ++m_sealedDropped;
            m_stats.countMalformed();
        } else if (!handleMessage(plain, nowUs)) {
            dropMalformed(peekMessageType(plain), plain.size());
        }
        return;
    }
    // In the clear: the handshake, or in an open session everything. With a code anything else
    // is dropped; it cannot be the server's.
    if (peekMessageType(data) == uint8_t(MessageType::Handshake)) {
        if (!onHandshake(data))
            m_stats.countMalformed();
    } else if (!m_code.empty()) {
        m_stats.countMalformed();
    } else if (!handleMessage(data, nowUs)) {
        dropMalformed(peekMessageType(data), data.size());
    }
}

std::optional<MessageType> SessionClient::essential(uint8_t type) const {
    switch (MessageType(type)) {
    case MessageType::Welcome:
    case MessageType::Scene: // sent once: no presets, sites or field without it
        return MessageType(type);
    case MessageType::ImageUpdate:
        // The full image the picture waits for; before the first picture, one that does not
        // decode may be it. A bad rectangle of a picture shown is dropped and nothing more.
        if (m_dropped.full ? *m_dropped.full && waitingForImage()
                           : m_wantSync == Sync::Dbi && !m_hasFull)
            return MessageType::ImageUpdate;
        return std::nullopt;
    case MessageType::VolumeUpdate:
        if (waitingForVolume() && m_dropped.full.value_or(true))
            return MessageType::VolumeUpdate;
        return std::nullopt;
    default:
        // Of another type, or of none (a damaged type byte: even a welcome's), it names nothing
        // to end on; before the welcome, ClientThread's timeout says how many there were.
        return std::nullopt;
    }
}

void SessionClient::dropMalformed(uint8_t type, size_t bytes) {
    m_stats.countMalformed();
    if (type == uint8_t(MessageType::ImageUpdate))
        ++m_malformedImages;
    const std::optional<MessageType> lost = essential(type);
    if (!lost || m_fault || !m_peer)
        return;
    m_fault =
        ServerFault{*lost, m_dropped.why ? std::string(m_dropped.why)
                                         : std::to_string(bytes) + " bytes that do not decode"};
    // At once, and without waiting for the server's acknowledgement: waiting on would only end
    // in a timeout that names nothing (the headless trainee's "no image" after 30 s).
    enet_peer_disconnect_now(m_peer, 0);
    m_peer = nullptr;
    m_connected = false;
    m_closed = true;
    m_closeReason = serverFaultText(m_serverName, *m_fault);
}

bool SessionClient::onHandshake(std::span<const uint8_t> data) {
    Handshake m;
    if (!decodeMessage(data, m))
        return false;
    if (m.step == Handshake::Step::Challenge) {
        if (m_code.empty() || m_spake)
            return true; // without a code the hello went already; the server says the rest
        if (m.open) {
            // Joining with a code asks for a sealed session: not one anybody can join in the
            // clear (nor one an attacker on the path claims is open).
            m_localRefusal = uint32_t(RefuseReason::WrongCode) | uint32_t(CodeRefusal::ServerOpen)
                                                                     << 8;
            enet_peer_disconnect(m_peer, 0);
            return true;
        }
        Salt salt;
        std::copy(m.salt.begin(), m.salt.end(), salt.begin());
        m_spake.emplace(codeScalar(m_code, salt), salt, m_config.role);
        Handshake offer;
        offer.step = Handshake::Step::Offer;
        offer.role = m_config.role;
        offer.share = m_spake->share();
        sendHandshake(offer);
        return true;
    }
    if (m.step != Handshake::Step::Answer || !m_spake || m_secure)
        return false;
    // The entry whose MAC our code reproduces: the code we hold is that entry's role's.
    Handshake confirm;
    confirm.step = Handshake::Step::Confirm;
    std::optional<SessionKeys> proven;
    for (size_t i = 0; i < m.entries.size() && !proven; ++i) {
        const auto keys = m_spake->keys(m.entries[i].share, m.entries[i].role);
        if (keys && sameMac(keys->serverConfirm, m.entries[i].mac)) {
            confirm.entry = uint8_t(i);
            confirm.mac = keys->clientConfirm;
            if (m.entries[i].role == m_config.role)
                proven = keys;
        }
    }
    // Sent even when none matched, so the server names the reason and counts the attempt.
    sendHandshake(confirm);
    m_spake.reset();
    if (proven) {
        m_secure.emplace(*proven, false);
        m_handshakeUs = m_config.clock() - m_connectedUs;
        sayHello();
    }
    return true;
}

namespace {

// The handler of the server state a client keeps whole (IsStoredState): a newer one replaces it.
struct KeepNewest {
    MessageStore& store;
    std::span<const uint8_t> data;
    template <typename M>
    requires IsStoredState<M>::value bool operator()(MessageTag<M>) const {
        return store.put<M>(data);
    }
};

} // namespace

bool SessionClient::handleMessage(std::span<const uint8_t> data, uint64_t nowUs) {
    // A message only clients send, or of no type, is malformed (the table's direction).
    return dispatchReceived<Side::Client>(
        peekMessageType(data),
        Handlers{
            [&](MessageTag<Welcome>) { return onWelcome(data, nowUs); },
            [&](MessageTag<ViewRefused>) { return onViewRefused(data); },
            [&](MessageTag<Scene>) { return onScene(data); },
            [&](MessageTag<ParticipantView>) { return onParticipantView(data); },
            [&](MessageTag<Participants>) { return onParticipants(data); },
            [&](MessageTag<Annotations>) { return onAnnotations(data); },
            [&](MessageTag<ToolRelay>) { return onToolRelay(data); },
            [&](MessageTag<ImageUpdate>) { return onImageUpdate(data, nowUs); },
            [&](MessageTag<VolumeUpdate>) { return onVolumeUpdate(data, nowUs); },
            [&](MessageTag<HapticModel>) { return onHapticModel(data, nowUs); },
            [&](MessageTag<HapticRelay>) { return onHapticRelay(data, nowUs); },
            [&](MessageTag<Pong>) { return onPong(data, nowUs); },
            [&](MessageTag<SafetyWarning>) { return onSafetyWarning(data); },
            [&](MessageTag<AssessmentSnapshot>) { return onAssessmentSnapshot(data); },
            [&](MessageTag<ReplayState>) { return onReplayState(data, nowUs); },
            [&](MessageTag<Codes>) { return onCodes(data); },
            KeepNewest{m_newest, data},
            // Only in the clear, before the channel is sealed (onReceive).
            [](MessageTag<Handshake>) { return false; },
        },
        false);
}

// The server serves no more view pixels for that request: it is dropped and the view the server
// holds stays ours (in volume sync, where the view changed at once, it comes back); a resync
// waiting on it asks for that view instead.
bool SessionClient::onViewRefused(std::span<const uint8_t> data) {
    ViewRefused r;
    if (!decodeMessage(data, r))
        return false;
    std::optional<ViewSpec> refused;
    if (auto it = m_requested.find(r.requestId); it != m_requested.end()) {
        refused = it->second;
        m_requested.erase(it);
    } else if (auto v = m_volumeViews.find(r.requestId); v != m_volumeViews.end()) {
        refused = v->second;
        m_volumeViews.erase(v);
        if (r.requestId == m_viewId && !m_volumeViews.empty())
            takeLocalView(m_volumeViews.rbegin()->first, m_volumeViews.rbegin()->second);
    }
    if (!refused)
        return true; // not ours, or long superseded
    ++m_viewsRefused;
    const bool newest = r.requestId == m_requestedViewId;
    forgetRefusedRequests();
    if (m_resyncRequestId == r.requestId)
        m_resyncRequestId = resyncRequest();
    if (newest)
        m_viewRefusal = ViewRefusal{refused->width, refused->height, r.freePixels};
    return true;
}

// The request whose full image makes our copy the server's again: the newest one waiting, else a
// new one for the view held.
uint32_t SessionClient::resyncRequest() {
    return m_requested.empty() ? requestView(m_view) : m_requested.rbegin()->first;
}

// The view asked for last is the newest request still waiting, else the view held.
void SessionClient::forgetRefusedRequests() {
    if (m_requestedViewId != m_viewId && !m_requested.contains(m_requestedViewId))
        m_requestedViewId = m_requested.empty() ? m_viewId : m_requested.rbegin()->first;
}

bool SessionClient::onWelcome(std::span<const uint8_t> data, uint64_t nowUs) {
    Welcome w;
    if (!decodeMessage(data, w))
        return false;
    m_welcome = w;
    // Views asked for before the welcome could not be checked against the server's limit:
    // the server drops one too large, and we would wait for its image for good (every later
    // resync waits on the newest request too).
    const size_t before = m_requested.size();
    std::erase_if(m_requested, [&](const auto& r) {
        return int64_t(r.second.width) * int64_t(r.second.height) > w.maxViewPixels;
    });
    m_viewsRefused += before - m_requested.size();
    forgetRefusedRequests();
    // Voxels that overtook the welcome on their own channel: place them now, in order.
    for (VolumeUpdate& early : std::exchange(m_earlyVolume, {})) {
        m_dropped = {.full = early.full};
        if (!applyVolume(early, nowUs)) {
            ++m_rejected;
            dropMalformed(uint8_t(MessageType::VolumeUpdate), early.payload.size());
        }
    }
    m_dropped = {};
    m_earlyVolumeBytes = 0;
    return true;
}

bool SessionClient::onScene(std::span<const uint8_t> data) {
    auto received = std::make_shared<ReceivedScene>();
    if (!decodeScene(data, received->scene, &received->field))
        return false;
    // The scene of the welcome's volume, or none: another's dims would misplace everything.
    if (!m_welcome)
        return reject("it came before the welcome");
    if (received->scene.dims != m_welcome->volumeDims ||
        received->scene.spacing != m_welcome->spacing)
        return reject("its volume's dims or spacing differ from the welcome's");
    m_scene = std::move(received);
    ++m_scenes;
    return true;
}

bool SessionClient::onParticipantView(std::span<const uint8_t> data) {
    ParticipantView pv;
    if (!decodeMessage(data, pv))
        return false;
    ++m_participantViews;
    if (pv.clientId != m_viewAs)
        return true; // one we no longer view as
    // The participant's camera in our own window: the newest size we asked for.
    const ViewSpec& mine = viewAskedFor();
    ViewSpec v = pv.view;
    v.width = mine.width;
    v.height = mine.height;
    requestView(v);
    return true;
}

bool SessionClient::onParticipants(std::span<const uint8_t> data) {
    Participants roster;
    if (!decodeMessage(data, roster))
        return false;
    m_participants.clear();
    for (const ParticipantInfo& p : roster.list)
        m_participants[p.clientId] = p;
    // Whoever left takes their tool and force plot along.
    std::erase_if(m_others, [&](const auto& e) { return !m_participants.count(e.first); });
    std::erase_if(m_relayedModels, [&](const auto& e) { return !m_participants.count(e.first); });
    ++m_rosters;
    return true;
}

bool SessionClient::onAnnotations(std::span<const uint8_t> data) {
    Annotations marks;
    if (!decodeMessage(data, marks))
        return false;
    m_annotations = std::move(marks.list);
    ++m_annotationLists;
    return true;
}

bool SessionClient::onToolRelay(std::span<const uint8_t> data) {
    ToolRelay r;
    if (!decodeMessage(data, r))
        return false;
    ++m_relays;
    if (!listed(r.clientId))
        return true; // someone who left: counted, not drawn
    auto it = m_others.find(r.clientId);
    // Unsequenced: keep the newest.
    if (it == m_others.end() || int32_t(r.tool.sequence - it->second.sequence) > 0)
        m_others[r.clientId] = r.tool;
    return true;
}

bool SessionClient::onImageUpdate(std::span<const uint8_t> data, uint64_t nowUs) {
    ImageUpdate u;
    if (!decodeMessage(data, u))
        return false;
    m_dropped.full = u.full;
    if (!applyImage(u, nowUs)) {
        ++m_rejected;
        return false;
    }
    return true;
}

bool SessionClient::onVolumeUpdate(std::span<const uint8_t> data, uint64_t nowUs) {
    VolumeUpdate u;
    if (!decodeMessage(data, u))
        return false;
    m_dropped.full = u.full;
    if (!m_welcome) {
        // The volume channel is not ordered with the control channel: under loss a join's
        // full volume can arrive before the welcome that gives its dims. Keep a few until
        // the welcome comes (bounded: a server that floods them before welcoming is wrong).
        if (m_earlyVolume.size() >= kMaxEarlyVolumeUpdates ||
            m_earlyVolumeBytes + u.payload.size() > kMaxEarlyVolumeBytes)
            return reject("more volume updates before the welcome than a client holds");
        m_earlyVolumeBytes += u.payload.size();
        m_earlyVolume.push_back(std::move(u));
        return true;
    }
    if (!applyVolume(u, nowUs)) {
        ++m_rejected;
        return false;
    }
    return true;
}

bool SessionClient::onHapticModel(std::span<const uint8_t> data, uint64_t nowUs) {
    HapticModel m;
    if (!decodeMessage(data, m))
        return false;
    ++m_hapticModels;
    if (m.clientTimeUs > 0 && m.clientTimeUs <= nowUs)
        m_stats.hapticRoundTripUs.add(double(nowUs - m.clientTimeUs));
    if (!m_latestHaptic || int32_t(m.toolSequence - m_latestHaptic->toolSequence) > 0)
        m_latestHaptic = m;
    if (m_hapticCallback)
        m_hapticCallback(m, nowUs);
    return true;
}

bool SessionClient::onHapticRelay(std::span<const uint8_t> data, uint64_t nowUs) {
    HapticRelay r;
    if (!decodeMessage(data, r))
        return false;
    ++m_hapticRelays;
    if (!listed(r.clientId))
        return true; // someone who left: counted, not plotted
    auto it = m_relayedModels.find(r.clientId);
    if (it == m_relayedModels.end() || int32_t(r.model.toolSequence - it->second.toolSequence) > 0)
        m_relayedModels[r.clientId] = r.model;
    if (m_relayCallback)
        m_relayCallback(r.clientId, r.model, nowUs);
    return true;
}

bool SessionClient::onPong(std::span<const uint8_t> data, uint64_t nowUs) {
    Pong p;
    if (!decodeMessage(data, p) || p.clientTimeUs > nowUs)
        return false;
    double rtt = double(nowUs - p.clientTimeUs);
    m_stats.rttUs.add(rtt);
    // The ping with the smallest round trip bounds the offset best (NTP's rule).
    if (m_stats.bestRttUs < 0 || rtt < m_stats.bestRttUs) {
        m_stats.bestRttUs = rtt;
        int64_t offset = int64_t(p.serverTimeUs) - int64_t(p.clientTimeUs + uint64_t(rtt / 2));
        // The true offset lies within +-rtt/2 of the estimate; when 0 does too, take the
        // clocks as one (one machine, one CLOCK_MONOTONIC) rather than add the error.
        m_stats.clockOffsetUs = double(std::abs(offset)) <= rtt / 2 ? 0 : offset;
    }
    return true;
}

double SessionClient::transmitUs(uint64_t sentServerUs, uint64_t receivedUs) const {
    int64_t sentLocal = int64_t(sentServerUs) - m_stats.clockOffsetUs;
    if (sentServerUs == 0 || int64_t(receivedUs) < sentLocal)
        return -1;
    return double(int64_t(receivedUs) - sentLocal);
}

void SessionClient::record(UpdateRecord r) {
    m_stats.modes[size_t(r.mode)].add(r);
    m_records.push_back(r);
    while (m_records.size() > m_config.recordCapacity)
        m_records.pop_front();
    if (m_recordCallback)
        m_recordCallback(r);
}

void SessionClient::requestSync(Sync mode) {
    if (mode == m_wantSync)
        return;
    m_wantSync = mode;
    SyncMode m{mode, m_config.volumeCodec};
    send(Channel::Control, encodeMessage(m));
}

void SessionClient::renderLocal() {
    if (!m_renderer || !m_config.renderLocally)
        return;
    // With the same hit cache the DBI server keeps per view: after erosion each ray resumes at
    // its previous first hit (a view change or a rise in density restarts it). Into the picture
    // it replaces, as the server renders into its view's frame: a new 500 x 500 frame each update
    // (2 MB zeroed, then filled with background, on one thread) was counted in the baseline's
    // client render. Every pixel is written (a miss gets the background).
    const Camera camera = toCamera(m_view);
    if (m_dbi.width() == camera.width && m_dbi.height() == camera.height)
        m_renderer->render(camera, m_dbi.bounds(), m_dbi, &m_hitCache);
    else
        m_dbi = m_renderer->render(camera, &m_hitCache);
}

namespace {
// Whether `sequence` is no newer than `last` (wrapping compare); never, when nothing was received:
// any sequence is new then, whatever the server's counter (even past 2^31).
bool notNewer(uint32_t sequence, std::optional<uint32_t> last) {
    return last && int32_t(sequence - *last) <= 0;
}
} // namespace

bool SessionClient::applyVolume(const VolumeUpdate& u, uint64_t nowUs) {
    uint64_t start = m_config.clock();
    double gridUs = -1; // the renderer's brick-grid update, part of the apply
    if (!m_welcome)
        return reject("it came before the welcome"); // we cannot place its voxels
    const glm::ivec3 dims = m_welcome->volumeDims;
    const Box3i box{{u.x, u.y, u.z}, {u.x + u.sizeX, u.y + u.sizeY, u.z + u.sizeZ}};
    if (box.hi.x > dims.x || box.hi.y > dims.y || box.hi.z > dims.z)
        return reject("its box leaves the welcome's volume");
    if (u.full && !(box == Box3i{glm::ivec3(0), dims}))
        return reject("a full volume that is not the welcome's whole volume");
    // Not wanted (a DBI client, or one that switched away): stale, not malformed.
    if (m_wantSync != Sync::Volume)
        return true;
    const bool switching = m_sync != Sync::Volume;
    if (switching && (!u.full || notNewer(u.sequence, m_lastImageSeq)))
        return true; // from an earlier volume period; the switch waits for its full volume
    if (!u.full && !m_volume)
        return true;
    if (u.full ? !placeFullVolume(u) : !placeVolumeBox(u, box, gridUs))
        return false;
    if (switching || u.full)
        enterVolumeSync();
    const uint64_t applied = m_config.clock();
    renderLocal();
    const uint64_t done = m_config.clock();

    m_lastVolumeSeq = u.sequence;
    m_lastSequence = u.sequence;
    ++m_updatesApplied;
    ++m_volumeUpdates;
    if (u.full)
        ++m_fullUpdates;
    UpdateRecord r;
    r.mode = Sync::Volume;
    r.sequence = u.sequence;
    r.full = u.full;
    r.bytes = uint32_t(u.payload.size());
    r.rawBytes = u.rawBytes;
    r.box = box.size();
    r.erodeUs = u.full ? -1 : double(u.erodeUs);
    r.serverRenderUs = 0;
    r.encodeUs = double(u.encodeUs);
    r.transmitUs = transmitUs(u.sentServerUs, nowUs);
    r.applyUs = double(applied - start);
    r.clientRenderUs = m_renderer && m_config.renderLocally ? double(done - applied) : -1;
    r.gridUs = gridUs;
    int64_t causeLocal = int64_t(u.causeServerUs) - m_stats.clockOffsetUs;
    if (causeLocal > 0 && int64_t(done) >= causeLocal)
        r.latencyUs = double(int64_t(done) - causeLocal);
    r.appliedUs = done;
    m_stats.updateBytes.add(double(r.bytes));
    m_stats.updateRawBytes.add(double(r.rawBytes));
    m_stats.applyUs.add(r.applyUs);
    if (!u.full && r.latencyUs >= 0)
        m_stats.updateLatencyUs.add(r.latencyUs);
    record(r);
    if (m_volumeCallback)
        m_volumeCallback(u, box, u.full);
    return true;
}

bool SessionClient::placeFullVolume(const VolumeUpdate& u) {
    Volume v;
    if (!decodeVolumeFull(u.payload, u.rawBytes, u.codec, m_welcome->volumeDims, m_welcome->spacing,
                          v))
        return reject("its voxels do not decode");
    std::unique_lock<std::shared_mutex> lock;
    if (m_volumeMutex)
        lock = std::unique_lock(*m_volumeMutex);
    if (m_volume)
        *m_volume = std::move(v); // same address: the renderer keeps pointing at it
    else
        m_volume = std::make_unique<Volume>(std::move(v));
    // The renderer only reads the volume, and this thread is its only writer: its brick
    // grid is built after the exclusive lock is let go, so a haptic thread reading the
    // volume waits for the copy only (a 256^3 grid build took 8.7 ms, eight haptic ticks).
    lock = {};
    if (m_renderer)
        m_renderer->rebuild();
    if (!m_renderer && m_config.renderLocally) {
        if (!m_pool)
            m_pool = std::make_unique<ThreadPool>(m_config.renderThreads);
        m_renderer = std::make_unique<Renderer>(*m_volume, m_pool.get());
    }
    return true;
}

bool SessionClient::placeVolumeBox(const VolumeUpdate& u, const Box3i& box, double& gridUs) {
    std::vector<uint8_t> voxels;
    if (!decompressBytes(u.payload, u.codec, u.rawBytes, voxels))
        return reject("its voxels do not decode");
    const size_t n = size_t(box.count());
    std::span<const uint8_t> densities(voxels.data(), n), materials;
    if (u.materials)
        materials = std::span<const uint8_t>(voxels.data() + n, n);
    std::unique_lock<std::shared_mutex> lock;
    if (m_volumeMutex)
        lock = std::unique_lock(*m_volumeMutex);
    if (!applyVolumeBox(*m_volume, box, densities, materials))
        return reject("its voxels do not fill its box");
    lock = {};
    if (m_renderer) {
        const uint64_t g0 = m_config.clock();
        // Boxes with their materials are voxels the server wrote wholesale (submitVoxels),
        // which may raise densities: the hit cache's indices may then be too deep, so the
        // renderer starts afresh, as the server's does. Drilling (densities only fall) keeps
        // the cache.
        if (u.materials)
            m_renderer->rebuild();
        else
            m_renderer->volumeChanged(box);
        gridUs = double(m_config.clock() - g0);
    }
    return true;
}

void SessionClient::enterVolumeSync() {
    m_sync = Sync::Volume;
    m_volumeViews.clear();
    // A view asked for while the DBI was shown is ours at once now: we render it.
    if (!m_requested.empty()) {
        m_view = m_requested.rbegin()->second;
        m_viewId = m_requested.rbegin()->first;
        m_requested.clear();
    }
    m_requestedViewId = m_viewId;
    m_resyncRequestId.reset(); // the next DBI is a full one
    if (!m_config.renderLocally &&
        (m_dbi.width() != m_view.width || m_dbi.height() != m_view.height))
        m_dbi = Dbi(m_view.width, m_view.height);
    m_hasFull = true;
    m_exactViewId = m_viewId; // rendered here
}

bool SessionClient::applyImage(const ImageUpdate& u, uint64_t nowUs) {
    uint64_t start = m_config.clock();
    // In volume mode images are stale, unless we are switching back and this is the full image
    // the server sent after the switch (newer than every volume update applied).
    const bool leavingVolume = m_sync == Sync::Volume;
    if (leavingVolume &&
        (m_wantSync != Sync::Dbi || !u.full || notNewer(u.sequence, m_lastVolumeSeq)))
        return true;
    // Which view does it belong to? Updates of a view we have left are stale, not malformed.
    const ViewSpec* view = nullptr;
    bool switching = false;
    if (u.viewId == m_viewId) {
        view = &m_view;
    } else if (auto it = m_requested.find(u.viewId); it != m_requested.end()) {
        if (!u.full)
            return true; // partial update of a view whose full image has not come yet
        view = &it->second;
        switching = true;
    } else {
        return true;
    }
    if (u.fullSequence != 0 && !lossyApplies(u))
        return true;
    // A full image re-sent after its acknowledgement was lost: newer rectangles may be applied
    // on it, which it would roll back. Acknowledged again.
    if (u.full && !switching && m_hasFull && notNewer(u.sequence, m_lastImageSeq)) {
        ++m_lossyIgnored;
        acknowledgeImage(*m_lastImageSeq);
        return true;
    }
    if (u.x + u.width > view->width || u.y + u.height > view->height)
        return reject("its rectangle leaves the view");
    // A preview is the view at half size (previewCamera), each pixel a 2 x 2 block of it.
    const Camera whole = u.preview ? previewCamera(toCamera(*view)) : toCamera(*view);
    if (u.full && (u.x != 0 || u.y != 0 || u.width != whole.width || u.height != whole.height))
        return reject("a full image that is not the whole view");
    Dbi patch;
    bool stale = false;
    if (!decodeImagePatch(u, *view, switching, patch, stale))
        return false;
    if (stale)
        return true;
    if (u.preview) {
        Dbi blocks(view->width, view->height);
        upsampleRows(patch, 0, patch.height(), blocks);
        patch = std::move(blocks);
    }
    if (switching) {
        m_view = *view;
        m_viewId = u.viewId;
        m_dbi = Dbi(m_view.width, m_view.height);
        // Requests older than this one will never be shown.
        std::erase_if(m_requested, [&](const auto& r) { return int32_t(r.first - u.viewId) <= 0; });
    }
    if (leavingVolume) {
        m_sync = Sync::Dbi;
        std::unique_lock<std::shared_mutex> lock;
        if (m_volumeMutex)
            lock = std::unique_lock(*m_volumeMutex);
        m_renderer.reset();
        m_volume.reset();
    }
    m_dbi.apply(patch, u.x, u.y);
    m_lastSequence = u.sequence;
    m_lastImageSeq = u.sequence;
    ++m_updatesApplied;
    if (u.full || u.fullSequence != 0)
        acknowledgeImage(u.sequence);
    if (u.full) {
        ++m_fullUpdates;
        m_fullSequence = u.sequence;
        if (u.viewId == m_viewId)
            m_hasFull = true;
        if (!u.preview)
            m_exactViewId = u.viewId;
        // The resync's answer, or a newer request's (the server may replace an unsent full
        // image by a newer view's): our copy is the server's again.
        if (m_resyncRequestId && int32_t(u.viewId - *m_resyncRequestId) >= 0)
            m_resyncRequestId.reset();
    }
    recordImage(u, start, nowUs);
    if (m_updateCallback)
        m_updateCallback(u, PixelRect{u.x, u.y, patch.width(), patch.height()}, u.full);
    return true;
}

// A rectangle after a full image (of the view we show) applies only on the full image it names,
// only when newer than every image applied (the image and lossy channels are not ordered with
// each other, and a late one would roll pixels back), and, chained, only on the image it builds
// on. A repeat is the server's repair of a rectangle whose acknowledgement was lost: acknowledged
// again, not applied. A chained one on an image we lack tells the server one was lost.
bool SessionClient::lossyApplies(const ImageUpdate& u) {
    if (u.fullSequence != m_fullSequence || !m_hasFull) {
        ++m_lossyIgnored;
        return false;
    }
    if (notNewer(u.sequence, m_lastImageSeq)) {
        ++m_lossyIgnored;
        acknowledgeImage(*m_lastImageSeq);
        return false;
    }
    if (u.baseSequence != 0 && u.baseSequence != m_lastImageSeq) {
        ++m_lossyIgnored;
        acknowledgeImage(*m_lastImageSeq, u.sequence);
        return false;
    }
    return true;
}

void SessionClient::acknowledgeImage(uint32_t sequence, uint32_t unusable) {
    if (!connected())
        return;
    send(ImageAck{m_viewId, sequence, unusable,
                  uint16_t(std::min<uint32_t>(m_host.lossPermille(m_peer), 1000))});
    // At once: the server times its round trip from it and repairs a reported loss from it, and
    // until it arrives it keeps the rectangle for self-contained ones to carry.
    m_host.flush();
    ++m_acksSent;
}

bool SessionClient::decodeImagePatch(const ImageUpdate& u, const ViewSpec& view, bool switching,
                                     Dbi& patch, bool& stale) {
    const Camera camera = u.preview ? previewCamera(toCamera(view)) : toCamera(view);
    if (!u.predicted) {
        if (!decodeImage(u.payload, u.rawBytes, u.codec, u.width, u.height, camera, patch))
            return reject("its pixels do not decode");
        return true;
    }
    // Coded against the pixels we hold there: only for the view we show, never a switch.
    stale = switching || m_dbi.width() != view.width || m_dbi.height() != view.height;
    if (stale)
        return true; // a full image of the right view is on its way
    const PixelRect rect{u.x, u.y, u.width, u.height};
    patch = m_dbi.extract(rect);
    PredictedStatus st =
        decodePredicted(u.payload, u.rawBytes, u.codec, u.baseHash, DepthQuantizer(camera), patch);
    if (st == PredictedStatus::Malformed)
        return reject("its pixels do not decode");
    if (st == PredictedStatus::Ok)
        ++m_predicted;
    if (st == PredictedStatus::BaseMismatch) {
        // Our copy is not what the server coded against: never show a wrong picture; ask for the
        // whole view again (the server answers with a full image). While a view change is
        // pending, its full image is already on its way and replaces our copy: wait for that
        // one (a request for the old view would supersede it and bring the old view back; one
        // for the pending view again would cost a second full image). Once asked, the updates
        // coded against the same stale copy until that full image comes need no request of
        // their own.
        ++m_resyncs;
        if (!m_resyncRequestId)
            m_resyncRequestId = resyncRequest();
        stale = true;
    }
    return true;
}

void SessionClient::recordImage(const ImageUpdate& u, uint64_t startUs, uint64_t nowUs) {
    m_stats.updateBytes.add(double(u.payload.size()));
    m_stats.updateRawBytes.add(double(u.rawBytes));
    uint64_t applied = m_config.clock();
    m_stats.applyUs.add(double(applied - startUs));
    // Server clock -> ours with the ping offset (0 on one machine: one monotonic clock).
    int64_t causeLocal = int64_t(u.causeServerUs) - m_stats.clockOffsetUs;
    if (!u.full && causeLocal > 0 && int64_t(applied) >= causeLocal)
        m_stats.updateLatencyUs.add(double(int64_t(applied) - causeLocal));
    UpdateRecord r;
    r.mode = Sync::Dbi;
    r.sequence = u.sequence;
    r.full = u.full;
    r.bytes = uint32_t(u.payload.size());
    r.rawBytes = u.rawBytes;
    r.box = {u.width, u.height, 1};
    r.erodeUs = u.full ? -1 : double(u.erodeUs);
    r.serverRenderUs = u.full ? -1 : double(u.renderUs);
    r.gridUs = u.full ? -1 : double(u.gridUs);
    r.encodeUs = double(u.encodeUs);
    r.transmitUs = transmitUs(u.sentServerUs, nowUs);
    r.applyUs = double(applied - startUs);
    r.clientRenderUs = 0; // the rectangle is the picture: nothing to render
    if (causeLocal > 0 && int64_t(applied) >= causeLocal)
        r.latencyUs = double(int64_t(applied) - causeLocal);
    r.appliedUs = applied;
    record(r);
}

uint32_t SessionClient::sendToolState(ToolState state) {
    if (state.sequence == 0)
        state.sequence = ++m_toolSequence;
    if (state.clientTimeUs == 0)
        state.clientTimeUs = m_config.clock();
    send(Channel::ToolState, encodeMessage(state));
    ++m_toolSent;
    return state.sequence;
}

uint32_t SessionClient::requestView(const ViewSpec& view) {
    // The server would drop it and we would wait for its image for good (in volume mode, show a
    // view the server does not know, so a switch to DBI would never complete).
    if (m_welcome && int64_t(view.width) * int64_t(view.height) > m_welcome->maxViewPixels) {
        ++m_viewsRefused;
        return 0;
    }
    ViewRequest r;
    r.requestId = m_nextRequestId;
    r.view = view;
    // A view the wire refuses (no direction, farther than kMaxViewDistanceMm, ...) would never be
    // answered: refused here like one too large.
    const std::vector<uint8_t> bytes = encodeMessage(r);
    if (bytes.empty()) {
        ++m_viewsRefused;
        return 0;
    }
    ++m_nextRequestId;
    m_requestedViewId = r.requestId;
    m_viewRefusal.reset(); // the server answers this one anew
    if (m_sync == Sync::Volume && m_wantSync == Sync::Volume && m_volume) {
        // We render it ourselves, now; the server only keeps it for a switch to DBI.
        if (m_volumeViews.empty())
            m_volumeViews[m_viewId] = m_view; // the view the server holds before these
        m_volumeViews[r.requestId] = view;
        if (m_volumeViews.size() > kVolumeViewsKept)
            m_volumeViews.erase(m_volumeViews.begin());
        takeLocalView(r.requestId, view);
    } else {
        m_requested[r.requestId] = view;
    }
    send(Channel::Control, bytes);
    return r.requestId;
}

// [Volume sync] `view` is ours at once: rendered here.
void SessionClient::takeLocalView(uint32_t id, const ViewSpec& view) {
    m_view = view;
    m_viewId = id;
    m_exactViewId = m_viewId;
    if (m_config.renderLocally)
        renderLocal();
    else
        m_dbi = Dbi(view.width, view.height);
}

void SessionClient::sendPing() {
    Ping p{m_config.clock()};
    send(Channel::Control, encodeMessage(p));
}

void SessionClient::annotate(Annotate a) {
    // Cut to what the wire carries, at a character boundary: half a UTF-8 character would show
    // as garbage in everyone's list.
    if (a.label.size() > kMaxNameLength) {
        size_t n = kMaxNameLength;
        while (n > 0 && (uint8_t(a.label[n]) & 0xC0) == 0x80)
            --n;
        a.label.resize(n);
    }
    send(Channel::Control, encodeMessage(a));
}

void SessionClient::viewAs(uint16_t id) {
    m_viewAs = id;
    ViewAs m{id};
    send(Channel::Control, encodeMessage(m));
}

void SessionClient::takeOver(uint16_t trainee) {
    send(TakeOver{trainee});
}

} // namespace trephine::net

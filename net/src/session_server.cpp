#include "net/session_server.h"

#include "libsim/dirty_rect.h"
#include "libsim/drill.h"
#include "libsim/error.h"
#include "libsim/renderer.h"
#include "libsim/thread_pool.h"
#include "libsim/volume_io.h"
#include "net/codec.h"
#include "net/view.h"

#include <pthread.h>

#include <algorithm>
#include <cstdio>
#include <optional>

namespace trephine::net {

// [SECTION] state shared by the two threads

namespace {

// What the network thread hands the simulation thread, in arrival order.
struct SimEvent {
    enum class Kind { Join, View, Tool, Leave } kind = Kind::Tool;
    uint16_t client = 0;
    Camera camera;
    uint32_t viewId = 0;
    Codec codec = Codec::Raw;
    ToolState tool;
    uint64_t arrivedUs = 0;
};

// An image update for one client, waiting for the network thread. While it waits, newer
// rectangles of the same view are merged into it (see SessionServer::Impl::post).
struct PendingUpdate {
    uint32_t viewId = 0;
    PixelRect rect;
    bool full = false;
    uint64_t causeUs = 0; // the oldest cause merged in: latency is never under-reported
    std::vector<uint8_t> message;
};

// A network-side participant.
struct NetPeer {
    ENetPeer* peer = nullptr;
    bool hello = false;
    Hello helloMsg;
    int malformed = 0;
    bool kicked = false;
};

// A simulation-side participant: its view, codec and tool.
struct SimClient {
    Camera camera;
    uint32_t viewId = 0;
    Codec codec = Codec::Raw;
    std::optional<Driller> driller;
    bool hasTool = false;
    uint32_t lastSequence = 0;
    uint64_t lastClientUs = 0;
};

// One render per distinct view; clients that share a camera share its frame.
struct ViewFrame {
    Camera camera;
    Dbi frame;
};

SimEvent makeEvent(SimEvent::Kind kind, uint16_t client) {
    SimEvent ev;
    ev.kind = kind;
    ev.client = client;
    return ev;
}

void nameThread(const char* name) {
    pthread_setname_np(pthread_self(), name);
}

ToolShape shapeOf(const ToolState& t) {
    return ToolKind(t.toolKind) == ToolKind::Perforator ? ToolShape::perforator(t.diameterMm)
                                                        : ToolShape::burr(t.diameterMm);
}

} // namespace

struct SessionServer::Impl {
    explicit Impl(Volume v, const ServerConfig& c)
        : host(Host::listen(c.port, c.maxClients)), volume(std::move(v)), pool(c.renderThreads),
          renderer(volume, &pool) {}

    Host host;

    // Simulation thread (and inspection) under volumeMutex.
    std::mutex volumeMutex;
    Volume volume;
    ThreadPool pool;
    Renderer renderer;
    std::map<uint16_t, SimClient> simClients;
    std::vector<ViewFrame> views;
    uint32_t sequence = 0;

    // Network thread only.
    std::map<uint16_t, NetPeer> peers;
    uint16_t nextId = 1;

    // Network -> simulation.
    std::mutex inMutex;
    std::condition_variable inCv;
    std::vector<SimEvent> inbox;
    bool busy = false; // the simulation thread is working on a batch (under inMutex)
    std::atomic<bool> stopSim{false};

    // Simulation -> network.
    std::mutex outMutex;
    std::map<uint16_t, PendingUpdate> outbox;

    void push(SimEvent ev) {
        {
            std::lock_guard lock(inMutex);
            inbox.push_back(std::move(ev));
        }
        inCv.notify_one();
    }

    // Queues `rect` of `view` for client `id`, merged with an unsent update of the same view so
    // a region is never queued twice and the newest pixels (the frame's, now) win.
    void post(uint16_t id, const SimClient& c, const ViewFrame& view, PixelRect rect, bool full,
              uint64_t causeUs) {
        std::optional<PendingUpdate> old;
        {
            std::lock_guard lock(outMutex);
            auto it = outbox.find(id);
            if (it != outbox.end()) {
                if (it->second.viewId == c.viewId)
                    old = std::move(it->second);
                outbox.erase(it);
            }
        }
        if (old) {
            rect = unite(rect, old->rect);
            full = full || old->full;
            causeUs = std::min(causeUs, old->causeUs);
        }
        ImageUpdate u;
        u.sequence = ++sequence;
        u.viewId = c.viewId;
        u.causeServerUs = causeUs;
        u.full = full;
        u.x = uint16_t(rect.x);
        u.y = uint16_t(rect.y);
        u.width = uint16_t(rect.w);
        u.height = uint16_t(rect.h);
        u.codec = c.codec;
        EncodedImage e = encodeImage(view.frame.extract(rect), c.codec, view.camera);
        u.rawBytes = e.rawBytes;
        u.payload = std::move(e.payload);
        u.sentServerUs = steadyNowUs();
        PendingUpdate p{c.viewId, rect, full, causeUs, encodeMessage(u)};
        std::lock_guard lock(outMutex);
        outbox[id] = std::move(p);
    }
};

// [SECTION] lifetime

SessionServer::SessionServer(Volume volume, ServerConfig config)
    : m_impl(std::make_unique<Impl>(std::move(volume), config)), m_config(std::move(config)) {}

SessionServer::~SessionServer() {
    try {
        stop();
    } catch (const std::exception& e) {
        std::fprintf(stderr, "trephine server: %s\n", e.what());
    }
}

uint16_t SessionServer::port() const {
    return m_impl->host.port();
}

void SessionServer::start() {
    if (m_started.exchange(true))
        return;
    m_netThread = std::thread([this] { networkLoop(); });
    m_simThread = std::thread([this] { simulationLoop(); });
}

void SessionServer::stop() {
    if (m_stop.exchange(true))
        return;
    if (m_netThread.joinable())
        m_netThread.join();
    m_impl->stopSim = true;
    m_impl->inCv.notify_all();
    if (m_simThread.joinable())
        m_simThread.join();
    if (!m_config.saveOnExit.empty()) {
        std::lock_guard lock(m_impl->volumeMutex);
        saveVolume(m_impl->volume, m_config.saveOnExit);
    }
}

// [SECTION] inspection

Dbi SessionServer::renderView(const ViewSpec& view) {
    std::lock_guard lock(m_impl->volumeMutex);
    return m_impl->renderer.render(toCamera(view));
}

Volume SessionServer::volumeSnapshot() {
    std::lock_guard lock(m_impl->volumeMutex);
    return m_impl->volume;
}

bool SessionServer::idle() {
    {
        std::lock_guard lock(m_impl->inMutex);
        if (!m_impl->inbox.empty() || m_impl->busy)
            return false;
    }
    std::lock_guard lock(m_impl->outMutex);
    return m_impl->outbox.empty();
}

// [SECTION] network thread

void SessionServer::networkLoop() {
    nameThread("trephine-net");
    Impl& s = *m_impl;
    uint64_t nextTick = 0;

    auto sendTo = [&](ENetPeer* peer, Channel ch, const std::vector<uint8_t>& bytes) {
        if (!bytes.empty() && s.host.send(peer, ch, bytes))
            m_stats.countOut(ch, bytes.size());
    };
    auto malformed = [&](NetPeer& p) {
        m_stats.countMalformed();
        if (++p.malformed > m_config.malformedLimit && !p.kicked) {
            p.kicked = true;
            m_malformedKicks.fetch_add(1);
            enet_peer_disconnect(p.peer, uint32_t(RefuseReason::Malformed));
        }
    };

    // Returns false for a malformed message (counted by the caller).
    auto handle = [&](uint16_t id, NetPeer& p, std::span<const uint8_t> data) -> bool {
        uint8_t type = peekMessageType(data);
        uint64_t now = steadyNowUs();
        if (!p.hello) {
            Hello h;
            if (type != uint8_t(MessageType::Hello) || !decodeMessage(data, h))
                return false;
            p.hello = true;
            p.helloMsg = h;
            Welcome w;
            w.clientId = id;
            w.serverTimeUs = now;
            {
                // dims and spacing never change after construction; no lock needed for reading.
                w.volumeDims = s.volume.dims();
                w.spacing = s.volume.spacing();
            }
            w.volumeName = m_config.volumeName.substr(0, 256);
            sendTo(p.peer, Channel::Control, encodeMessage(w));
            SimEvent ev = makeEvent(SimEvent::Kind::Join, id);
            ev.camera = toCamera(h.view);
            ev.codec = h.codec;
            s.push(std::move(ev));
            return true;
        }
        switch (MessageType(type)) {
        case MessageType::ViewRequest: {
            ViewRequest r;
            if (!decodeMessage(data, r))
                return false;
            SimEvent ev = makeEvent(SimEvent::Kind::View, id);
            ev.camera = toCamera(r.view);
            ev.viewId = r.requestId;
            s.push(std::move(ev));
            return true;
        }
        case MessageType::ToolState: {
            ToolState t;
            if (!decodeMessage(data, t))
                return false;
            try {
                shapeOf(t).validate();
            } catch (const Error&) {
                return false; // a diameter the tool cannot have
            }
            SimEvent ev = makeEvent(SimEvent::Kind::Tool, id);
            ev.tool = t;
            ev.arrivedUs = now;
            s.push(std::move(ev));
            ToolRelay relay{id, t};
            std::vector<uint8_t> bytes = encodeMessage(relay);
            for (auto& [otherId, other] : s.peers)
                if (otherId != id && other.hello && !other.kicked)
                    sendTo(other.peer, Channel::ToolState, bytes);
            return true;
        }
        case MessageType::Ping: {
            Ping ping;
            if (!decodeMessage(data, ping))
                return false;
            Pong pong{ping.clientTimeUs, steadyNowUs()};
            sendTo(p.peer, Channel::Control, encodeMessage(pong));
            return true;
        }
        default:
            return false; // unknown, or a message only the server sends
        }
    };

    auto onEvent = [&](const ENetEvent& ev) {
        switch (ev.type) {
        case ENET_EVENT_TYPE_CONNECT: {
            if (ev.data != kProtocolVersion) {
                ev.peer->data = nullptr;
                enet_peer_disconnect(ev.peer,
                                     uint32_t(RefuseReason::Version) | (kProtocolVersion << 8));
                return;
            }
            disableThrottle(ev.peer);
            uint16_t id = s.nextId++;
            if (s.nextId == 0)
                s.nextId = 1;
            ev.peer->data = reinterpret_cast<void*>(uintptr_t(id));
            s.peers[id].peer = ev.peer;
            m_clientCount = s.peers.size();
            return;
        }
        case ENET_EVENT_TYPE_DISCONNECT: {
            auto id = uint16_t(reinterpret_cast<uintptr_t>(ev.peer->data));
            ev.peer->data = nullptr;
            if (id && s.peers.erase(id)) {
                s.push(makeEvent(SimEvent::Kind::Leave, id));
                m_clientCount = s.peers.size();
            }
            return;
        }
        case ENET_EVENT_TYPE_RECEIVE: {
            auto id = uint16_t(reinterpret_cast<uintptr_t>(ev.peer->data));
            auto it = s.peers.find(id);
            if (!id || it == s.peers.end() || it->second.kicked)
                return;
            m_stats.countIn(Channel(std::min<int>(ev.channelID, int(Channel::Count) - 1)),
                            ev.packet->dataLength);
            if (!handle(id, it->second, {ev.packet->data, ev.packet->dataLength}))
                malformed(it->second);
            return;
        }
        default:
            return;
        }
    };

    while (!m_stop.load()) {
        s.host.service(1, onEvent);
        std::map<uint16_t, PendingUpdate> out;
        {
            std::lock_guard lock(s.outMutex);
            out.swap(s.outbox);
        }
        for (auto& [id, u] : out) {
            auto it = s.peers.find(id);
            if (it != s.peers.end() && !it->second.kicked)
                sendTo(it->second.peer, Channel::Image, u.message);
        }
        if (!out.empty())
            s.host.flush();
        uint64_t now = steadyNowUs();
        if (now >= nextTick) {
            m_stats.tick(now);
            nextTick = now + 1000000;
        }
    }

    // Say goodbye so clients print a reason, and give the goodbyes a moment to leave.
    for (auto& [id, p] : s.peers)
        enet_peer_disconnect(p.peer, uint32_t(RefuseReason::Shutdown));
    uint64_t deadline = steadyNowUs() + 200000;
    while (!s.peers.empty() && steadyNowUs() < deadline)
        s.host.service(5, [&](const ENetEvent& ev) {
            if (ev.type == ENET_EVENT_TYPE_DISCONNECT) {
                auto id = uint16_t(reinterpret_cast<uintptr_t>(ev.peer->data));
                if (id && s.peers.erase(id))
                    s.push(makeEvent(SimEvent::Kind::Leave, id));
            }
        });
    m_clientCount = 0;
}

// [SECTION] simulation thread

void SessionServer::simulationLoop() {
    nameThread("trephine-sim");
    Impl& s = *m_impl;
    std::vector<SimEvent> batch;
    for (;;) {
        {
            std::unique_lock lock(s.inMutex);
            s.inCv.wait_for(lock, std::chrono::milliseconds(10),
                            [&] { return !s.inbox.empty() || s.stopSim.load(); });
            if (s.inbox.empty() && s.stopSim.load())
                return;
            batch.clear();
            batch.swap(s.inbox);
            s.busy = !batch.empty();
        }
        if (batch.empty())
            continue;

        std::lock_guard volumeLock(s.volumeMutex);
        Box3i changed;
        uint64_t causeUs = 0;
        std::map<uint16_t, uint64_t> needFull; // client -> cause time
        for (SimEvent& ev : batch) {
            switch (ev.kind) {
            case SimEvent::Kind::Join:
            case SimEvent::Kind::View: {
                SimClient& c = s.simClients[ev.client];
                c.camera = ev.camera;
                c.viewId = ev.viewId;
                if (ev.kind == SimEvent::Kind::Join)
                    c.codec = ev.codec;
                needFull[ev.client] = steadyNowUs();
                break;
            }
            case SimEvent::Kind::Leave:
                s.simClients.erase(ev.client);
                needFull.erase(ev.client);
                break;
            case SimEvent::Kind::Tool: {
                auto it = s.simClients.find(ev.client);
                if (it == s.simClients.end())
                    break;
                SimClient& c = it->second;
                const ToolState& t = ev.tool;
                // Unsequenced: an older state that arrives late is dropped (newest wins).
                if (c.hasTool && int32_t(t.sequence - c.lastSequence) <= 0)
                    break;
                ToolShape shape = shapeOf(t);
                if (!c.driller || c.driller->shape().kind != shape.kind ||
                    c.driller->shape().diameterMm != shape.diameterMm)
                    c.driller.emplace(shape);
                // The step is the time between the client's own timestamps (time passed in).
                float dt = 0.0f;
                if (c.hasTool && t.clientTimeUs > c.lastClientUs)
                    dt = std::min(float(double(t.clientTimeUs - c.lastClientUs) * 1e-6),
                                  m_config.maxStepS);
                c.hasTool = true;
                c.lastSequence = t.sequence;
                c.lastClientUs = t.clientTimeUs;
                m_toolStatesApplied.fetch_add(1);
                if (!t.drilling || t.speed <= 0.0f || dt <= 0.0f)
                    break;
                DrillResult r =
                    c.driller->drill(s.volume, ToolPose{t.position, t.orientation}, t.speed, dt);
                if (!r.changed.empty()) {
                    changed.merge(r.changed);
                    causeUs = causeUs ? std::min(causeUs, ev.arrivedUs) : ev.arrivedUs;
                }
                break;
            }
            }
        }
        if (!changed.empty())
            s.renderer.volumeChanged(changed);

        // Frames of views nobody holds any more are dropped.
        std::erase_if(s.views, [&](const ViewFrame& v) {
            return std::none_of(s.simClients.begin(), s.simClients.end(),
                                [&](const auto& c) { return c.second.camera == v.camera; });
        });
        for (const auto& [id, c] : s.simClients) {
            auto it = std::find_if(s.views.begin(), s.views.end(),
                                   [&](const ViewFrame& v) { return v.camera == c.camera; });
            if (it == s.views.end()) {
                s.views.push_back({c.camera, s.renderer.render(c.camera)});
                m_renders.fetch_add(1);
            }
        }
        for (ViewFrame& v : s.views) {
            // The frame first takes the change, so a full refresh sent now holds it too.
            PixelRect rect;
            if (!changed.empty()) {
                rect = dirtyScreenRect(v.camera, s.volume, changed);
                if (!rect.empty()) {
                    s.renderer.render(v.camera, rect, v.frame);
                    m_renders.fetch_add(1);
                }
            }
            for (const auto& [id, c] : s.simClients) {
                if (!(c.camera == v.camera))
                    continue;
                auto full = needFull.find(id);
                if (full != needFull.end())
                    s.post(id, c, v, v.frame.bounds(), true, full->second);
                else if (!rect.empty())
                    s.post(id, c, v, rect, false, causeUs);
            }
        }
        std::lock_guard lock(s.inMutex);
        s.busy = false;
    }
}

} // namespace trephine::net

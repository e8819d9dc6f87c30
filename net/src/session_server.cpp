#include "net/session_server.h"

#include "libsim/dirty_rect.h"
#include "libsim/drill.h"
#include "libsim/error.h"
#include "libsim/force_model.h"
#include "libsim/renderer.h"
#include "libsim/replacing_file.h"
#include "libsim/thread_pool.h"
#include "libsim/volume_io.h"
#include "net/codec.h"
#include "net/image_delta.h"
#include "net/marks_file.h"
#include "net/view.h"
#include "net/view_follow.h"

#include <poll.h>
#include <pthread.h>
#include <sys/eventfd.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cstdio>
#include <filesystem>
#include <optional>
#include <shared_mutex>

namespace trephine::net {

// [SECTION] state shared by the two threads

namespace {

// What the network thread hands the simulation thread, in arrival order.
struct SimEvent {
    enum class Kind { Join, View, Tool, Leave, Cut, Sync, Voxels } kind = Kind::Tool;
    uint16_t client = 0;
    Camera camera;
    uint32_t viewId = 0;
    Codec codec = Codec::Raw;
    Sync sync = Sync::Dbi;          // Join, Sync
    Codec volumeCodec = Codec::Raw; // Join, Sync
    ToolState tool;
    Box3i box;                              // Cut, Voxels
    std::vector<uint8_t> density, material; // Voxels
    uint64_t arrivedUs = 0;
    Host::InFlight inFlight; // Join: the peer's bytes in flight (read by the simulation thread)
};

// An image update for one client, waiting for the network thread. While it waits, newer
// rectangles of the same view are merged into it (see SessionServer::Impl::post).
struct PendingUpdate {
    uint32_t viewId = 0;
    PixelRect rect;
    bool full = false;
    uint64_t causeUs = 0; // the oldest cause merged in: latency is never under-reported
    uint32_t rawBytes = 0;
    uint32_t payloadBytes = 0;
    std::vector<uint8_t> message;
    // The client's pixels of `rect` before this update (SimClient::shadow), put back if the update
    // is merged into a newer one before it leaves: the client never saw it. Empty when full.
    Dbi undo;
};

// A volume update for one client (replicated-volume baseline), coalesced like images: a newer
// box merges into an unsent one and the voxels are taken afresh, so the newest voxels win and no
// voxel is queued twice.
struct PendingVolume {
    Box3i box;
    bool full = false;
    bool materials = false;
    uint64_t causeUs = 0;
    uint32_t rawBytes = 0;
    uint32_t payloadBytes = 0;
    std::vector<uint8_t> message;
};

// Per-mode server figures for the report (under reportMutex).
struct ModeReport {
    SampleWindow erodeUs{65536}, renderUs{65536}, encodeUs{65536};
};

// A network-side participant.
struct NetPeer {
    ENetPeer* peer = nullptr;
    bool hello = false;
    Hello helloMsg;
    Sync sync = Sync::Dbi;          // the hello's, then the latest SyncMode
    Codec volumeCodec = Codec::Lz4; // likewise
    // Bytes of this peer's image and volume updates ENet still holds (ServerConfig::
    // maxInFlightBytes).
    Host::InFlight inFlight = std::make_shared<std::atomic<int64_t>>(0);
    int malformed = 0;
    bool kicked = false;
    uint64_t connectedUs = 0; // a peer still without a hello after ServerConfig::helloTimeoutS goes
    // When the last mode switch went to the simulation, and whether a later one waits
    // (kSyncSwitchIntervalUs).
    uint64_t syncPushedUs = 0;
    bool syncDeferred = false;
    VelocityEstimate toolVelocity; // from its tool states' positions and client times
};

// A message the network thread sends whole, at most once every `intervalUs`: changes mark it and
// the loop sends it when due, so changes as fast as a peer can send go out together. A change
// marked `urgent` goes out at the next pass.
struct Coalesced {
    uint64_t intervalUs;
    bool dirty = false, urgent = false;
    uint64_t sentUs = 0;

    void mark(bool now = false) {
        dirty = true;
        urgent = urgent || now;
    }
    // True (and counted as sent) when it should go out at time `now`.
    bool due(uint64_t now) {
        if (!dirty || (!urgent && now - sentUs < intervalUs))
            return false;
        dirty = urgent = false;
        sentUs = now;
        return true;
    }
};

// Per-peer figures for the server report (kept after the peer leaves).
struct PeerReport {
    std::string name;
    Role role = Role::Trainee;
    bool hello = false;
    uint64_t bytesIn = 0, bytesOut = 0, messagesIn = 0, messagesOut = 0;
    uint64_t malformed = 0, hapticModels = 0, hapticRelays = 0, toolStates = 0, viewsRefused = 0;
    uint64_t connectedUs = 0, disconnectedUs = 0;
    bool kicked = false;
    Sync sync = Sync::Dbi;
    uint64_t syncSwitches = 0;
};

// A simulation-side participant: its view, codec and tool.
struct SimClient {
    Camera camera;
    uint32_t viewId = 0;
    // What the client holds once every posted image update has arrived (the image channel is
    // reliable and ordered): the base of predicted updates. Empty outside DBI mode.
    Dbi shadow;
    Codec codec = Codec::Raw;
    Sync sync = Sync::Dbi;
    Codec volumeCodec = Codec::Raw;
    std::optional<Driller> driller;
    ToolPose lastPose;         // of the newest applied tool state
    bool lastDrilling = false; // it drilled (with the driller there is now)
    bool hasTool = false;
    uint32_t lastSequence = 0;
    uint64_t lastClientUs = 0;
    // The peer's bytes in flight (the network thread's count): over ServerConfig::maxInFlightBytes
    // its updates wait in the outbox.
    Host::InFlight inFlight;
    // [Volume mode] Changes noted while the client is held back with an update already waiting:
    // posted (coded) once, when it can go, instead of re-coding the waiting one at every batch.
    struct DeferredVolume {
        Box3i box;
        bool full = false, materials = false;
        uint64_t causeUs = 0;
        uint32_t erodeUs = 0;
    };
    std::optional<DeferredVolume> deferredVolume;
};

// One render per distinct view; clients that share a camera share its frame.
struct ViewFrame {
    Camera camera;
    Dbi frame;
    HitCache cache; // where each pixel's ray met bone: dirty re-renders resume there
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
        : host(Host::listen(c.port, c.maxClients + kSparePeers)),
          volume(normaliseAir(std::move(v))), pool(c.renderThreads), renderer(volume, &pool),
          wakeFd(eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC)) {}
    ~Impl() {
        if (wakeFd >= 0)
            ::close(wakeFd);
    }
    Impl(const Impl&) = delete;
    Impl& operator=(const Impl&) = delete;

    // Air has no material: a voxel of density 0 is labelled Air, as erosion and box cuts leave
    // it. With that invariant a volume client derives materials exactly from box densities.
    static Volume normaliseAir(Volume v) {
        uint8_t* den = v.densityData();
        uint8_t* mat = v.materialData();
        for (size_t i = 0; i < v.voxelCount(); ++i)
            if (den[i] == 0)
                mat[i] = uint8_t(Material::Air);
        return v;
    }

    // ENet peer slots beyond maxClients, so that one more can be told "server full".
    static constexpr size_t kSparePeers = 4;

    Host host;

    // Simulation thread (and inspection) under volumeMutex: the renderer's bricks, views, frames.
    std::mutex volumeMutex;
    // Changes the renderer's brick grid has not taken yet: it is rendering data for DBI views,
    // kept in step only while some client is in DBI mode (a volume-only session pays nothing for
    // it, nor do its clients' measured cycles, which share the machine in the study), and brought
    // up to date before the next render. Under volumeMutex.
    Box3i gridPending;
    bool gridRebuildPending = false;
    // Applies the pending changes to the brick grid (under volumeMutex).
    void syncGrid() {
        if (gridRebuildPending)
            renderer.rebuild(); // voxels written wholesale may have raised densities
        else if (!gridPending.empty())
            renderer.volumeChanged(gridPending); // erosion only: the hit caches stay valid
        gridRebuildPending = false;
        gridPending = {};
    }
    // The voxels themselves are also read by the network thread (haptic force models) while the
    // simulation thread renders: the simulation thread, the only writer, holds volumeRw exclusively
    // just around each write (one Driller::drill step, one box cut); the network thread holds it
    // shared around ForceModel::compute. Reads on the simulation thread need no lock (it is the
    // writer), so rendering never blocks haptics and haptics waits at most one drill step.
    std::shared_mutex volumeRw;
    Volume volume;
    ThreadPool pool;
    Renderer renderer;
    std::map<uint16_t, SimClient> simClients;
    std::vector<ViewFrame> views;
    uint32_t sequence = 0;

    // Network thread writes, report readers read, under reportMutex.
    mutable std::mutex reportMutex;
    std::map<uint16_t, PeerReport> peerReport;
    SampleWindow forceComputeUs{65536};
    SampleWindow hapticServiceUs{65536}; // tool state received -> haptic model queued
    std::array<ModeReport, 2> modeReport;
    std::array<ModeTotals, 2> modeTotals;

    // Network thread only.
    std::map<uint16_t, NetPeer> peers;
    // The instructors' marks, by id (network thread only).
    std::map<uint32_t, AnnotationInfo> annotations;
    uint32_t nextAnnotationId = 1;
    // Trainees taken over: trainee id -> the instructor holding it (network thread only).
    std::map<uint16_t, uint16_t> takenOver;
    ViewFollowers follow; // every participant's view, and the instructors viewing as one
    uint16_t nextId = 1;

    // Whether client `id` (of `role`) may cut now: a trainee nobody holds, or an instructor
    // holding a trainee.
    bool mayCut(uint16_t id, Role role) const {
        if (role == Role::Trainee)
            return !takenOver.count(id);
        return std::any_of(takenOver.begin(), takenOver.end(),
                           [&](const auto& held) { return held.second == id; });
    }
    // Hands back whatever `id` holds or is held by; true when that changed anything.
    bool releaseTakeOvers(uint16_t id) {
        return std::erase_if(takenOver, [&](const auto& held) {
                   return held.first == id || held.second == id;
               }) > 0;
    }

    // Network -> simulation.
    std::mutex inMutex;
    std::condition_variable inCv;
    std::vector<SimEvent> inbox;
    size_t inboxTools = 0; // Tool events in the inbox (ServerConfig::maxQueuedToolStates)
    // Peers whose mode switch waits for kSyncSwitchIntervalUs (NetPeer::syncDeferred): not idle.
    std::atomic<int> syncsDeferred{0};
    // Volume clients with changes noted but not yet coded (SimClient::deferredVolume), counted by
    // the simulation thread after each pass: not idle while there are any.
    std::atomic<int> volumesDeferred{0};
    bool busy = false; // the simulation thread is working on a batch (under inMutex)
    std::atomic<bool> stopSim{false};

    // Simulation -> network.
    std::mutex outMutex;
    std::map<uint16_t, PendingUpdate> outbox;
    std::map<uint16_t, PendingVolume> volumeOutbox;
    // Volume clients whose whole volume does not fit a message in their codec: the network
    // thread disconnects them, saying why (RefuseReason::VolumeTooLarge).
    std::vector<uint16_t> volumeRefused;
    // Wakes the network thread's wait on the ENet socket when an update is posted, so it goes
    // out at once instead of after the rest of a 1 ms service timeout (-1: no eventfd; the
    // network thread then simply waits out its timeout).
    int wakeFd = -1;

    void wakeNetwork() {
        if (wakeFd >= 0) {
            uint64_t one = 1;
            [[maybe_unused]] ssize_t n = ::write(wakeFd, &one, sizeof one);
        }
    }

    // Waits up to timeoutMs for a datagram on the ENet socket or a wake-up.
    void waitNetwork(int timeoutMs) {
        pollfd fds[2] = {{int(host.get()->socket), POLLIN, 0}, {wakeFd, POLLIN, 0}};
        if (::poll(fds, wakeFd >= 0 ? 2 : 1, timeoutMs) > 0 && wakeFd >= 0 &&
            (fds[1].revents & POLLIN)) {
            uint64_t count = 0;
            [[maybe_unused]] ssize_t n = ::read(wakeFd, &count, sizeof count);
        }
    }

    void push(SimEvent ev) {
        {
            std::lock_guard lock(inMutex);
            inbox.push_back(std::move(ev));
        }
        inCv.notify_one();
    }
    // A tool state, unless `cap` of them already wait: false when dropped.
    bool pushTool(SimEvent ev, size_t cap) {
        {
            std::lock_guard lock(inMutex);
            if (inboxTools >= cap)
                return false;
            ++inboxTools;
            inbox.push_back(std::move(ev));
        }
        inCv.notify_one();
        return true;
    }

    // Queues `rect` of `view` for client `id`, merged with an unsent update of the same view so
    // a region is never queued twice and the newest pixels (the frame's, now) win.
    void post(uint16_t id, SimClient& c, const ViewFrame& view, PixelRect rect, bool full,
              uint64_t causeUs, uint32_t erodeUs, uint32_t renderUs, uint32_t gridUs) {
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
        // Not of this frame (a view change drops pending images; this is the safety net): the
        // client's pixels are unknown, so it gets the whole frame.
        const bool merge = old && view.frame.bounds().contains(old->rect);
        if (old && !merge)
            full = true;
        if (merge) {
            // It never left: the client does not have its pixels.
            if (!old->full && !old->undo.empty() && !c.shadow.empty())
                c.shadow.apply(old->undo, old->rect.x, old->rect.y);
            rect = unite(rect, old->rect);
            full = full || old->full;
            causeUs = std::min(causeUs, old->causeUs);
        }
        rect = full ? view.frame.bounds() : intersect(rect, view.frame.bounds());
        if (rect.empty())
            return;
        ImageUpdate u;
        u.sequence = ++sequence;
        u.viewId = c.viewId;
        u.causeServerUs = causeUs;
        u.full = full;
        u.x = uint16_t(rect.x);
        u.y = uint16_t(rect.y);
        u.width = uint16_t(rect.w);
        u.height = uint16_t(rect.h);
        // A raw rectangle too large for one message goes lz4-coded (see kMaxImagePayloadBytes).
        u.codec = c.codec == Codec::Raw && uint64_t(rect.area()) * 8 > kMaxImagePayloadBytes
                      ? Codec::Lz4
                      : c.codec;
        uint64_t e0 = steadyNowUs();
        const Dbi pixels = view.frame.extract(rect);
        Dbi undo;
        // Predicted updates trade ~4 ns a pixel more coding at each end than the planar form
        // for about half its bytes (benchmark_net 'predicted|planar'): worth it with zstd (the
        // codec chosen for bytes), not with lz4 (chosen for latency).
        if (!full && c.codec == Codec::Zstd && c.shadow.width() == view.frame.width() &&
            c.shadow.height() == view.frame.height()) {
            undo = c.shadow.extract(rect);
            PredictedImage p = encodePredicted(pixels, undo, c.codec, DepthQuantizer(view.camera));
            u.predicted = true;
            u.baseHash = p.baseHash;
            u.rawBytes = p.rawBytes;
            u.payload = std::move(p.payload);
        } else {
            EncodedImage e = encodeImage(pixels, u.codec, view.camera);
            u.rawBytes = e.rawBytes;
            u.payload = std::move(e.payload);
        }
        // What the client holds, for predicted coding: only zstd clients get predicted updates,
        // so only they need the copy (a whole frame: 33.5 MB for 2048 x 2048).
        if (c.codec != Codec::Zstd)
            c.shadow = Dbi();
        else if (full)
            c.shadow = view.frame;
        else if (!c.shadow.empty())
            c.shadow.apply(pixels, rect.x, rect.y);
        u.sentServerUs = steadyNowUs();
        u.erodeUs = erodeUs;
        u.renderUs = renderUs;
        u.gridUs = std::min(gridUs, renderUs);
        u.encodeUs = uint32_t(u.sentServerUs - e0);
        {
            std::lock_guard lock(reportMutex);
            ModeReport& m = modeReport[size_t(Sync::Dbi)];
            m.encodeUs.add(double(u.encodeUs));
            if (!full) {
                m.erodeUs.add(double(erodeUs));
                m.renderUs.add(double(renderUs));
            }
        }
        PendingUpdate p{c.viewId,         rect,           full,
                        causeUs,          u.rawBytes,     uint32_t(u.payload.size()),
                        encodeMessage(u), std::move(undo)};
        {
            std::lock_guard lock(outMutex);
            outbox[id] = std::move(p);
        }
        wakeNetwork();
    }

    // Queues the voxels of `box` (or, when `full`, the whole volume) for volume client `id`,
    // merged with its unsent volume update: the union box, taken from the volume now.
    // Returns false when the update does not fit a message (nothing is posted then).
    bool postVolume(uint16_t id, const SimClient& c, Box3i box, bool full, bool materials,
                    uint64_t causeUs, uint32_t erodeUs) {
        std::optional<PendingVolume> old;
        {
            std::lock_guard lock(outMutex);
            auto it = volumeOutbox.find(id);
            if (it != volumeOutbox.end()) {
                old = std::move(it->second);
                volumeOutbox.erase(it);
            }
        }
        if (old) {
            box.merge(old->box);
            full = full || old->full;
            materials = materials || old->materials;
            causeUs = std::min(causeUs, old->causeUs);
        }
        if (full)
            box = volume.bounds();
        box = box.intersect(volume.bounds());
        if (box.empty())
            return true;
        VolumeUpdate u;
        u.sequence = ++sequence;
        u.causeServerUs = causeUs;
        u.full = full;
        u.materials = full || materials;
        u.x = uint16_t(box.lo.x);
        u.y = uint16_t(box.lo.y);
        u.z = uint16_t(box.lo.z);
        glm::ivec3 size = box.size();
        u.sizeX = uint16_t(size.x);
        u.sizeY = uint16_t(size.y);
        u.sizeZ = uint16_t(size.z);
        // More raw bytes than a VolumeUpdate may announce cannot go, however well they code: not
        // built and compressed first (a 1024^3 volume took 4 GiB and seconds of the simulation
        // thread for each volume client's join, only to be refused).
        if (!fitsVolumeUpdate(size, u.materials))
            return false;
        uint64_t e0 = steadyNowUs();
        EncodedVolume e = full ? encodeVolumeFull(volume, c.volumeCodec)
                               : encodeVolumeBox(volume, box, c.volumeCodec, materials);
        u.codec = e.codec;
        u.rawBytes = e.rawBytes;
        u.payload = std::move(e.payload);
        u.sentServerUs = steadyNowUs();
        u.erodeUs = erodeUs;
        u.encodeUs = uint32_t(u.sentServerUs - e0);
        {
            std::lock_guard lock(reportMutex);
            ModeReport& m = modeReport[size_t(Sync::Volume)];
            m.encodeUs.add(double(u.encodeUs));
            if (!full)
                m.erodeUs.add(double(erodeUs));
        }
        std::vector<uint8_t> message = encodeMessage(u);
        if (message.empty() || message.size() > kMaxSentMessageBytes)
            return false; // too large once coded to go through ENet

        PendingVolume p{box,
                        full,
                        materials,
                        causeUs,
                        u.rawBytes,
                        uint32_t(u.payload.size()),
                        std::move(message)};
        {
            std::lock_guard lock(outMutex);
            volumeOutbox[id] = std::move(p);
        }
        wakeNetwork();
        return true;
    }

    // A box too large for a message goes as the whole volume, coded, which may fit; a whole
    // volume that does not fit cannot be sent at all: the client is refused (network thread).
    void postVolumeOrRefuse(uint16_t id, const SimClient& c, const Box3i& box, bool full,
                            bool materials, uint64_t causeUs, uint32_t erodeUs) {
        if (postVolume(id, c, box, full, materials, causeUs, erodeUs))
            return;
        if (!full && postVolume(id, c, volume.bounds(), true, true, causeUs, 0))
            return;
        {
            std::lock_guard lock(outMutex);
            volumeOutbox.erase(id);
            volumeRefused.push_back(id);
        }
        wakeNetwork();
    }

    // A client that switched modes needs nothing queued for the other one.
    void dropPending(uint16_t id, Sync mode) {
        std::lock_guard lock(outMutex);
        if (mode == Sync::Dbi)
            outbox.erase(id);
        else
            volumeOutbox.erase(id);
    }
};

// [SECTION] lifetime

namespace {

// Throws on a volume the session cannot carry: the welcome gives at most kMaxVolumeDim voxels an
// axis (files load up to 2^20), and a larger one went silently unwelcomed, every client told
// "no answer (is `trephine server` running?)".
Volume checkedVolume(Volume volume) {
    const glm::ivec3 d = volume.dims();
    for (int axis = 0; axis < 3; ++axis)
        if (d[axis] > kMaxVolumeDim)
            throw Error("server: the volume has " + std::to_string(d[axis]) + " voxels along " +
                        "xyz"[axis] + "; a session carries at most " +
                        std::to_string(kMaxVolumeDim) + " an axis (crop or resample it)");
    return volume;
}

// Throws on settings the server cannot honour (before anything starts).
const ServerConfig& checkedConfig(const ServerConfig& config) {
    if (!(config.helloTimeoutS > 0.0f))
        throw Error("server: the hello timeout must be positive");
    // Now, not at the end of the session: a path that cannot be written would lose it all.
    if (!config.saveOnExit.empty()) {
        checkSaveTarget(config.saveOnExit);
        // A NIfTI file holds densities only: the session would come back with its dura and brain
        // turned to bone, so it is refused before anyone drills.
        if (!savesMaterials(config.saveOnExit))
            throw Error("--save-on-exit " + config.saveOnExit +
                        ": NIfTI keeps no materials (dura and brain would reload as bone); "
                        "save the session as .nrrd or .nhdr");
        // The marks' file is replaced as ReplacingFile does, which writes a device or a folder in
        // place: a folder there would fail only at the end.
        const std::string marks = marksPathFor(config.saveOnExit);
        if (!replacementTarget(marks))
            throw Error("--save-on-exit: " + marks + ", where the marks go, is not a regular file");
    }
    // Cut to fit, it named another file, which a headless trainee then failed to open.
    if (config.volumeName.size() > kMaxVolumeNameBytes)
        throw Error("server: the volume's name is " + std::to_string(config.volumeName.size()) +
                    " bytes; the session carries at most " + std::to_string(kMaxVolumeNameBytes) +
                    " (give a shorter path)");
    checkMarks(config.marks, "server: the starting marks");
    if (config.maxViewPixels < 1 || config.maxViewPixels > kMaxServedViewPixels)
        throw Error("server: the largest view must be 1 to " +
                    std::to_string(kMaxServedViewPixels) +
                    " pixels (a coded image must fit one message), not " +
                    std::to_string(config.maxViewPixels));
    return config;
}

} // namespace

SessionServer::SessionServer(Volume volume, ServerConfig config)
    : m_impl(std::make_unique<Impl>(checkedVolume(std::move(volume)), checkedConfig(config))),
      m_config(std::move(config)) {
    if (!m_config.scene)
        m_config.scene = std::make_shared<const Scene>(buildScene(m_impl->volume));
    Scene scene = *m_config.scene;
    m_sceneMessage = encodeMessage(scene);
    if (m_sceneMessage.empty() || scene.dims != m_impl->volume.dims())
        throw Error("server: the scene given is not one of this volume");
    for (const AnnotationInfo& m : m_config.marks) {
        const uint32_t id = m_impl->nextAnnotationId++;
        m_impl->annotations[id] = {id, 0, m.position, m.label};
    }
}

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
    // Once stopped, a server stays stopped: threads started then would end at once, unjoined,
    // and the destructor's join-less threads would terminate the program.
    if (m_stop.load() || m_started.exchange(true))
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
        // The marks too (the network thread, their keeper, has stopped), always, even none: an
        // older file beside the volume would bring back marks this session removed.
        std::vector<AnnotationInfo> marks;
        for (const auto& [id, a] : m_impl->annotations)
            marks.push_back(a);
        auto saveSession = [&](const std::string& path) {
            saveVolume(m_impl->volume, path);
            try {
                writeMarksFile(marksPathFor(path), marks);
                writeSceneFile(scenePathFor(path), *m_config.scene);
            } catch (...) {
                // The new volume is in place: an older marks file left beside it would come back
                // with it (marks this session removed, none of those it placed).
                std::error_code ec;
                for (const std::string& beside : {marksPathFor(path), scenePathFor(path)})
                    if (std::filesystem::is_regular_file(beside, ec))
                        std::filesystem::remove(beside, ec);
                throw;
            }
        };
        try {
            saveSession(m_config.saveOnExit);
            m_savedTo = m_config.saveOnExit;
        } catch (const std::exception& e) {
            // The session's drilling must not be lost to a full disk or a folder gone since the
            // start: an emergency copy in the temporary folder, and both said on one line each.
            m_saveError = e.what();
            const auto stamp = std::chrono::system_clock::now().time_since_epoch();
            const std::string copy =
                (std::filesystem::temp_directory_path() /
                 ("trephine-session-" + std::to_string(::getpid()) + "-" +
                  std::to_string(std::chrono::duration_cast<std::chrono::seconds>(stamp).count()) +
                  ".nrrd"))
                    .string();
            std::fprintf(stderr, "trephine server: %s\n", e.what());
            try {
                saveSession(copy);
                m_savedTo = copy;
                std::fprintf(stderr,
                             "trephine server: the final volume and marks are saved in %s (and "
                             "%s) instead\n",
                             copy.c_str(), marksPathFor(copy).c_str());
            } catch (const std::exception& e2) {
                std::fprintf(stderr, "trephine server: no emergency copy either: %s\n", e2.what());
            }
        }
    }
}

// [SECTION] inspection

void SessionServer::submitBoxCut(const Box3i& box) {
    SimEvent ev = makeEvent(SimEvent::Kind::Cut, 0);
    ev.box = box;
    ev.arrivedUs = steadyNowUs();
    m_impl->push(std::move(ev));
}

void SessionServer::submitVoxels(const Box3i& box, std::vector<uint8_t> density,
                                 std::vector<uint8_t> material) {
    if (box.empty() || !(box.intersect(m_impl->volume.bounds()) == box))
        throw Error("submitVoxels: the box must be non-empty and inside the volume");
    if (density.size() != size_t(box.count()) || material.size() != density.size())
        throw Error("submitVoxels: give box.count() density and material bytes");
    for (uint8_t m : material)
        if (m >= uint8_t(kMaterialCount))
            throw Error("submitVoxels: unknown material label " + std::to_string(m));
    SimEvent ev = makeEvent(SimEvent::Kind::Voxels, 0);
    ev.box = box;
    ev.density = std::move(density);
    ev.material = std::move(material);
    ev.arrivedUs = steadyNowUs();
    m_impl->push(std::move(ev));
}

Dbi SessionServer::renderView(const ViewSpec& view) {
    std::lock_guard lock(m_impl->volumeMutex);
    m_impl->syncGrid();
    return m_impl->renderer.render(toCamera(view));
}

Volume SessionServer::volumeSnapshot() {
    std::lock_guard lock(m_impl->volumeMutex);
    return m_impl->volume;
}

bool SessionServer::idle() {
    if (m_impl->syncsDeferred.load() > 0 || m_impl->volumesDeferred.load() > 0)
        return false;
    {
        std::lock_guard lock(m_impl->inMutex);
        if (!m_impl->inbox.empty() || m_impl->busy)
            return false;
    }
    std::lock_guard lock(m_impl->outMutex);
    return m_impl->outbox.empty() && m_impl->volumeOutbox.empty();
}

ModeTotals SessionServer::modeTotals(Sync mode) const {
    std::lock_guard lock(m_impl->reportMutex);
    ModeTotals t = m_impl->modeTotals[size_t(mode)];
    for (const auto& [id, r] : m_impl->peerReport)
        t.clients += r.hello && !r.kicked && r.disconnectedUs == 0 && r.sync == mode;
    return t;
}

// [SECTION] network thread

void SessionServer::networkLoop() {
    nameThread("trephine-net");
    Impl& s = *m_impl;
    uint64_t nextTick = 0;

    ForceModelCache forceModels; // network thread only
    auto peerId = [](ENetPeer* peer) { return uint16_t(reinterpret_cast<uintptr_t>(peer->data)); };
    auto report = [&](uint16_t id, const auto& f) {
        std::lock_guard lock(s.reportMutex);
        f(s.peerReport[id]);
    };
    // False when ENet refused the packet (it is then not counted anywhere).
    auto sendTo = [&](ENetPeer* peer, Channel ch, const std::vector<uint8_t>& bytes,
                      const Host::InFlight& inFlight = {}) -> bool {
        if (!bytes.empty() && s.host.send(peer, ch, bytes, inFlight)) {
            m_stats.countOut(ch, bytes.size());
            if (uint16_t id = peerId(peer))
                report(id, [&](PeerReport& r) {
                    r.bytesOut += bytes.size();
                    ++r.messagesOut;
                    if (bytes[0] == uint8_t(MessageType::HapticModel))
                        ++r.hapticModels;
                    else if (bytes[0] == uint8_t(MessageType::HapticRelay))
                        ++r.hapticRelays;
                });
            return true;
        }
        return false;
    };
    auto viewTooLarge = [&](const ViewSpec& v) {
        return int64_t(v.width) * int64_t(v.height) > m_config.maxViewPixels;
    };
    // The force at the tool's pose, answered at once (before and independent of drilling).
    auto answerHaptic = [&](NetPeer& p, const ToolState& t, uint64_t receivedUs) {
        HapticModel m;
        m.toolSequence = t.sequence;
        m.serverReceivedUs = receivedUs;
        m.clientTimeUs = t.clientTimeUs;
        m.position = t.position;
        const ForceModel& model = forceModels.get(shapeOf(t));
        // The drilling resistance resists the tool's motion: its velocity from this peer's
        // tool states (it was never passed, so the resistance was never felt).
        const glm::vec3 velocity = p.toolVelocity.update(t.position, double(t.clientTimeUs) * 1e-6);
        uint64_t c0 = steadyNowUs();
        ForceResult f;
        {
            std::shared_lock lock(s.volumeRw);
            f = model.compute(s.volume, ToolPose{t.position, t.orientation},
                              t.drilling ? t.speed : 0.0f, velocity);
        }
        uint64_t c1 = steadyNowUs();
        m.force = f.force;
        m.gradient = f.gradient;
        m.contact = f.contact;
        m.serverSentUs = steadyNowUs();
        {
            std::lock_guard lock(s.reportMutex);
            s.forceComputeUs.add(double(c1 - c0));
            s.hapticServiceUs.add(double(m.serverSentUs - receivedUs));
        }
        m_hapticSent.fetch_add(1); // before it can arrive: readers never see fewer than received
        sendTo(p.peer, Channel::Haptic, encodeMessage(m));
        // Every instructor sees every other participant's force plot.
        const uint16_t from = peerId(p.peer);
        HapticRelay relay{from, m};
        std::vector<uint8_t> relayBytes;
        for (auto& [otherId, other] : s.peers) {
            if (otherId == from || !other.hello || other.kicked ||
                other.helloMsg.role != Role::Instructor)
                continue;
            if (relayBytes.empty())
                relayBytes = encodeMessage(relay);
            m_hapticRelayed.fetch_add(1);
            sendTo(other.peer, Channel::Haptic, relayBytes);
        }
        s.host.flush();
    };
    // The peer's latest mode and volume codec, to the simulation.
    auto pushSync = [&](uint16_t id, NetPeer& p, uint64_t now) {
        SimEvent ev = makeEvent(SimEvent::Kind::Sync, id);
        ev.sync = p.sync;
        ev.volumeCodec = p.volumeCodec;
        s.push(std::move(ev));
        p.syncPushedUs = now;
        if (p.syncDeferred)
            --s.syncsDeferred;
        p.syncDeferred = false;
    };
    // A control message to everyone who said hello (and was not kicked).
    auto sendToParticipants = [&](const std::vector<uint8_t>& bytes) {
        for (const auto& [pid, peer] : s.peers)
            if (peer.hello && !peer.kicked)
                sendTo(peer.peer, Channel::Control, bytes);
    };
    // The roster, to everyone. Changes only mark it (sendParticipants); the loop sends it at most
    // every kRosterIntervalUs, so a peer switching modes or taking over as fast as it can send
    // cannot make the server queue a roster per message for every participant. Joins and leaves
    // (`now`) go out at once: the others keep a newcomer's relayed tool only once a roster lists
    // it, and a connection makes at most one of each.
    Coalesced rosterOut{kRosterIntervalUs};
    auto sendParticipants = [&](bool now = false) { rosterOut.mark(now); };
    auto sendRoster = [&] {
        Participants roster;
        for (const auto& [pid, peer] : s.peers) { // a std::map: increasing ids, as the wire wants
            if (!peer.hello || peer.kicked)
                continue;
            auto held = s.takenOver.find(pid);
            roster.list.push_back({pid, peer.helloMsg.role, peer.sync, peer.helloMsg.name,
                                   held == s.takenOver.end() ? uint16_t(0) : held->second});
        }
        sendToParticipants(encodeMessage(roster));
    };
    Coalesced marksOut{kAnnotationsIntervalUs}; // the marks' list, when they change
    // Every mark, in increasing id (a std::map).
    auto annotationList = [&] {
        Annotations marks;
        for (const auto& [markId, a] : s.annotations)
            marks.list.push_back(a);
        return encodeMessage(marks);
    };
    // Disconnects a listed (or listing) peer, saying why; the others hear it has gone.
    auto kick = [&](NetPeer& p, RefuseReason why) {
        p.kicked = true;
        report(peerId(p.peer), [](PeerReport& r) { r.kicked = true; });
        enet_peer_disconnect(p.peer, uint32_t(why));
        s.releaseTakeOvers(peerId(p.peer));
        if (p.hello)
            sendParticipants(true);
    };
    auto malformed = [&](NetPeer& p) {
        m_stats.countMalformed();
        report(peerId(p.peer), [](PeerReport& r) { ++r.malformed; });
        if (++p.malformed > m_config.malformedLimit && !p.kicked) {
            m_malformedKicks.fetch_add(1);
            kick(p, RefuseReason::Malformed);
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
            p.sync = h.sync;
            p.volumeCodec = h.volumeCodec;
            report(id, [&](PeerReport& r) {
                r.hello = true;
                r.name = h.name;
                r.role = h.role;
                r.sync = h.sync;
            });
            if (viewTooLarge(h.view)) {
                p.kicked = true;
                report(id, [](PeerReport& r) { r.kicked = true; });
                enet_peer_disconnect(p.peer, uint32_t(RefuseReason::BadHello));
                return true;
            }
            Welcome w;
            w.clientId = id;
            w.serverTimeUs = now;
            {
                // dims and spacing never change after construction; no lock needed for reading.
                w.volumeDims = s.volume.dims();
                w.spacing = s.volume.spacing();
            }
            w.volumeName = m_config.volumeName; // at most kMaxVolumeNameBytes (checkedConfig)
            w.maxViewPixels = uint32_t(m_config.maxViewPixels);
            sendTo(p.peer, Channel::Control, encodeMessage(w));
            sendTo(p.peer, Channel::Control, m_sceneMessage); // the scene: net/scene.h
            s.follow.setView(id, h.view);
            sendParticipants(true);
            if (!s.annotations.empty())
                sendTo(p.peer, Channel::Control, annotationList());
            SimEvent ev = makeEvent(SimEvent::Kind::Join, id);
            ev.inFlight = p.inFlight;
            ev.camera = toCamera(h.view);
            ev.codec = h.codec;
            ev.sync = h.sync;
            ev.volumeCodec = h.volumeCodec;
            s.push(std::move(ev));
            return true;
        }
        switch (MessageType(type)) {
        case MessageType::ViewRequest: {
            ViewRequest r;
            if (!decodeMessage(data, r))
                return false;
            if (viewTooLarge(r.view)) {
                m_viewsRefused.fetch_add(1);
                report(id, [](PeerReport& rep) { ++rep.viewsRefused; });
                return true; // well-formed, but more than we serve: dropped and counted
            }
            SimEvent ev = makeEvent(SimEvent::Kind::View, id);
            ev.camera = toCamera(r.view);
            ev.viewId = r.requestId;
            s.push(std::move(ev));
            ParticipantView seen{id, r.view};
            for (uint16_t f : s.follow.setView(id, r.view)) // instructors viewing as this one
                if (auto fp = s.peers.find(f); fp != s.peers.end())
                    sendTo(fp->second.peer, Channel::Control, encodeMessage(seen));
            return true;
        }
        case MessageType::ViewAs: { // net/view_follow.h
            ViewAs m;
            if (!decodeMessage(data, m))
                return false;
            if (p.helloMsg.role == Role::Instructor)
                if (const auto view = s.follow.follow(id, m.clientId)) {
                    ParticipantView seen{m.clientId, *view};
                    sendTo(p.peer, Channel::Control, encodeMessage(seen));
                }
            return true;
        }
        case MessageType::ToolState: {
            ToolState t;
            if (!decodeMessage(data, t))
                return false;
            // Forces and cutting both take the unit rotation (the message only bounds its norm).
            t.orientation = glm::normalize(t.orientation);
            try {
                shapeOf(t).validate();
            } catch (const Error&) {
                return false; // a diameter the tool cannot have
            }
            report(id, [](PeerReport& r) { ++r.toolStates; });
            // A paused drill (taken over, or an instructor holding nobody) still touches the
            // bone, as a burr that does not spin: forces, relays, no cutting.
            if (t.drilling && !s.mayCut(id, p.helloMsg.role)) {
                t.drilling = false;
                m_drillingPaused.fetch_add(1);
            }
            if (m_config.hapticModels)
                answerHaptic(p, t, now);
            SimEvent ev = makeEvent(SimEvent::Kind::Tool, id);
            ev.tool = t;
            ev.arrivedUs = now;
            if (!s.pushTool(std::move(ev), m_config.maxQueuedToolStates))
                m_toolStatesDropped.fetch_add(1);
            ToolRelay relay{id, t};
            std::vector<uint8_t> bytes = encodeMessage(relay);
            for (auto& [otherId, other] : s.peers)
                if (otherId != id && other.hello && !other.kicked)
                    sendTo(other.peer, Channel::ToolState, bytes);
            return true;
        }
        case MessageType::SyncMode: {
            SyncMode m;
            if (!decodeMessage(data, m))
                return false;
            const bool changed = p.sync != m.sync;
            // The mode and codec the client already has: nothing to do. (Each switch to volume
            // encodes the whole volume on the simulation thread; a client repeating it would
            // slow every other one.)
            if (!changed && m.volumeCodec == p.volumeCodec)
                return true;
            p.sync = m.sync;
            p.volumeCodec = m.volumeCodec;
            report(id, [&](PeerReport& r) {
                r.sync = m.sync;
                ++r.syncSwitches;
            });
            if (changed)
                sendParticipants();
            // Each switch to volume encodes the whole volume on the simulation thread, so a peer
            // switching back and forth as fast as it can send would slow everyone: a switch
            // within kSyncSwitchIntervalUs of the last one waits, and what reaches the simulation
            // then is the latest mode.
            if (now - p.syncPushedUs >= kSyncSwitchIntervalUs) {
                pushSync(id, p, now);
            } else if (!p.syncDeferred) {
                p.syncDeferred = true;
                ++s.syncsDeferred;
            }
            return true;
        }
        case MessageType::Annotate: {
            Annotate a;
            if (!decodeMessage(data, a))
                return false;
            // Well-formed but not allowed: counted, not applied (and not malformed).
            auto refuse = [&] {
                m_annotationsRefused.fetch_add(1);
                return true;
            };
            if (p.helloMsg.role != Role::Instructor)
                return refuse();
            switch (a.op) {
            case Annotate::Op::Add:
                if (s.annotations.size() >= kMaxAnnotations || s.nextAnnotationId == 0)
                    return refuse();
                s.annotations[s.nextAnnotationId] = {s.nextAnnotationId, id, a.position, a.label};
                ++s.nextAnnotationId;
                break;
            case Annotate::Op::Remove:
                if (!s.annotations.erase(a.id))
                    return true; // already gone (another instructor removed it): nothing to do
                break;
            case Annotate::Op::Clear:
                if (s.annotations.empty())
                    return true;
                s.annotations.clear();
                break;
            }
            marksOut.mark(); // sent from the loop (kAnnotationsIntervalUs)
            return true;
        }
        case MessageType::TakeOver: {
            TakeOver m;
            if (!decodeMessage(data, m))
                return false;
            auto refuse = [&] {
                m_takeOversRefused.fetch_add(1);
                return true;
            };
            if (p.helloMsg.role != Role::Instructor)
                return refuse();
            if (m.trainee == 0) {
                if (s.releaseTakeOvers(id))
                    sendParticipants();
                return true;
            }
            auto target = s.peers.find(m.trainee);
            if (target == s.peers.end() || !target->second.hello || target->second.kicked ||
                target->second.helloMsg.role != Role::Trainee)
                return refuse();
            auto held = s.takenOver.find(m.trainee);
            if (held != s.takenOver.end()) {
                if (held->second != id)
                    return refuse(); // another instructor's: handed back first
                return true;         // already ours
            }
            s.releaseTakeOvers(id); // one trainee at a time
            s.takenOver[m.trainee] = id;
            sendParticipants();
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
            if (s.peers.size() >= m_config.maxClients) {
                ev.peer->data = nullptr;
                m_refusedFull.fetch_add(1);
                enet_peer_disconnect(ev.peer, uint32_t(RefuseReason::ServerFull));
                return;
            }
            disableThrottle(ev.peer);
            // After 65535 joins the ids wrap: skip any still held (peers <= maxClients, so one
            // is free within maxClients + 1 tries).
            uint16_t id = 0;
            do {
                id = s.nextId++;
                if (s.nextId == 0)
                    s.nextId = 1;
            } while (s.peers.count(id));
            ev.peer->data = reinterpret_cast<void*>(uintptr_t(id));
            s.peers[id].peer = ev.peer;
            s.peers[id].connectedUs = steadyNowUs();
            // A fresh report: after the ids wrap, one may still hold a left peer's figures.
            report(id, [](PeerReport& r) {
                r = PeerReport{};
                r.connectedUs = steadyNowUs();
            });
            m_clientCount = s.peers.size();
            return;
        }
        case ENET_EVENT_TYPE_DISCONNECT: {
            auto id = uint16_t(reinterpret_cast<uintptr_t>(ev.peer->data));
            ev.peer->data = nullptr;
            if (id)
                report(id, [](PeerReport& r) { r.disconnectedUs = steadyNowUs(); });
            auto gone = id ? s.peers.find(id) : s.peers.end();
            if (gone != s.peers.end()) {
                const bool listed = gone->second.hello && !gone->second.kicked;
                if (gone->second.syncDeferred)
                    --s.syncsDeferred; // it left: nothing to switch
                s.peers.erase(gone);
                s.releaseTakeOvers(id);
                s.follow.leave(id);
                s.push(makeEvent(SimEvent::Kind::Leave, id));
                m_clientCount = s.peers.size();
                if (listed)
                    sendParticipants(true);
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
            report(id, [&](PeerReport& r) {
                r.bytesIn += ev.packet->dataLength;
                ++r.messagesIn;
            });
            if (!handle(id, it->second, {ev.packet->data, ev.packet->dataLength}))
                malformed(it->second);
            return;
        }
        default:
            return;
        }
    };

    while (!m_stop.load()) {
        // Wait on the socket and the wake-up together, then handle everything pending.
        s.waitNetwork(1);
        s.host.service(0, onEvent);
        std::map<uint16_t, PendingUpdate> out;
        std::map<uint16_t, PendingVolume> outVolume;
        std::vector<uint16_t> refused;
        {
            std::lock_guard lock(s.outMutex);
            refused.swap(s.volumeRefused);
            // A peer with too much still in ENet's hands gets nothing now: its update stays in
            // the outbox, where the next changes merge into it (ServerConfig::maxInFlightBytes).
            auto take = [&](auto& box, auto& into) {
                for (auto it = box.begin(); it != box.end();) {
                    auto peer = s.peers.find(it->first);
                    if (peer != s.peers.end() && !peer->second.kicked &&
                        peer->second.inFlight->load(std::memory_order_relaxed) >
                            m_config.maxInFlightBytes) {
                        ++it;
                        continue;
                    }
                    into.insert(std::move(*it));
                    it = box.erase(it);
                }
            };
            take(s.outbox, out);
            take(s.volumeOutbox, outVolume);
        }
        auto countSent = [&](Sync mode, bool full, uint32_t bytes, uint32_t rawBytes) {
            std::lock_guard lock(s.reportMutex);
            ModeTotals& t = s.modeTotals[size_t(mode)];
            ++t.updates;
            t.fullUpdates += full;
            t.bytes += bytes;
            t.rawBytes += rawBytes;
        };
        for (uint16_t id : refused) {
            auto it = s.peers.find(id);
            if (it == s.peers.end() || it->second.kicked)
                continue;
            std::fprintf(stderr,
                         "trephine server: client %u: the whole volume does not fit a message "
                         "in its volume codec; disconnected (volume sync refused)\n",
                         unsigned(id));
            kick(it->second, RefuseReason::VolumeTooLarge);
        }
        for (auto& [id, u] : out) {
            auto it = s.peers.find(id);
            if (it != s.peers.end() && !it->second.kicked) {
                if (sendTo(it->second.peer, Channel::Image, u.message, it->second.inFlight))
                    countSent(Sync::Dbi, u.full, u.payloadBytes, u.rawBytes);
            }
        }
        for (auto& [id, u] : outVolume) {
            auto it = s.peers.find(id);
            if (it != s.peers.end() && !it->second.kicked) {
                if (sendTo(it->second.peer, Channel::Volume, u.message, it->second.inFlight))
                    countSent(Sync::Volume, u.full, u.payloadBytes, u.rawBytes);
            }
        }
        if (!out.empty() || !outVolume.empty())
            s.host.flush();
        for (const auto& [id, p] : s.peers) {
            const int64_t held = p.inFlight->load(std::memory_order_relaxed);
            if (held > m_peakInFlight.load(std::memory_order_relaxed))
                m_peakInFlight.store(held, std::memory_order_relaxed);
        }
        uint64_t now = steadyNowUs();
        // A connection that never says hello would hold a client slot for good.
        const uint64_t helloTimeoutUs = uint64_t(double(m_config.helloTimeoutS) * 1e6);
        for (auto& [id, p] : s.peers)
            if (!p.hello && !p.kicked && now - p.connectedUs > helloTimeoutUs) {
                m_helloTimeouts.fetch_add(1);
                kick(p, RefuseReason::BadHello);
            }
        // The marks go out at most every kAnnotationsIntervalUs, the whole list once: a peer
        // editing fast (any hello may claim the instructor's role) cannot make the server queue a
        // list per edit for every participant on the reliable channel.
        if (marksOut.due(now))
            sendToParticipants(annotationList());
        if (rosterOut.due(now))
            sendRoster();
        // A mode switch that came too soon after the last one reaches the simulation now, as the
        // peer's latest mode (see the SyncMode handler).
        for (auto& [id, p] : s.peers)
            if (p.syncDeferred && !p.kicked && now - p.syncPushedUs >= kSyncSwitchIntervalUs)
                pushSync(id, p, now);
        if (now >= nextTick) {
            m_stats.tick(now);
            nextTick = now + 1000000;
        }
    }

    // Say goodbye so clients print a reason, and give the goodbyes a moment to leave. Every peer
    // is gone from here on, whether or not its goodbye is acknowledged in time: the report says
    // so (it listed them as connected, and counted them per mode, beside "clients": 0).
    const uint64_t goodbyeUs = steadyNowUs();
    for (auto& [id, p] : s.peers) {
        enet_peer_disconnect(p.peer, uint32_t(RefuseReason::Shutdown));
        report(id, [&](PeerReport& r) {
            if (r.disconnectedUs == 0)
                r.disconnectedUs = goodbyeUs;
        });
    }
    uint64_t deadline = steadyNowUs() + 200000;
    while (!s.peers.empty() && steadyNowUs() < deadline)
        s.host.service(5, [&](const ENetEvent& ev) {
            if (ev.type == ENET_EVENT_TYPE_DISCONNECT) {
                auto id = uint16_t(reinterpret_cast<uintptr_t>(ev.peer->data));
                if (id && s.peers.erase(id))
                    s.push(makeEvent(SimEvent::Kind::Leave, id));
            } else if (ev.type == ENET_EVENT_TYPE_CONNECT) {
                // Arrived while the server says goodbye: told why at once (it waited, unwelcomed,
                // for ENet's timeout and then read "the connection was lost").
                enet_peer_disconnect(ev.peer, uint32_t(RefuseReason::Shutdown));
            }
        });
    m_clientCount = 0;
}

// [SECTION] simulation thread

void SessionServer::simulationLoop() {
    nameThread("trephine-sim");
    Impl& s = *m_impl;
    std::vector<SimEvent> batch;
    // [Volume mode] A client with more than maxInFlightBytes unacknowledged keeps its update in
    // the outbox; a newer change merged into it was coded again at every batch (a held whole
    // volume: a whole volume's encode per drilling batch, for as long as a slow link stayed
    // behind, everyone's updates waiting). While held with one waiting, a change is only noted
    // (merged into deferredVolume) and coded once the waiting one has gone. Volume lock held.
    using Deferred = SimClient::DeferredVolume;
    auto postOrDefer = [&](uint16_t id, SimClient& c, std::optional<Deferred> d) {
        if (c.deferredVolume) {
            if (d) {
                d->box.merge(c.deferredVolume->box);
                d->full = d->full || c.deferredVolume->full;
                d->materials = d->materials || c.deferredVolume->materials;
                d->causeUs = std::min(d->causeUs, c.deferredVolume->causeUs);
                d->erodeUs += c.deferredVolume->erodeUs; // every batch's erosion it carries
            } else {
                d = c.deferredVolume;
            }
        }
        if (!d)
            return;
        const bool held =
            c.inFlight && c.inFlight->load(std::memory_order_relaxed) > m_config.maxInFlightBytes;
        bool waiting = false;
        if (held) {
            std::lock_guard lock(s.outMutex);
            waiting = s.volumeOutbox.count(id) > 0;
        }
        if (held && waiting) {
            c.deferredVolume = d;
            return;
        }
        c.deferredVolume.reset();
        s.postVolumeOrRefuse(id, c, d->box, d->full, d->materials, d->causeUs, d->erodeUs);
    };
    // After the posts (a change posted is in the outbox before it stops counting here).
    auto countDeferred = [&] {
        s.volumesDeferred =
            int(std::count_if(s.simClients.begin(), s.simClients.end(),
                              [](const auto& kv) { return kv.second.deferredVolume.has_value(); }));
    };
    for (;;) {
        {
            std::unique_lock lock(s.inMutex);
            s.inCv.wait_for(lock, std::chrono::milliseconds(10),
                            [&] { return !s.inbox.empty() || s.stopSim.load(); });
            if (s.inbox.empty() && s.stopSim.load())
                return;
            batch.clear();
            batch.swap(s.inbox);
            s.inboxTools = 0;
            s.busy = !batch.empty();
        }
        if (batch.empty()) {
            // Updates noted for clients that were held back go once they can.
            if (s.volumesDeferred.load() > 0) {
                std::lock_guard volumeLock(s.volumeMutex);
                for (auto& [id, c] : s.simClients)
                    if (c.sync == Sync::Volume)
                        postOrDefer(id, c, std::nullopt);
                countDeferred();
            }
            continue;
        }

        std::lock_guard volumeLock(s.volumeMutex);
        Box3i changed;
        uint64_t causeUs = 0;
        uint64_t erodeUs = 0;                    // erosion and cuts of this batch
        bool changedMaterials = false;           // voxels written wholesale (submitVoxels)
        std::map<uint16_t, uint64_t> needFull;   // DBI client -> cause time of a full DBI
        std::map<uint16_t, uint64_t> needVolume; // volume client -> cause time of a full volume
        for (SimEvent& ev : batch) {
            switch (ev.kind) {
            case SimEvent::Kind::Join:
            case SimEvent::Kind::View: {
                SimClient& c = s.simClients[ev.client];
                c.camera = ev.camera;
                c.viewId = ev.viewId;
                if (ev.kind == SimEvent::Kind::Join) {
                    c.inFlight = ev.inFlight;
                    c.deferredVolume.reset();
                    c.codec = ev.codec;
                    c.sync = ev.sync;
                    c.volumeCodec = ev.volumeCodec;
                    if (c.sync == Sync::Volume)
                        needVolume[ev.client] = steadyNowUs();
                }
                // A volume client renders its views itself; the server only keeps the camera for
                // a later switch to DBI. A DBI client's unsent image belongs to the view it
                // leaves (maybe another size, even under the same id): dropped, the full image
                // of the new view replaces it and the shadow.
                if (c.sync == Sync::Dbi) {
                    needFull[ev.client] = steadyNowUs();
                    s.dropPending(ev.client, Sync::Dbi);
                }
                break;
            }
            case SimEvent::Kind::Sync: {
                auto it = s.simClients.find(ev.client);
                if (it == s.simClients.end())
                    break;
                SimClient& c = it->second;
                c.sync = ev.sync;
                c.volumeCodec = ev.volumeCodec;
                if (c.sync == Sync::Volume) {
                    needFull.erase(ev.client);
                    needVolume[ev.client] = steadyNowUs();
                    s.dropPending(ev.client, Sync::Dbi);
                    c.shadow = Dbi(); // the next DBI it gets is a full one
                } else {
                    needVolume.erase(ev.client);
                    needFull[ev.client] = steadyNowUs();
                    s.dropPending(ev.client, Sync::Volume);
                    c.deferredVolume.reset();
                }
                break;
            }
            case SimEvent::Kind::Leave:
                s.simClients.erase(ev.client);
                needFull.erase(ev.client);
                needVolume.erase(ev.client);
                break;
            case SimEvent::Kind::Cut: {
                Box3i box = ev.box.intersect(s.volume.bounds());
                if (box.empty())
                    break;
                uint64_t e0 = steadyNowUs();
                {
                    std::unique_lock write(s.volumeRw);
                    s.volume.fill(box, 0, Material::Air);
                }
                erodeUs += steadyNowUs() - e0;
                changed.merge(box);
                causeUs = causeUs ? std::min(causeUs, ev.arrivedUs) : ev.arrivedUs;
                break;
            }
            case SimEvent::Kind::Voxels: {
                const Box3i& box = ev.box; // checked by submitVoxels
                uint64_t e0 = steadyNowUs();
                {
                    std::unique_lock write(s.volumeRw);
                    size_t i = 0;
                    for (int z = box.lo.z; z < box.hi.z; ++z)
                        for (int y = box.lo.y; y < box.hi.y; ++y)
                            for (int x = box.lo.x; x < box.hi.x; ++x, ++i)
                                s.volume.set(x, y, z, ev.density[i], Material(ev.material[i]));
                }
                erodeUs += steadyNowUs() - e0;
                changed.merge(box);
                changedMaterials = true;
                causeUs = causeUs ? std::min(causeUs, ev.arrivedUs) : ev.arrivedUs;
                break;
            }
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
                    c.driller->shape().diameterMm != shape.diameterMm) {
                    c.driller.emplace(shape);
                    c.lastDrilling = false; // another tool: nothing to sweep from
                }
                // The step is the time between the client's own timestamps (time passed in).
                float dt = 0.0f;
                if (c.hasTool && t.clientTimeUs > c.lastClientUs)
                    dt = std::min(float(double(t.clientTimeUs - c.lastClientUs) * 1e-6),
                                  m_config.maxStepS);
                c.hasTool = true;
                c.lastSequence = t.sequence;
                c.lastClientUs = t.clientTimeUs;
                m_toolStatesApplied.fetch_add(1);
                const ToolPose pose{t.position, t.orientation};
                const ToolPose from = c.lastPose;
                const bool sweep = c.lastDrilling;
                c.lastPose = pose;
                c.lastDrilling = t.drilling && t.speed > 0.0f;
                if (!t.drilling || t.speed <= 0.0f) {
                    // Lifted clear of bone between holes, the perforator's clutch re-engages
                    // (this thread is the volume's only writer: reading it needs no lock).
                    c.driller->observe(s.volume, pose);
                    break;
                }
                if (dt <= 0.0f)
                    break;
                // The cutter moved from the last drilling pose to this one during dt: it sweeps
                // the path (a quarter voxel a sub-step, dt shared out), so a fast stroke cuts a
                // groove rather than dents at the sampled poses. The lock is taken per sub-step so
                // that a haptic answer never waits for more than one.
                const glm::vec3 spacing = s.volume.spacing(); // fixed at construction
                const float quarterVoxel = 0.25f * std::min({spacing.x, spacing.y, spacing.z});
                const std::vector<ToolPose> path =
                    sweep ? sweepPoses(from, pose, quarterVoxel, m_config.maxSweepMm)
                          : std::vector<ToolPose>{pose};
                const float stepDt = dt / float(path.size());
                uint64_t e0 = steadyNowUs();
                bool any = false;
                for (const ToolPose& p : path) {
                    DrillResult r;
                    {
                        std::unique_lock write(s.volumeRw);
                        r = c.driller->drill(s.volume, p, t.speed, stepDt);
                    }
                    if (!r.changed.empty()) {
                        changed.merge(r.changed);
                        any = true;
                    }
                }
                erodeUs += steadyNowUs() - e0;
                if (any)
                    causeUs = causeUs ? std::min(causeUs, ev.arrivedUs) : ev.arrivedUs;
                break;
            }
            }
        }
        // Volume clients: the changed voxels themselves, or the whole volume after a join or a
        // switch (which already holds this batch's change). Posted first: they need none of the
        // rendering below, so in a mixed session they never wait for the DBI clients' renders.
        for (auto& [id, c] : s.simClients) {
            if (c.sync != Sync::Volume)
                continue;
            auto full = needVolume.find(id);
            if (full != needVolume.end())
                postOrDefer(id, c, Deferred{s.volume.bounds(), true, true, full->second, 0});
            else if (!changed.empty())
                postOrDefer(id, c,
                            Deferred{changed, false, changedMaterials, causeUs, uint32_t(erodeUs)});
            else
                postOrDefer(id, c, std::nullopt);
        }
        countDeferred();
        // Erosion only lowers densities, so the views' hit caches stay valid; voxels written
        // wholesale may raise them, which invalidates every cache (the next render restarts it).
        // With no DBI client the grid waits (syncGrid): nothing here renders.
        if (changedMaterials)
            s.gridRebuildPending = true;
        else
            s.gridPending.merge(changed);
        uint32_t gridUs = 0;
        if (std::any_of(s.simClients.begin(), s.simClients.end(),
                        [](const auto& c) { return c.second.sync == Sync::Dbi; })) {
            const uint64_t g0 = steadyNowUs();
            s.syncGrid();
            // The brick grid is rendering data: its update counts in each view's render stage.
            gridUs = uint32_t(steadyNowUs() - g0);
        }

        // Frames of views no DBI client holds any more are dropped.
        auto dbiView = [](const SimClient& c, const Camera& cam) {
            return c.sync == Sync::Dbi && c.camera == cam;
        };
        std::erase_if(s.views, [&](const ViewFrame& v) {
            return std::none_of(s.simClients.begin(), s.simClients.end(),
                                [&](const auto& c) { return dbiView(c.second, v.camera); });
        });
        for (const auto& [id, c] : s.simClients) {
            if (c.sync != Sync::Dbi)
                continue;
            auto it = std::find_if(s.views.begin(), s.views.end(),
                                   [&](const ViewFrame& v) { return v.camera == c.camera; });
            if (it == s.views.end()) {
                ViewFrame& v = s.views.emplace_back();
                v.camera = c.camera;
                v.frame = s.renderer.render(c.camera, &v.cache);
                m_renders.fetch_add(1);
            }
        }
        for (ViewFrame& v : s.views) {
            // The frame first takes the change, so a full refresh sent now holds it too.
            PixelRect rect;
            uint32_t renderUs = gridUs;
            if (!changed.empty()) {
                rect = dirtyScreenRect(v.camera, s.volume, changed);
                if (!rect.empty()) {
                    uint64_t r0 = steadyNowUs();
                    // The paper's way re-renders the whole view, through the view's hit cache as
                    // the volume client's re-render does (uncached, it was ~1 ms a cycle slower
                    // than the baseline's same render, and the study compared the two).
                    if (m_fullRender.load())
                        s.renderer.render(v.camera, v.frame.bounds(), v.frame, &v.cache);
                    else
                        s.renderer.render(v.camera, rect, v.frame, &v.cache);
                    renderUs += uint32_t(steadyNowUs() - r0);
                    m_renders.fetch_add(1);
                }
            }
            for (auto& [id, c] : s.simClients) {
                if (!dbiView(c, v.camera))
                    continue;
                auto full = needFull.find(id);
                if (full != needFull.end())
                    s.post(id, c, v, v.frame.bounds(), true, full->second, 0, 0, 0);
                else if (!rect.empty())
                    s.post(id, c, v, rect, false, causeUs, uint32_t(erodeUs), renderUs, gridUs);
            }
        }
        std::lock_guard lock(s.inMutex);
        s.busy = false;
    }
}

} // namespace trephine::net

// [SECTION] report

namespace trephine::net {

std::string SessionServer::reportJson() const {
    const Impl& s = *m_impl;
    std::string j = "{\n";
    j += "  \"port\": " + std::to_string(port()) + ",\n";
    j += "  \"volume\": " + jsonString(m_config.volumeName) + ",\n";
    j += "  \"max_clients\": " + std::to_string(m_config.maxClients) + ",\n";
    j += "  \"clients\": " + std::to_string(m_clientCount.load()) + ",\n";
    j += "  \"tool_states_applied\": " + std::to_string(m_toolStatesApplied.load()) + ",\n";
    j += "  \"tool_states_dropped\": " + std::to_string(m_toolStatesDropped.load()) + ",\n";
    j += "  \"renders\": " + std::to_string(m_renders.load()) + ",\n";
    j += "  \"haptic_models_sent\": " + std::to_string(m_hapticSent.load()) + ",\n";
    j += "  \"haptic_relays_sent\": " + std::to_string(m_hapticRelayed.load()) + ",\n";
    j += "  \"malformed_dropped\": " + std::to_string(m_stats.malformed()) + ",\n";
    j += "  \"disconnected_for_malformed\": " + std::to_string(m_malformedKicks.load()) + ",\n";
    j += "  \"refused_server_full\": " + std::to_string(m_refusedFull.load()) + ",\n";
    j += "  \"hello_timeouts\": " + std::to_string(m_helloTimeouts.load()) + ",\n";
    j += "  \"views_refused\": " + std::to_string(m_viewsRefused.load()) + ",\n";
    j += "  \"annotations_refused\": " + std::to_string(m_annotationsRefused.load()) + ",\n";
    j += "  \"take_overs_refused\": " + std::to_string(m_takeOversRefused.load()) + ",\n";
    j += "  \"drilling_paused\": " + std::to_string(m_drillingPaused.load()) + ",\n";
    j += "  \"channels\": " + jsonChannels(m_stats) + ",\n";
    std::lock_guard lock(s.reportMutex);
    j += "  \"force_compute_us\": " + jsonWindow(s.forceComputeUs) + ",\n";
    j += "  \"modes\": {";
    for (Sync mode : {Sync::Dbi, Sync::Volume}) {
        const ModeTotals& t = s.modeTotals[size_t(mode)];
        const ModeReport& m = s.modeReport[size_t(mode)];
        uint64_t clients = 0;
        for (const auto& [id, r] : s.peerReport)
            clients += r.hello && !r.kicked && r.disconnectedUs == 0 && r.sync == mode;
        j += std::string(mode == Sync::Dbi ? "" : ",") + "\n    " +
             jsonString(mode == Sync::Dbi ? "dbi" : "volume") +
             ": {\"clients\": " + std::to_string(clients) +
             ", \"updates_sent\": " + std::to_string(t.updates) +
             ", \"full_updates_sent\": " + std::to_string(t.fullUpdates) +
             ", \"bytes_sent\": " + std::to_string(t.bytes) +
             ", \"raw_bytes_sent\": " + std::to_string(t.rawBytes) +
             ", \"erode_us\": " + jsonWindow(m.erodeUs) +
             ", \"render_us\": " + jsonWindow(m.renderUs) +
             ", \"encode_us\": " + jsonWindow(m.encodeUs) + "}";
    }
    j += "\n  },\n";
    j += "  \"haptic_service_us\": " + jsonWindow(s.hapticServiceUs) + ",\n";
    j += "  \"peers\": [";
    bool first = true;
    for (const auto& [id, r] : s.peerReport) {
        j += std::string(first ? "" : ",") + "\n    {\"id\": " + std::to_string(id) +
             ", \"name\": " + jsonString(r.name) +
             ", \"role\": " + jsonString(r.role == Role::Instructor ? "instructor" : "trainee") +
             ", \"hello\": " + (r.hello ? "true" : "false") +
             ", \"connected\": " + (r.disconnectedUs == 0 ? "true" : "false") +
             ", \"bytes_in\": " + std::to_string(r.bytesIn) +
             ", \"bytes_out\": " + std::to_string(r.bytesOut) +
             ", \"messages_in\": " + std::to_string(r.messagesIn) +
             ", \"messages_out\": " + std::to_string(r.messagesOut) +
             ", \"tool_states\": " + std::to_string(r.toolStates) +
             ", \"haptic_models\": " + std::to_string(r.hapticModels) +
             ", \"haptic_relays\": " + std::to_string(r.hapticRelays) +
             ", \"malformed\": " + std::to_string(r.malformed) +
             ", \"views_refused\": " + std::to_string(r.viewsRefused) +
             ", \"sync\": " + jsonString(r.sync == Sync::Dbi ? "dbi" : "volume") +
             ", \"sync_switches\": " + std::to_string(r.syncSwitches) +
             ", \"kicked\": " + (r.kicked ? "true" : "false") + "}";
        first = false;
    }
    j += "\n  ]\n}\n";
    return j;
}

} // namespace trephine::net

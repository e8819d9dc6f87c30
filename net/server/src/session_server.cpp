#include "net/session_server.h"

#include "libsim/error.h"
#include "libsim/force_model.h"
#include "libsim/replacing_file.h"
#include "libsim/volume_io.h"
#include "net/debrief.h"
#include "net/fair_share.h"
#include "net/marks_file.h"
#include "net/outbox.h"
#include "net/replay_feed.h"
#include "net/send_passes.h"
#include "net/session_codes.h"
#include "net/session_gate.h"
#include "net/session_log.h"
#include "net/session_policy.h"
#include "net/sim_step.h"
#include "net/tool_model.h"
#include "net/view.h"

#include <poll.h>
#include <pthread.h>
#include <sys/eventfd.h>
#include <unistd.h>

#include <algorithm>
#include <condition_variable>
#include <cstdio>
#include <filesystem>
#include <map>
#include <mutex>
#include <shared_mutex>

namespace trephine::net {

// [SECTION] the host, the queues and the parts

namespace {

// The nice value of the server's background work: new views' rows and full images' coding take
// what the network thread, updates and the clients leave of the CPU.
constexpr int kBulkNice = 10;

// The config with its scene: the one given (a saved session's), or one built from the volume.
ServerConfig withScene(ServerConfig c, const Volume& volume) {
    if (!c.scene)
        c.scene = std::make_shared<const Scene>(buildScene(volume));
    return c;
}

// Admission and the foreign-address rule on raw datagrams (defined with the network pass).
int ENET_CALLBACK screenDatagram(ENetHost* host, ENetEvent*);

// ENet's intercept has no user pointer: the gate and report of the server whose host this thread
// services, set around each service call (one thread may pump several servers).
thread_local AdmissionGate* t_admission = nullptr;
thread_local ReportBook* t_book = nullptr;
class ScreenFor {
public:
    ScreenFor(AdmissionGate& gate, ReportBook& book) : m_gate(t_admission), m_book(t_book) {
        t_admission = &gate;
        t_book = &book;
    }
    ~ScreenFor() {
        t_admission = m_gate;
        t_book = m_book;
    }
    ScreenFor(const ScreenFor&) = delete;
    ScreenFor& operator=(const ScreenFor&) = delete;

private:
    AdmissionGate* m_gate;
    ReportBook* m_book;
};

StepConfig stepConfig(const ServerConfig& c, std::function<bool()> yield,
                      std::function<void()> letSend) {
    StepConfig s{c.maxStepS, c.maxSweepMm, c.renderThreads, {}};
    s.yield = std::move(yield);
    s.letSend = std::move(letSend);
    s.renderer = c.renderer;
    s.assessment.cautionMm = c.cautionMm;
    s.assessment.dangerMm = c.dangerMm;
    return s;
}

} // namespace

struct SessionServer::Impl {
    Impl(Volume v, const ServerConfig& c)
        : host(Host::listen(c.port, c.maxClients + c.admission.waitingSlots, c.bulkWindow)),
          wakeFd(eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC)),
          outbox(
              c.maxInFlightBytes, book, [this] { return clock(); },
              [this] {
                  sendPasses.posted();
                  wakeNetwork();
              }),
          step(std::move(v),
               stepConfig(
                   c, [this] { return eventsWaiting(); }, [this] { letSend(); }),
               outbox, book, [this] { return clock(); }),
          policy(withScene(c, step.volume()), step.volume().dims(), step.volume().spacing(), book,
                 [this](const ToolState& t, glm::vec3 velocity) { return force(t, velocity); }),
          gate(c, book), maxQueuedToolStates(c.maxQueuedToolStates),
          admission(
              host.get(), c.admission,
              [this](const ENetPeer* p) {
                  using Standing = AdmissionGate::Standing;
                  const auto id = uint16_t(reinterpret_cast<uintptr_t>(p->data));
                  if (id && policy.admitted(id))
                      return Standing::Admitted;
                  return id && gate.progressing(id) ? Standing::Progressing : Standing::Waiting;
              },
              [this](ENetPeer* p) { forgetPeer(p, clock()); }),
          control(c.controlBudgetBytes), recorder(c.recorder) {
        // The full image of a view larger than a slice is coded apart, as its rows are rendered
        // in chunks: the simulation thread never stops for a whole large frame.
        outbox.codeFullImagesApart(apartPixels, inlineCoder);
        host.get()->intercept = screenDatagram;
        book.record([&](ServerReport& r) {
            r.port = host.port();
            r.volume = c.volumeName;
            r.maxClients = c.maxClients;
        });
    }
    ~Impl() {
        if (wakeFd >= 0)
            ::close(wakeFd);
    }
    Impl(const Impl&) = delete;
    Impl& operator=(const Impl&) = delete;

    ReportBook book;
    NetStats stats;
    Host host;
    // Wakes the network thread's wait on the ENet socket when an update is posted, so it goes
    // out at once instead of after the rest of a 1 ms wait (-1: no eventfd; the network thread
    // then waits out its timeout).
    int wakeFd = -1;
    // The network thread's passes over the outbox, so the simulation can let what it posted go
    // out before another peer's chunked work (StepConfig::letSend, counted in the report). Before
    // the outbox and its coder, whose posts mark it.
    SendPasses sendPasses;
    // The time: the last one pump() was given, else the steady clock (before the first pump, and
    // once start()'s threads run).
    std::atomic<uint64_t> pumpedUs{0}; // 0: never pumped
    std::atomic<bool> threaded{false};
    uint64_t clock() const {
        const uint64_t pumped = pumpedUs.load();
        return threaded.load() || pumped == 0 ? steadyNowUs() : pumped;
    }
    // Where full images are coded apart: inline when pumped, a worker beside the threads. From
    // 256^2 up: a peer asking for new views every few ms would otherwise hold the simulation
    // thread for each one's coding (a 512^2 image: ~1 ms) while others' rectangles wait.
    const int64_t apartPixels = 256 * 256;
    InlineExecutor inlineCoder;
    WorkerExecutor workerCoder{"trephine-coder", kBulkNice};
    Outbox outbox;
    // The simulation step under stepMutex: the simulation thread per batch, inspection
    // (renderView, volumeSnapshot) between batches.
    std::mutex stepMutex;
    SimulationStep step;
    ForceModelCache forceModels; // network thread only
    SessionPolicy policy;        // network thread only
    SessionGate gate;            // network thread only: codes, sealing (docs/security.md)
    // [Network thread] What peers send, handled in fair order and charged to them, with every
    // other piece of work done for a peer here (docs/session.md, "Availability"). A pass handles
    // at most kReceiveSliceUs of it before it sends; the rest waits for the next pass.
    static constexpr uint64_t kReceiveSliceUs = 2000;
    // An update of more datagrams than this goes after a flush of the smaller ones before it.
    static constexpr size_t kLargeUpdateBytes = 16 * 1024;
    FairInbox received{[] { return steadyNowUs(); }};
    // New codes hashed on a worker, newest wins per role (inline when pumped).
    InlineExecutor inlineMint;
    WorkerExecutor workerMint{"trephine-codes", 10};
    CodeMint mint{inlineMint};
    std::map<uint16_t, uint64_t> netCharged; // what the report has of `received`'s charges
    std::map<uint16_t, ENetPeer*> links;     // policy ids -> ENet peers (network thread only)
    // The most bytes ENet held for one peer, of updates and of control messages: they grow only
    // as sendTo hands ENet a message, so it takes them there.
    int64_t peakInFlight = 0;
    int64_t peakControlBytes = 0;
    uint64_t nextTickUs = 0; // the channel statistics' next tick
    // guard's scans of every slot and peer (handshakes to reset, network charges to report, held
    // offers' hello clocks) run at most every kScanPeriodUs.
    uint64_t nextScanUs = 0;

    // Network -> simulation.
    std::mutex inMutex;
    std::condition_variable inCv;
    std::vector<LogRecord> inbox;
    // [Simulation thread] The batch being applied: swapped with the inbox each pass, so both keep
    // their capacity instead of growing anew.
    std::vector<LogRecord> batch;
    size_t inboxTools = 0; // Tool events in the inbox (ServerConfig::maxQueuedToolStates)
    size_t maxQueuedToolStates;
    bool busy = false; // the simulation thread is applying a batch (under inMutex)
    bool stopSim = false;
    // Events wait for the next batch: bulk rendering yields to them. Asked by the bulk pool's
    // threads before each column of tiles, so read without inMutex: a nice-10 thread preempted
    // holding it would stop the network thread's next push.
    std::atomic<bool> inboxWaiting{false}; // !inbox.empty(), written under inMutex
    bool eventsWaiting() const { return inboxWaiting.load(std::memory_order_relaxed); }
    // StepConfig::letSend: the network's next pass waited for, and counted.
    void letSend() {
        const bool passed = sendPasses.awaitPosted();
        book.record([&](ServerReport& r) {
            ++r.counters.sendWaits;
            r.counters.sendWaitsBounded += !passed;
        });
    }

    // [Availability] Connections not yet admitted (net/admission.h) and each peer's control
    // backlog (net/budgets.h); network thread only.
    AdmissionGate admission;
    ControlBudget control;
    std::map<uint16_t, Host::InFlight> controlHeld; // control bytes ENet holds, per peer
    AvailabilityCounters reported;                  // what the report has of the two above

    // [Network thread] A pass: receive() takes every datagram waiting and what the replay has
    // due; send() sends what the outbox lets go and what the policy has due by `now`.
    void receive(uint64_t now);
    void send(uint64_t now);
    // [Simulation thread] One batch: the events waiting, the next slice of a large view, or the
    // changes noted for held-back clients and the assessment's tick.
    void simulate(uint64_t now);
    // [Simulation thread] Applies what is still queued, then ends the assessment.
    void finishSimulation();
    SessionPolicy::ForceAnswer force(const ToolState& t, glm::vec3 velocity);
    void onEvent(const ENetEvent& ev);
    void handleReceived(uint16_t id, Channel channel, std::span<const uint8_t> data);
    void issueMinted(PolicyOutput& out);
    void apply(PolicyOutput& out, bool mayDrop = true);
    // [Replay] The timeline of a log served (serveLog; network thread only once started), the
    // log's start to rebuild from, and what other threads hand it and read of it.
    std::optional<ReplayPlayer> player;
    Volume replayStart;
    uint64_t replayStateSentUs = 0;
    mutable std::mutex replayMutex;
    std::vector<ReplayControl> replayControls;  // under replayMutex
    std::optional<ReplayState> replayPublished; // under replayMutex
    void playReplayed();
    bool sendTo(uint16_t id, Channel ch, const std::vector<uint8_t>& bytes,
                const Host::InFlight& inFlight = {}, uint32_t lossPermille = 0);
    bool sendControl(uint16_t id, const std::vector<uint8_t>& bytes);
    void forget(uint16_t id, uint64_t now);     // a peer gone (disconnected, or its slot reset)
    void forgetPeer(ENetPeer* p, uint64_t now); // the peer in an ENet slot the gate resets
    void guard(uint64_t now);                   // admission and control budgets, once a pass
    void reportNetCharged(uint16_t id);         // the report's copy of its network charges
    void sendUpdates();
    void sendNotices();
    void sayGoodbye();
    void wakeNetwork();
    void waitNetwork(int timeoutMs);
    // [Any thread] Events for the simulation; tool states beyond maxQueuedToolStates are dropped
    // and counted, as a lossy link would drop them. With a recorder, the policy's `log` and the
    // events queued are written to the session log first, in the order the simulation gets them.
    void push(std::vector<LogRecord>& events, const std::vector<LogRecord>& log = {},
              bool mayDrop = true);
    std::shared_ptr<SessionRecorder> recorder;
    std::vector<LogRecord> logged; // push's records (under inMutex)
};

void SessionServer::Impl::wakeNetwork() {
    if (wakeFd >= 0) {
        uint64_t one = 1;
        [[maybe_unused]] ssize_t n = ::write(wakeFd, &one, sizeof one);
    }
}

// Waits up to timeoutMs for a datagram on the ENet socket or a wake-up.
void SessionServer::Impl::waitNetwork(int timeoutMs) {
    pollfd fds[2] = {{int(host.get()->socket), POLLIN, 0}, {wakeFd, POLLIN, 0}};
    if (::poll(fds, wakeFd >= 0 ? 2 : 1, timeoutMs) > 0 && wakeFd >= 0 &&
        (fds[1].revents & POLLIN)) {
        uint64_t count = 0;
        [[maybe_unused]] ssize_t n = ::read(wakeFd, &count, sizeof count);
    }
}

void SessionServer::Impl::push(std::vector<LogRecord>& events, const std::vector<LogRecord>& log,
                               bool mayDrop) {
    if (events.empty() && (log.empty() || !recorder))
        return;
    uint64_t dropped = 0;
    {
        std::lock_guard lock(inMutex);
        const size_t queued = inbox.size();
        // Every event carries its time, and its record the same, so a replay of the log times
        // the assessment's joins and leaves as this server does (SimulationStep::step).
        const uint64_t now = clock();
        for (LogRecord& ev : events) {
            if (!ev.timeUs)
                ev.timeUs = now;
            if (ev.is<ToolEvent>()) {
                if (mayDrop && inboxTools >= maxQueuedToolStates) {
                    ++dropped;
                    continue;
                }
                ++inboxTools;
            }
            inbox.push_back(std::move(ev));
        }
        inboxWaiting.store(!inbox.empty(), std::memory_order_relaxed);
        // Written before the simulation can take the events, and before the caller sends what
        // they caused: nothing a client sees is missing from the log after a crash.
        if (recorder) {
            logged.assign(log.begin(), log.end());
            logged.insert(logged.end(), inbox.begin() + ptrdiff_t(queued), inbox.end());
            recorder->write(logged);
        }
    }
    inCv.notify_one();
    step.yieldChanged();
    if (dropped)
        book.count(&ServerCounters::toolStatesDropped, dropped);
}

// [SECTION] lifetime

namespace {

void nameThread(const char* name) {
    pthread_setname_np(pthread_self(), name);
}

// Throws on a volume the session cannot carry: the welcome gives at most kMaxVolumeDim voxels an
// axis (files load up to 2^20).
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
    if (!(config.idleTimeoutS > 0.0f))
        throw Error("server: the idle timeout must be positive");
    // ENet numbers peers in 12 bits.
    if (config.maxClients + config.admission.waitingSlots > 4000)
        throw Error("server: --max-clients and the waiting slots come to more than 4000 peers");
    // Now, not at the end of the session: a path that cannot be written would lose it all.
    if (!config.saveOnExit.empty()) {
        checkSaveTarget(config.saveOnExit);
        // A NIfTI file holds densities only: the session would come back with its dura and brain
        // turned to bone.
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
    // Cut to fit, the name would name another file.
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
    m_config.scene = m_impl->policy.scene();
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
    // Once stopped, a server stays stopped: threads started then would end at once, unjoined.
    if (m_stop.load())
        return;
    // Its time would jump back from the pumped one to the steady clock.
    if (m_impl->pumpedUs.load() != 0)
        throw Error("start: this server is pumped (pump()); a server is pumped or started");
    if (m_started.exchange(true))
        return;
    m_impl->threaded = true;
    m_impl->outbox.codeFullImagesApart(m_impl->apartPixels, m_impl->workerCoder);
    m_impl->step.renderBulkApart(kBulkNice, m_impl->workerCoder);
    m_impl->mint.setWorker(m_impl->workerMint);
    m_netThread = std::thread([this] { networkLoop(); });
    m_simThread = std::thread([this] { simulationLoop(); });
}

void SessionServer::stop() {
    if (m_stop.exchange(true))
        return;
    if (m_netThread.joinable())
        m_netThread.join();
    {
        std::lock_guard lock(m_impl->inMutex);
        m_impl->stopSim = true;
    }
    m_impl->inCv.notify_all();
    if (m_simThread.joinable()) {
        m_simThread.join();
    } else { // pumped: this thread does what the two would do at the end
        m_impl->sayGoodbye();
        m_impl->finishSimulation();
    }
    // What the simulation posted after the network thread's last pass will never be sent: a
    // stopped server is idle.
    m_impl->outbox.clear();
    if (!m_config.saveOnExit.empty())
        saveSession();
    if (!m_config.debriefDir.empty())
        writeDebriefs();
}

// A debrief per participant (net/debrief.h); a folder that cannot be written loses only them.
void SessionServer::writeDebriefs() {
    std::lock_guard lock(m_impl->stepMutex);
    try {
        const Assessment& a = m_impl->step.assessment();
        m_debriefs =
            net::writeDebriefs(m_config.debriefDir, a, a.metrics(m_impl->clock()), a.timelines());
    } catch (const std::exception& e) {
        std::fprintf(stderr, "trephine server: no debrief: %s\n", e.what());
    }
}

// Writes saveOnExit and the marks beside it; should that fail, an emergency copy in the
// temporary folder, so the session's drilling is not lost to a full disk or a folder gone.
void SessionServer::saveSession() {
    std::lock_guard lock(m_impl->stepMutex);
    // The marks always, even none: an older file beside the volume would bring back marks this
    // session removed. Their keeper, the network thread, has stopped.
    std::vector<AnnotationInfo> marks;
    for (const auto& [id, a] : m_impl->policy.marks())
        marks.push_back(a);
    auto save = [&](const std::string& path) {
        saveVolume(m_impl->step.volume(), path);
        try {
            writeMarksFile(marksPathFor(path), marks);
            writeSceneFile(scenePathFor(path), *m_config.scene);
        } catch (...) {
            // The new volume is in place: older files beside it would come back with it.
            std::error_code ec;
            for (const std::string& beside : {marksPathFor(path), scenePathFor(path)})
                if (std::filesystem::is_regular_file(beside, ec))
                    std::filesystem::remove(beside, ec);
            throw;
        }
    };
    try {
        save(m_config.saveOnExit);
        m_savedTo = m_config.saveOnExit;
    } catch (const std::exception& e) {
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
            save(copy);
            m_savedTo = copy;
            std::fprintf(stderr,
                         "trephine server: the final volume, marks and scene are saved in %s "
                         "(with %s and %s) instead\n",
                         copy.c_str(), marksPathFor(copy).c_str(), scenePathFor(copy).c_str());
        } catch (const std::exception& e2) {
            std::fprintf(stderr, "trephine server: no emergency copy either: %s\n", e2.what());
        }
    }
}

// [SECTION] inspection

void SessionServer::submitBoxCut(const Box3i& box) {
    std::vector<LogRecord> events{{m_impl->clock(), CutEvent{box}}};
    m_impl->push(events);
}

void SessionServer::submitVoxels(const Box3i& box, std::vector<uint8_t> density,
                                 std::vector<uint8_t> material) {
    const Box3i bounds = m_impl->step.volume().bounds(); // fixed at construction
    if (box.empty() || !(box.intersect(bounds) == box))
        throw Error("submitVoxels: the box must be non-empty and inside the volume");
    if (density.size() != size_t(box.count()) || material.size() != density.size())
        throw Error("submitVoxels: give box.count() density and material bytes");
    for (uint8_t m : material)
        if (m >= uint8_t(kMaterialCount))
            throw Error("submitVoxels: unknown material label " + std::to_string(m));
    std::vector<LogRecord> events;
    events.push_back({m_impl->clock(), VoxelsEvent{box, std::move(density), std::move(material)}});
    m_impl->push(events);
}

void SessionServer::serveLog(std::vector<LogRecord> records, double speed, bool playing) {
    if (m_netThread.joinable())
        throw Error("serveLog: call it before start()");
    m_impl->player.emplace(std::move(records), speed, playing, m_impl->clock());
    m_impl->replayStart = m_impl->step.volume();
}

void SessionServer::controlReplay(const ReplayControl& control) {
    {
        std::lock_guard lock(m_impl->replayMutex);
        m_impl->replayControls.push_back(control);
    }
    m_impl->wakeNetwork();
}

std::optional<ReplayState> SessionServer::replayState() const {
    std::lock_guard lock(m_impl->replayMutex);
    return m_impl->replayPublished;
}

void SessionServer::setFullRenderUpdates(bool on) {
    m_impl->step.setFullRender(on);
}

Dbi SessionServer::renderView(const ViewSpec& view) {
    std::lock_guard lock(m_impl->stepMutex);
    return m_impl->step.render(toCamera(view));
}

std::string SessionServer::rendererName() const {
    std::lock_guard lock(m_impl->stepMutex);
    return m_impl->step.rendererName();
}

Volume SessionServer::volumeSnapshot() {
    std::lock_guard lock(m_impl->stepMutex);
    return m_impl->step.volume();
}

bool SessionServer::idle() {
    if (m_impl->policy.switchWaiting())
        return false;
    {
        std::lock_guard lock(m_impl->replayMutex);
        if (!m_impl->replayControls.empty())
            return false;
    }
    {
        std::lock_guard lock(m_impl->inMutex);
        if (!m_impl->inbox.empty() || m_impl->busy || m_impl->step.rendering())
            return false;
    }
    return m_impl->outbox.empty();
}

SecurityCounters SessionServer::security() const {
    return m_impl->book.read([](const ServerReport& r) { return r.security; });
}

ServerCounters SessionServer::counters() const {
    return m_impl->book.read([](const ServerReport& r) { return r.counters; });
}

uint64_t SessionServer::malformedTotal() const {
    return m_impl->stats.malformed();
}

const NetStats& SessionServer::stats() const {
    return m_impl->stats;
}

ModeTotals SessionServer::modeTotals(Sync mode) const {
    return m_impl->book.read([&](const ServerReport& r) { return r.modeTotals(mode); });
}

std::string SessionServer::reportJson() const {
    return m_impl->book.read([&](const ServerReport& r) { return toJsonText(r, m_impl->stats); });
}

// [SECTION] network thread

SessionPolicy::ForceAnswer SessionServer::Impl::force(const ToolState& t, glm::vec3 velocity) {
    const ForceModel& model = forceModels.get(shapeOf(t));
    const uint64_t c0 = steadyNowUs(); // a duration: real time, pumped or not
    SessionPolicy::ForceAnswer a;
    {
        std::shared_lock lock(step.voxelMutex());
        a.force = model.compute(step.volume(), ToolPose{t.position, t.orientation},
                                t.drilling ? t.speed : 0.0f, velocity);
    }
    a.computeUs = steadyNowUs() - c0;
    a.doneUs = clock();
    return a;
}

// False when ENet refused the packet (it is then not counted anywhere).
bool SessionServer::Impl::sendTo(uint16_t id, Channel ch, const std::vector<uint8_t>& bytes,
                                 const Host::InFlight& inFlight, uint32_t lossPermille) {
    if (ch == Channel::Control && !inFlight)
        return sendControl(id, bytes);
    auto link = links.find(id);
    if (bytes.empty() || link == links.end())
        return false;
    // A proven peer's messages go sealed (docs/security.md); the figures count what goes out, a
    // lossy message's parity included.
    const bool sealed = gate.sealing(id);
    const std::vector<uint8_t> sealedBytes =
        sealed ? gate.seal(id, ch, bytes) : std::vector<uint8_t>{};
    const std::vector<uint8_t>& wire = sealed ? sealedBytes : bytes;
    const size_t queued = host.send(link->second, ch, wire, inFlight, lossPermille);
    if (!queued)
        return false;
    if (inFlight) {
        int64_t& peak = ch == Channel::Control ? peakControlBytes : peakInFlight;
        peak = std::max(peak, inFlight->load(std::memory_order_relaxed));
    }
    stats.countOut(ch, queued);
    book.peer(id, [&](PeerReport& r) {
        r.bytesOut += queued;
        ++r.messagesOut;
        r.hapticModels += bytes[0] == uint8_t(MessageType::HapticModel);
        r.hapticRelays += bytes[0] == uint8_t(MessageType::HapticRelay);
    });
    return true;
}

// [SECTION] availability

// A control message within the peer's budget (net/budgets.h): sent, held as the latest of its
// kind until the backlog drains, or dropped.
bool SessionServer::Impl::sendControl(uint16_t id, const std::vector<uint8_t>& bytes) {
    if (!links.count(id))
        return false;
    Host::InFlight& held = controlHeld[id];
    if (!held)
        held = std::make_shared<std::atomic<int64_t>>(0);
    if (control.offer(id, bytes, held->load(std::memory_order_relaxed)) !=
        ControlBudget::Action::Send)
        return false;
    return sendTo(id, Channel::Control, bytes, held);
}

void SessionServer::Impl::forget(uint16_t id, uint64_t now) {
    // What it sent before it left is handled first, as it was sent (a flood's tail is dropped).
    const size_t dropped =
        received.drain(id, [this](uint16_t peer, Channel ch, std::span<const uint8_t> data) {
            handleReceived(peer, ch, data);
        });
    if (dropped)
        book.record([&](ServerReport& r) { r.availability.receivedDropped += dropped; });
    reportNetCharged(id);
    netCharged.erase(id);
    PolicyOutput out;
    policy.disconnect(id, now, out);
    gate.leave(id);
    links.erase(id);
    control.forget(id);
    controlHeld.erase(id);
    apply(out);
}

void SessionServer::Impl::forgetPeer(ENetPeer* p, uint64_t now) {
    const auto id = uint16_t(reinterpret_cast<uintptr_t>(p->data));
    p->data = nullptr;
    if (id)
        forget(id, now);
}

void SessionServer::Impl::reportNetCharged(uint16_t id) {
    if (const uint64_t c = received.charged(id); c != netCharged[id]) {
        netCharged[id] = c;
        book.peer(id, [&](PeerReport& r) { r.netChargedUs = c; });
    }
}

void SessionServer::Impl::guard(uint64_t now) {
    if (now >= nextScanUs) {
        nextScanUs = now + kScanPeriodUs;
        admission.reap(now);
        for (const auto& [id, peer] : links)
            reportNetCharged(id);
        for (uint16_t id : gate.held()) // a held offer's hello clock (seconds) stands still
            policy.holdHelloClock(id, now);
    }
    for (const auto& [id, answer] : gate.release(now))
        sendTo(id, Channel::Control, answer);
    auto heldBy = [&](uint16_t id) {
        auto it = controlHeld.find(id);
        return it == controlHeld.end() ? int64_t(0) : it->second->load(std::memory_order_relaxed);
    };
    if (control.holding())
        for (auto& [id, bytes] : control.due(heldBy))
            if (links.count(id))
                sendTo(id, Channel::Control, bytes, controlHeld[id]);
    AvailabilityCounters seen = reported;
    seen.admission = admission.counts();
    seen.controlCoalesced = control.counts().coalesced;
    seen.controlDropped = control.counts().dropped;
    seen.peakControlBytes = peakControlBytes;
    if (seen.admission == reported.admission &&
        seen.controlCoalesced == reported.controlCoalesced &&
        seen.controlDropped == reported.controlDropped &&
        seen.peakControlBytes == reported.peakControlBytes)
        return;
    reported = seen;
    book.record([&](ServerReport& r) {
        r.availability.admission = seen.admission;
        r.availability.controlCoalesced = seen.controlCoalesced;
        r.availability.controlDropped = seen.controlDropped;
        r.availability.peakControlBytes = seen.peakControlBytes;
    });
}

// Sends what the policy asked for; its events go to the simulation (and the log) first.
void SessionServer::Impl::apply(PolicyOutput& out, bool mayDrop) {
    push(out.events, out.log, mayDrop);
    for (const auto& [id, ack] : out.imageAcks)
        outbox.acknowledge(id, ack);
    // New codes first (those hashed by now: at once when pumped): the instructors' copies join
    // this output's messages.
    if (const std::optional<Salt> salt = gate.salt())
        for (const CodeRequest& r : std::exchange(out.newCodes, {}))
            mint.request(r, *salt, clock());
    issueMinted(out);
    for (const PolicyOutput::Message& m : out.messages)
        for (uint16_t id : m.to)
            sendTo(id, m.channel, m.bytes);
    if (out.flush)
        host.flush();
    for (uint16_t id : out.removed)
        gate.remove(id);
    if (out.allowRejoin)
        gate.allowRejoin();
    if (!out.replayControls.empty()) { // played at this pass's playReplayed()
        std::lock_guard lock(replayMutex);
        replayControls.insert(replayControls.end(), out.replayControls.begin(),
                              out.replayControls.end());
    }
    for (const PolicyOutput::Disconnect& d : out.disconnects)
        if (auto link = links.find(d.client); link != links.end())
            enet_peer_disconnect(link->second, d.data);
}

// The codes the mint has hashed: installed, told to every instructor, printed like the start
// banner for whoever reads them out; the hashing is charged to whoever asked.
void SessionServer::Impl::issueMinted(PolicyOutput& out) {
    for (CodeMint::Done& d : mint.take(clock())) {
        if (links.count(d.request.by))
            received.charge(d.request.by, d.us);
        if (!gate.install(d.request.role, d.minted.w)) {
            mint.request(d.request, *gate.salt(), clock()); // the other role's code: another
            continue;
        }
        policy.codeIssued(d.request.role, d.minted.code, out);
        std::printf("trephine server: %s\n",
                    codeIssuedLine(d.request.role, d.minted.code, d.request.byName).c_str());
        std::fflush(stdout);
    }
}

void SessionServer::Impl::onEvent(const ENetEvent& ev) {
    const uint64_t now = clock();
    PolicyOutput out;
    switch (ev.type) {
    case ENET_EVENT_TYPE_CONNECT: {
        const uint16_t id = policy.connect(ev.data, now, out);
        ev.peer->data = reinterpret_cast<void*>(uintptr_t(id));
        if (id == 0) {
            enet_peer_disconnect(ev.peer, out.disconnects.at(0).data);
            return;
        }
        disableThrottle(ev.peer);
        links[id] = ev.peer;
        sendTo(id, Channel::Control, gate.connect(id, ev.peer->address)); // the Challenge
        return;
    }
    case ENET_EVENT_TYPE_DISCONNECT: {
        const auto id = uint16_t(reinterpret_cast<uintptr_t>(ev.peer->data));
        ev.peer->data = nullptr;
        if (!id)
            return;
        forget(id, now);
        return;
    }
    case ENET_EVENT_TYPE_RECEIVE: {
        const auto id = uint16_t(reinterpret_cast<uintptr_t>(ev.peer->data));
        if (!id || !policy.live(id))
            return;
        const size_t bytes = ev.packet->dataLength;
        stats.countIn(Channel(std::min<int>(ev.channelID, int(Channel::Count) - 1)), bytes);
        book.peer(id, [&](PeerReport& r) {
            r.bytesIn += bytes;
            ++r.messagesIn;
        });
        // Handled in its turn (receive()); a peer with a full queue loses the message.
        if (!received.push(id, Channel(ev.channelID), {ev.packet->data, bytes}))
            book.record([](ServerReport& r) { ++r.availability.receivedDropped; });
        return;
    }
    default:
        return;
    }
}

// A message `id` sent, in its turn: opened by the gate, then the policy's.
void SessionServer::Impl::handleReceived(uint16_t id, Channel channel,
                                         std::span<const uint8_t> data) {
    if (!policy.live(id))
        return;
    const uint64_t now = clock();
    PolicyOutput out;
    {
        const SessionGate::Result in = gate.receive(id, channel, data, now);
        switch (in.kind) {
        case SessionGate::Result::Kind::Deliver:
            out = policy.receive(id, in.message, now);
            break;
        case SessionGate::Result::Kind::Reply:
            sendTo(id, Channel::Control, {in.message.begin(), in.message.end()});
            break;
        case SessionGate::Result::Kind::Proven:
            policy.authenticate(id, in.role);
            break;
        case SessionGate::Result::Kind::Held:
            break;
        case SessionGate::Result::Kind::Refuse:
            policy.refuse(id, in.refuse, now, out);
            break;
        case SessionGate::Result::Kind::Bad:
            out = policy.reject(id, now);
            break;
        }
    }
    if (out.malformed)
        stats.countMalformed();
    apply(out);
}

// A served log's timeline: the windows' controls, then the records due (after a rebuild from the
// start when a seek went backwards). Its tool states are the session's own, so none is dropped
// (the log holds only those its server applied).
void SessionServer::Impl::playReplayed() {
    if (!player)
        return;
    const uint64_t now = clock();
    bool changed = false;
    {
        std::lock_guard lock(replayMutex);
        for (const ReplayControl& c : replayControls)
            changed = player->control(c, now) || changed;
        replayControls.clear();
    }
    const bool wasPlaying = player->playing();
    ReplayPlayer::Due due = player->advance(now);
    changed = changed || wasPlaying != player->playing();
    PolicyOutput out;
    if (due.rewind) {
        policy.rewindReplay(out);
        VoxelsEvent start{replayStart.bounds(), {}, {}};
        replayStart.copyBox(start.box, start.density, start.material);
        out.events.push_back({now, std::move(start)});
    }
    if (!due.records.empty())
        policy.replayed(due.records, now, out);
    const ReplayState state = player->state(now);
    // The first pass's state is what every welcome carries from then on.
    if (changed || replayStateSentUs == 0 ||
        (state.playing && now - replayStateSentUs >= kReplayStateIntervalUs)) {
        policy.replayState(state, out);
        replayStateSentUs = now;
    }
    apply(out, false);
    // After the records are queued: a reader that sees this state and idle() sees them applied.
    std::lock_guard lock(replayMutex);
    replayPublished = state;
}

// Sends the updates the outbox lets go, and sends away the volume clients it refused.
void SessionServer::Impl::sendUpdates() {
    const SendPasses::Pass pass(sendPasses);
    Outbox::Taken taken = outbox.take([&](uint16_t id) { return policy.live(id); });
    PolicyOutput out;
    for (uint16_t id : taken.refused) {
        if (!policy.live(id))
            continue;
        std::fprintf(stderr,
                     "trephine server: client %u: the whole volume does not fit a message in "
                     "its volume codec; disconnected (volume sync refused)\n",
                     unsigned(id));
        policy.refuseVolume(id, clock(), out);
    }
    apply(out);
    // Updates in their clients' fair order (where each stands, not its lifetime total, which put
    // a long-standing trainee behind every newcomer's burst), and what is handed to ENet is
    // flushed before a large update joins it: a small rectangle does not wait behind another
    // peer's large one's datagrams (ENet's flush goes peer by peer in slot order). One flush for
    // all the small ones: each flush walks every peer slot, and one a client cost a classroom of
    // 64 its updates. Stable: a client's own stay in order.
    std::stable_sort(taken.updates.begin(), taken.updates.end(),
                     [&](const Outbox::Ready& a, const Outbox::Ready& b) {
                         return received.standing(a.client) < received.standing(b.client);
                     });
    bool handed = false;
    const int64_t peakBefore = peakInFlight;
    for (const Outbox::Ready& u : taken.updates) {
        if (handed && u.message.size() > kLargeUpdateBytes) {
            host.flush();
            handed = false;
        }
        // Sealing and handing it to ENet (a whole volume's fragments) is work for that client.
        const uint64_t t0 = received.now();
        const Host::InFlight held = policy.inFlight(u.client);
        const bool sent = sendTo(u.client, u.channel, u.message, held, u.lossPermille);
        handed = handed || sent;
        if (!sent)
            continue;
        received.charge(u.client, received.now() - t0);
        book.record([&](ServerReport& r) {
            ModeTotals& t = r.modes[size_t(u.mode)].sent;
            ++t.updates;
            t.fullUpdates += u.full;
            t.bytes += u.payloadBytes;
            t.rawBytes += u.rawBytes;
        });
    }
    if (handed)
        host.flush();
    if (peakInFlight > peakBefore)
        book.record([&](ServerReport& r) { r.counters.peakInFlightBytes = peakInFlight; });
}

// The assessment's warnings and snapshots (net/assessment.h), to whoever is still here.
void SessionServer::Impl::sendNotices() {
    for (const Assessment::Notice& n : step.assessment().takeNotices())
        for (uint16_t id : n.to)
            if (policy.live(id))
                sendTo(id, Channel::Control, n.bytes);
}

// Says goodbye so clients print a reason, and gives the goodbyes a moment to leave; a client
// connecting meanwhile is told the server is shutting down.
void SessionServer::Impl::sayGoodbye() {
    const ScreenFor screen(admission, book);
    for (const auto& [id, peer] : links) // the report's last copy
        reportNetCharged(id);
    PolicyOutput out;
    policy.goodbye(clock(), out);
    apply(out);
    // A real wait on the socket, pumped or not.
    const uint64_t deadline = steadyNowUs() + 200000;
    while (policy.peerCount() > 0 && steadyNowUs() < deadline)
        host.service(5, [&](const ENetEvent& ev) {
            if (ev.type == ENET_EVENT_TYPE_DISCONNECT) {
                const auto id = uint16_t(reinterpret_cast<uintptr_t>(ev.peer->data));
                ev.peer->data = nullptr;
                if (!id)
                    return;
                PolicyOutput left;
                policy.disconnect(id, clock(), left);
                links.erase(id);
                push(left.events, left.log);
            } else if (ev.type == ENET_EVENT_TYPE_CONNECT) {
                enet_peer_disconnect(ev.peer, uint32_t(RefuseReason::Shutdown));
            }
        });
    // Whoever did not answer in time is gone all the same: its leave is applied (and logged) at
    // the stop, so its assessment ends there, as a replay of the log ends it.
    for (const auto& [id, peer] : std::map<uint16_t, ENetPeer*>(links)) {
        peer->data = nullptr;
        PolicyOutput left;
        policy.disconnect(id, clock(), left);
        links.erase(id);
        push(left.events, left.log);
    }
    book.record([](ServerReport& r) { r.counters.clients = 0; });
}

namespace {

// A datagram that names a connected peer but comes from another address: counted (ENet would
// drop it silently too).
int countForeignDatagram(ENetHost* host, ReportBook& book) {
    if (host->receivedDataLength < 2)
        return 0;
    const uint16_t header = uint16_t(host->receivedData[0] << 8 | host->receivedData[1]);
    const uint16_t peerId =
        header & ~(ENET_PROTOCOL_HEADER_FLAG_MASK | ENET_PROTOCOL_HEADER_SESSION_MASK);
    if (peerId >= host->peerCount)
        return 0; // a connect (the maximum id), or no peer of ours
    const ENetPeer& peer = host->peers[peerId];
    if (peer.state == ENET_PEER_STATE_DISCONNECTED || peer.state == ENET_PEER_STATE_ZOMBIE ||
        (peer.address.host == host->receivedAddress.host &&
         peer.address.port == host->receivedAddress.port))
        return 0;
    book.record([](ServerReport& r) { ++r.security.spoofed; });
    return 1; // consumed: dropped here
}

// ENet has one intercept, so every rule on raw datagrams is here, in turn: admission judges
// CONNECTs (net/admission.h), then a peer's datagrams from a foreign address are dropped.
int ENET_CALLBACK screenDatagram(ENetHost* host, ENetEvent*) {
    if (!t_admission || !t_book)
        return 0;
    return t_admission->judge() ? 1 : countForeignDatagram(host, *t_book);
}

} // namespace

void SessionServer::Impl::receive(uint64_t now) {
    const ScreenFor screen(admission, book);
    admission.setNow(now);
    host.service(0, [&](const ENetEvent& ev) { onEvent(ev); });
    received.serve(kReceiveSliceUs, [this](uint16_t id, Channel ch, std::span<const uint8_t> data) {
        handleReceived(id, ch, data);
    });
    playReplayed();
}

void SessionServer::Impl::send(uint64_t now) {
    sendUpdates();
    sendNotices();
    guard(now);
    PolicyOutput out;
    policy.update(now, out);
    apply(out);
    if (now >= nextTickUs) {
        stats.tick(now);
        nextTickUs = now + 1000000;
    }
    if (recorder)
        recorder->tick(now); // its syncs run on its own executor
}

void SessionServer::Impl::simulate(uint64_t now) {
    batch.clear();
    {
        std::lock_guard lock(inMutex);
        batch.swap(inbox);
        inboxWaiting.store(false, std::memory_order_relaxed);
        inboxTools = 0;
        busy = !batch.empty() || step.rendering();
    }
    {
        std::lock_guard stepLock(stepMutex);
        if (batch.empty() && !step.rendering()) {
            step.offerNoted();
            step.assessment().tick(now);
        } else {
            step.step(batch, now);
        }
        step.postRepairs();
    }
    std::lock_guard lock(inMutex);
    busy = false;
}

void SessionServer::Impl::finishSimulation() {
    for (;;) {
        {
            std::lock_guard lock(inMutex);
            if (inbox.empty())
                break;
        }
        simulate(clock());
    }
    std::lock_guard stepLock(stepMutex);
    step.assessment().finish(clock());
}

void SessionServer::pump(uint64_t nowUs) {
    if (m_started.load() || m_stop.load())
        return;
    Impl& s = *m_impl;
    s.pumpedUs = std::max(s.pumpedUs.load(), nowUs);
    const uint64_t now = s.pumpedUs.load();
    s.receive(now);
    s.simulate(now);
    s.send(now);
}

// [SECTION] the runner: two threads and the steady clock

void SessionServer::networkLoop() {
    nameThread("trephine-net");
    Impl& s = *m_impl;
    s.sendPasses.open();
    while (!m_stop.load()) {
        // Wait on the socket and the wake-up together, then handle everything pending.
        s.waitNetwork(s.received.waiting() > 0 ? 0 : 1); // messages left waiting go at once
        s.receive(s.clock());
        s.send(s.clock());
    }
    s.sendPasses.close();
    s.sayGoodbye();
}

void SessionServer::simulationLoop() {
    nameThread("trephine-sim");
    Impl& s = *m_impl;
    for (;;) {
        {
            std::unique_lock lock(s.inMutex);
            // A view's work not done is work: its next piece goes without waiting.
            const uint64_t waitUs = s.step.rendering() ? 0 : 10000;
            s.inCv.wait_for(lock, std::chrono::microseconds(waitUs),
                            [&] { return !s.inbox.empty() || s.stopSim; });
            if (s.inbox.empty() && s.stopSim)
                break;
        }
        s.simulate(s.clock());
    }
    s.finishSimulation();
}

} // namespace trephine::net

#include "net/client_thread.h"

#include "libsim/error.h"
#include "net/codec.h"
#include "net/messages.h"

#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <functional>
#include <mutex>
#include <pthread.h>
#include <utility>

namespace trephine::net {

PicturePart picturePart(const AppliedRect& r, glm::ivec2 viewSize,
                        const std::optional<HeldPicture>& held) {
    if (r.full)
        return r.pixels.width() == viewSize.x && r.pixels.height() == viewSize.y
                   ? PicturePart::Whole
                   : PicturePart::None;
    return held && r.viewId == held->viewId &&
                   PixelRect{0, 0, held->size.x, held->size.y}.contains(r.rect)
               ? PicturePart::Rect
               : PicturePart::None;
}

const char* linkStateName(LinkState s) {
    switch (s) {
    case LinkState::Connecting:
        return "connecting";
    case LinkState::Connected:
        return "connected";
    case LinkState::Retrying:
        return "retrying";
    case LinkState::Stopped:
        return "stopped";
    }
    return "?";
}

namespace {

// The mean of the samples added to a window since the last call (the newest sample when one was
// added); -1 when none was. SampleWindow keeps no "latest", but its running sum does.
struct NewSamples {
    uint64_t count = 0;
    double sum = 0;
    double take(const SampleWindow& w) {
        uint64_t n = w.totalCount() - count;
        double v = n ? (w.totalSum() - sum) / double(n) : -1.0;
        count = w.totalCount();
        sum = w.totalSum();
        return v;
    }
};

// The box's voxels (or the whole volume) as a window uploads them.
AppliedVolumeBox copyBox(const Volume& v, const Box3i& box, bool full) {
    AppliedVolumeBox b;
    b.full = full;
    b.box = full ? v.bounds() : box;
    b.dims = v.dims();
    b.spacing = v.spacing();
    if (full) {
        b.density.assign(v.densityData(), v.densityData() + v.voxelCount());
        b.material.assign(v.materialData(), v.materialData() + v.voxelCount());
        return b;
    }
    const glm::ivec3 size = b.box.size();
    b.density.resize(size_t(b.box.count()));
    b.material.resize(size_t(b.box.count()));
    size_t o = 0;
    for (int z = b.box.lo.z; z < b.box.hi.z; ++z)
        for (int y = b.box.lo.y; y < b.box.hi.y; ++y) {
            size_t i = v.index(b.box.lo.x, y, z);
            std::memcpy(b.density.data() + o, v.densityData() + i, size_t(size.x));
            std::memcpy(b.material.data() + o, v.materialData() + i, size_t(size.x));
            o += size_t(size.x);
        }
    return b;
}

// The end-to-end latency of the update just applied (the newest record, when it is that update),
// -1 for a full one (a join or a switch: not caused by drilling) or when unknown.
double latencyOf(const SessionClient& c, uint32_t sequence, bool full) {
    const auto& records = c.updateRecords();
    if (full || records.empty() || records.back().sequence != sequence)
        return -1;
    return records.back().latencyUs;
}

// The client's picture after an image or volume update, as the window takes it: `rect` of its
// DBI, or all of it after a full update.
template <typename Update>
AppliedRect appliedRect(const SessionClient& c, const Update& meta, const PixelRect& rect,
                        bool full, uint32_t viewId) {
    AppliedRect r;
    r.full = full;
    r.rect = full ? c.dbi().bounds() : rect;
    r.pixels = full ? c.dbi() : c.dbi().extract(rect);
    r.sequence = meta.sequence;
    r.viewId = viewId;
    r.view = c.view();
    r.bytes = uint32_t(meta.payload.size());
    r.rawBytes = meta.rawBytes;
    r.appliedUs = steadyNowUs();
    r.latencyUs = latencyOf(c, meta.sequence, full);
    return r;
}

ModeFigures figures(const ModeStats& m, double ratePerS) {
    ModeFigures f;
    f.updatesApplied = m.updates;
    f.updateRatePerS = ratePerS;
    f.meanBytes = m.bytes.size() ? m.bytes.mean() : 0;
    f.meanRawBytes = m.rawBytes.size() ? m.rawBytes.mean() : 0;
    f.latencyP50Us = m.latencyUs.size() ? m.latencyUs.percentile(50) : -1;
    f.latencyP99Us = m.latencyUs.size() ? m.latencyUs.percentile(99) : -1;
    f.applyP50Us = m.applyUs.size() ? m.applyUs.percentile(50) : -1;
    f.clientRenderP50Us = m.clientRenderUs.size() ? m.clientRenderUs.percentile(50) : -1;
    f.erodeP50Us = m.erodeUs.size() ? m.erodeUs.percentile(50) : -1;
    f.serverRenderP50Us = m.serverRenderUs.size() ? m.serverRenderUs.percentile(50) : -1;
    f.encodeP50Us = m.encodeUs.size() ? m.encodeUs.percentile(50) : -1;
    f.transmitP50Us = m.transmitUs.size() ? m.transmitUs.percentile(50) : -1;
    return f;
}

} // namespace

ClientThread::ClientThread(ClientThreadConfig config)
    : m_config(std::move(config)), m_snapshot(std::make_shared<ClientSnapshot>()) {}

ClientThread::~ClientThread() {
    stop();
}

void ClientThread::start() {
    if (m_thread.joinable())
        return;
    m_stop = false;
    m_thread = std::thread([this] { run(); });
}

void ClientThread::stop() {
    m_stop = true;
    if (m_thread.joinable())
        m_thread.join();
}

bool ClientThread::push(Command c) {
    std::lock_guard lock(m_cmdMutex);
    if (std::holds_alternative<ToolState>(c))
        for (auto& q : m_commands)
            if (std::holds_alternative<ToolState>(q)) {
                q = std::move(c); // newest tool state wins
                return true;
            }
    if (m_commands.size() >= m_config.maxCommands)
        return false;
    m_commands.push_back(std::move(c));
    return true;
}

bool ClientThread::sendToolState(const ToolState& t) {
    return push(t);
}
bool ClientThread::requestView(const ViewSpec& v) {
    return push(ViewCmd{v});
}
bool ClientThread::ping() {
    return push(PingCmd{});
}
bool ClientThread::requestSync(Sync mode) {
    return push(SyncCmd{mode});
}
bool ClientThread::annotate(const Annotate& a) {
    return push(a);
}
bool ClientThread::send(ClientRequest r) {
    return push(std::move(r));
}
bool ClientThread::takeOver(uint16_t trainee) {
    return send(TakeOver{trainee});
}
bool ClientThread::viewAs(uint16_t id) {
    return push(ViewAs{id});
}
bool ClientThread::remove(Remove m) {
    return send(m);
}
bool ClientThread::controlReplay(const ReplayControl& c) {
    return send(c);
}
bool ClientThread::newCode(Role role) {
    Codes m;
    m.op = Codes::Op::Issue;
    m.role = role;
    return send(std::move(m));
}

std::vector<AppliedVolumeBox> ClientThread::drainVolumeBoxes() {
    std::vector<AppliedVolumeBox> out;
    std::lock_guard lock(m_boxMutex);
    out.swap(m_boxes);
    return out;
}

void ClientThread::pushBox(AppliedVolumeBox b) {
    std::lock_guard lock(m_boxMutex);
    if (b.full)
        m_boxes.clear();
    m_boxes.push_back(std::move(b));
    if (m_boxes.size() > m_config.maxQueuedRects) {
        m_boxes.clear();
        m_needFullVolume = true;
    }
    m_boxesPublished.fetch_add(1);
    if (m_config.onNews)
        m_config.onNews();
}

bool ClientThread::withLocalVolume(const std::function<void(const Volume&)>& fn) const {
    std::shared_lock lock(m_volumeRw);
    const Volume* v = m_localClient ? m_localClient->localVolume() : nullptr;
    if (!v)
        return false;
    fn(*v);
    return true;
}

std::shared_ptr<const ClientSnapshot> ClientThread::snapshot() const {
    std::lock_guard lock(m_snapMutex);
    return m_snapshot;
}

std::vector<AppliedRect> ClientThread::drainRects() {
    std::vector<AppliedRect> out;
    std::lock_guard lock(m_rectMutex);
    out.swap(m_rects);
    return out;
}

void ClientThread::pushRect(AppliedRect r) {
    std::lock_guard lock(m_rectMutex);
    if (r.full)
        m_rects.clear(); // a full image supersedes every queued rectangle
    m_rects.push_back(std::move(r));
    if (m_rects.size() > m_config.maxQueuedRects) {
        // The UI fell behind: drop the queue; the network thread publishes a full copy of the DBI
        // next, which stands for everything dropped.
        m_rects.clear();
        m_needFull = true;
    }
    m_rectsPublished.fetch_add(1);
    if (m_config.onNews)
        m_config.onNews();
}

namespace {

// [SECTION] snapshot equality

// The same value: a message of the server's by its wire bytes (and whether it encodes: values
// off the wire always do), containers element by element, the rest by its operator==. All
// declared first, so each finds the others whatever the order of their definitions.
template <typename T>
bool same(const T& a, const T& b);
template <typename T>
bool same(const std::optional<T>& a, const std::optional<T>& b);
template <typename K, typename V>
bool same(const std::map<K, V>& a, const std::map<K, V>& b);
template <typename T, size_t N>
bool same(const std::array<T, N>& a, const std::array<T, N>& b);
template <typename T>
bool same(const std::vector<T>& a, const std::vector<T>& b);
template <typename T>
bool same(const std::deque<T>& a, const std::deque<T>& b);
bool same(const ChannelRates& a, const ChannelRates& b);
bool same(const ServerFault& a, const ServerFault& b);

template <typename M>
std::vector<uint8_t> wireBytes(M m) {
    std::vector<uint8_t> out;
    WriteStream w(out);
    out.push_back(uint8_t(m.serialize(w)));
    return out;
}

template <typename T>
bool same(const std::optional<T>& a, const std::optional<T>& b) {
    return a.has_value() == b.has_value() && (!a || same(*a, *b));
}

template <typename K, typename V>
bool same(const std::map<K, V>& a, const std::map<K, V>& b) {
    return std::equal(a.begin(), a.end(), b.begin(), b.end(), [](const auto& x, const auto& y) {
        return x.first == y.first && same(x.second, y.second);
    });
}

template <typename R>
bool sameRange(const R& a, const R& b) {
    return std::equal(a.begin(), a.end(), b.begin(), b.end(),
                      [](const auto& x, const auto& y) { return same(x, y); });
}
template <typename T, size_t N>
bool same(const std::array<T, N>& a, const std::array<T, N>& b) {
    return sameRange(a, b);
}
template <typename T>
bool same(const std::vector<T>& a, const std::vector<T>& b) {
    return sameRange(a, b);
}
template <typename T>
bool same(const std::deque<T>& a, const std::deque<T>& b) {
    return sameRange(a, b);
}

bool same(const ChannelRates& a, const ChannelRates& b) {
    return a.bytesInPerS == b.bytesInPerS && a.bytesOutPerS == b.bytesOutPerS &&
           a.messagesInPerS == b.messagesInPerS && a.messagesOutPerS == b.messagesOutPerS;
}

bool same(const ServerFault& a, const ServerFault& b) {
    return a.type == b.type && a.detail == b.detail;
}

template <typename T>
bool same(const T& a, const T& b) {
    if constexpr (requires(T & m, WriteStream & w) { m.serialize(w); } &&
                  !std::equality_comparable<T>)
        return wireBytes(a) == wireBytes(b);
    else
        return a == b;
}

// The snapshot's fields, one binding each: a field added to ClientSnapshot does not compile here
// until it is bound, and so compared.
auto fieldsOf(const ClientSnapshot& s) {
    const auto& [f0, f1, f2, f3, f4, f5, f6, f7, f8, f9, f10, f11, f12, f13, f14, f15, f16, f17,
                 f18, f19, f20, f21, f22, f23, f24, f25, f26, f27, f28, f29, f30, f31, f32, f33,
                 f34, f35, f36, f37, f38, f39, f40, f41, f42, f43, f44, f45, f46, f47, f48, f49,
                 f50, f51] = s;
    return std::tie(f0, f1, f2, f3, f4, f5, f6, f7, f8, f9, f10, f11, f12, f13, f14, f15, f16, f17,
                    f18, f19, f20, f21, f22, f23, f24, f25, f26, f27, f28, f29, f30, f31, f32, f33,
                    f34, f35, f36, f37, f38, f39, f40, f41, f42, f43, f44, f45, f46, f47, f48, f49,
                    f50, f51);
}

template <typename Tuple, size_t... I>
bool sameFields(const Tuple& a, const Tuple& b, std::index_sequence<I...>) {
    return (same(std::get<I>(a), std::get<I>(b)) && ...);
}

} // namespace

bool ClientSnapshot::operator==(const ClientSnapshot& o) const {
    const auto a = fieldsOf(*this), b = fieldsOf(o);
    return sameFields(a, b, std::make_index_sequence<std::tuple_size_v<decltype(a)>>());
}

std::string viewNotServedText(const ClientSnapshot& snap, int width, int height,
                              const std::string& sizeOption) {
    if (snap.state != LinkState::Connected || !snap.welcome)
        return "";
    const int64_t most = snap.welcome->maxViewPixels;
    if (int64_t(width) * height > most)
        return fmt::format("The server serves views of at most {} pixels; this view is {} x {}: "
                           "restart with {} {} or less",
                           most, width, height, sizeOption, int(std::sqrt(double(most))));
    const std::optional<ViewRefusal>& r = snap.viewRefusal;
    if (r && r->width == width && r->height == height)
        return fmt::format("The session's views are full: the server has {} pixels free for "
                           "your view and this one is {} x {}",
                           r->freePixels, width, height);
    return "";
}

DrawnPart drawnPart(const ClientSnapshot& s) {
    DrawnPart d;
    d.state = s.state;
    d.closeReason = s.closeReason;
    d.attempts = s.attempts;
    d.scene = s.scene;
    d.welcomed = s.welcome.has_value();
    d.viewingAs = s.viewingAs;
    d.view = s.view;
    d.viewId = s.viewId;
    d.waitingForView = s.waitingForView;
    d.viewRefusal = s.viewRefusal;
    d.sync = s.sync;
    d.requestedSync = s.requestedSync;
    d.participants = s.participants;
    d.annotations = s.annotations;
    if (s.replay)
        d.replay =
            DrawnPart::Timeline{s.replay->playing, s.replay->seeks, s.replay->speed,
                                s.replay->durationUs, s.replay->playing ? 0 : s.replay->positionUs};
    d.codes = s.codes;
    d.newest = s.newest;
    for (const auto& [id, t] : s.others)
        d.others[id] = {t.position, t.orientation, t.drilling, t.toolKind, t.diameterMm};
    return d;
}

void ClientThread::publish(const SessionClient* c, uint64_t nowUs) {
    auto s = std::make_shared<ClientSnapshot>();
    s->state = m_state;
    s->closeReason = m_closeReason;
    s->fault = m_fault;
    s->attempts = m_attempts;
    s->volumeRefusals = m_volumeRefusals;
    s->publishedUs = nowUs;
    s->codec = codecName(m_config.client.codec);
    s->volumeCodec = codecName(m_config.client.volumeCodec);
    s->sync = s->requestedSync = m_wantedSync.value_or(m_config.client.sync);
    s->hapticModel = m_haptic;
    s->hapticModels = m_hapticModels;
    // Between connections, the view the next hello asks for: a default ViewSpec here jumped a
    // volume-mode window (which draws this view) to a camera 300 mm above the skull, or to
    // nothing at another size, for every retry.
    s->view = m_wantedView.value_or(m_config.client.view);
    if (c) {
        if (c->welcomed())
            s->welcome = c->welcome();
        s->scene = c->scene();
        s->viewingAs = c->viewingAs();
        s->view = c->view();
        s->viewId = c->viewId();
        s->hasFullImage = c->hasPicture(); // a preview is a picture to show
        s->waitingForView = c->welcomed() && !c->hasPicture();
        s->others = c->others();
        s->participants = c->participants();
        s->annotations = c->annotations();
        s->warnings = c->warnings();
        s->assessment = c->assessment();
        s->codes = c->codes();
        s->newest = c->newest();
        if (c->replay()) {
            s->replay = *c->replay();
            s->replay->positionUs = c->replayPosition(nowUs);
        }
        s->updatesApplied = c->updatesApplied();
        s->fullUpdates = c->fullUpdates();
        s->updatesRejected = c->updatesRejected();
        s->viewsRefused = c->viewsRefused();
        s->viewRefusal = c->viewRefusal();
        s->toolStatesSent = c->toolStatesSent();
        s->relaysReceived = c->relaysReceived();
        s->relayedModels = c->relayedModels();
        s->hapticRelays = c->hapticRelaysReceived();
        const NetStats& st = c->stats();
        s->packetLoss = st.packetLoss;
        s->packetsLost = st.packetsLost;
        s->malformed = st.malformed();
        s->malformedImages = c->malformedImages();
        s->rttUs = m_lastRttUs;
        s->rttP50Us = st.rttUs.size() ? st.rttUs.percentile(50) : -1;
        s->hapticRoundTripP50Us =
            st.hapticRoundTripUs.size() ? st.hapticRoundTripUs.percentile(50) : -1;
        s->hapticRoundTripP99Us =
            st.hapticRoundTripUs.size() ? st.hapticRoundTripUs.percentile(99) : -1;
        s->lastHeardUs = c->lastHeardUs();
        s->latencyP50Us = st.updateLatencyUs.size() ? st.updateLatencyUs.percentile(50) : -1;
        s->latencyP99Us = st.updateLatencyUs.size() ? st.updateLatencyUs.percentile(99) : -1;
        s->meanBytes = st.updateBytes.size() ? st.updateBytes.mean() : 0;
        s->meanRawBytes = st.updateRawBytes.size() ? st.updateRawBytes.mean() : 0;
        s->sync = c->sync();
        s->requestedSync = c->requestedSync();
        for (size_t m = 0; m < 2; ++m)
            s->modes[m] = figures(st.modes[m], m_modeRates[m]);
        s->rateHistory = m_rateHistory;
        if (!s->rateHistory.empty())
            s->rates = s->rateHistory.back();
    }
    std::shared_ptr<const ClientSnapshot> last, now = s;
    {
        std::lock_guard lock(m_snapMutex);
        last = std::exchange(m_snapshot, std::move(s));
    }
    if (m_config.onNews && (!last || drawnPart(*last) != drawnPart(*now)))
        m_config.onNews();
}

void ClientThread::run() {
    pthread_setname_np(pthread_self(), "net-client");
    using namespace std::chrono;
    while (!m_stop) {
        ++m_attempts;
        m_state = LinkState::Connecting;
        publish(nullptr, steadyNowUs());
        ClientConfig cc = m_config.client;
        if (m_wantedView)
            cc.view = *m_wantedView;
        if (m_wantedSync)
            cc.sync = *m_wantedSync;
        if (m_wantedCode)
            cc.code = *m_wantedCode;
        if (std::unique_ptr<SessionClient> client = connectClient(cc))
            runConnection(*client, cc);
        if (m_stop)
            break;
        m_state = LinkState::Retrying;
        publish(nullptr, steadyNowUs());
        auto until = steady_clock::now() + duration<double>(m_config.retryS);
        while (!m_stop && steady_clock::now() < until)
            std::this_thread::sleep_for(milliseconds(20));
    }
    m_state = LinkState::Stopped;
    publish(nullptr, steadyNowUs());
}

std::unique_ptr<SessionClient> ClientThread::connectClient(const ClientConfig& cc) {
    try {
        auto client = std::make_unique<SessionClient>(cc);
        client->continueToolSequence(m_toolSequence);
        client->connect(parseAddress(m_config.address), m_config.address);
        return client;
    } catch (const std::exception& e) {
        m_closeReason = e.what();
        m_fault.reset();
        return nullptr;
    }
}

void ClientThread::runConnection(SessionClient& client, const ClientConfig& cc) {
    SessionClient* cp = &client;
    cp->setVolumeMutex(&m_volumeRw);
    {
        std::unique_lock lock(m_volumeRw);
        m_localClient = cp;
    }
    // Whatever this connection throws (memory for a whole volume, a thread the render pool
    // cannot start) ends the connection with its reason and a retry: escaping the thread's
    // body it terminated the window without a word.
    try {
        installCallbacks(*cp, cc.renderLocally);
        pollUntilClosed(*cp, cc);
        if (cp->closed()) {
            m_closeReason =
                cp->closeReason().empty() ? "the connection was lost" : cp->closeReason();
            m_fault = cp->fault();
        } else if (m_stop)
            cp->disconnect();
        // The server cannot send its whole volume: the next connection asks for DBI (it
        // asked for the volume again at every reconnect, each refusal costing the server a
        // whole volume's encode, and the window never got a picture).
        if (cp->closed() && cp->closeCode() == uint32_t(RefuseReason::VolumeTooLarge)) {
            m_wantedSync = Sync::Dbi;
            ++m_volumeRefusals;
        }
    } catch (const std::exception& e) {
        m_closeReason = std::string("the connection failed: ") + e.what();
        m_fault.reset();
    }
    {
        std::unique_lock lock(m_volumeRw);
        m_localClient = nullptr;
    }
    m_toolSequence = cp->toolSequence();
}

void ClientThread::installCallbacks(SessionClient& client, bool renderLocally) {
    SessionClient* cp = &client;
    if (!renderLocally)
        cp->setVolumeCallback([this, cp](const VolumeUpdate& meta, const Box3i& box, bool full) {
            if (!cp->localVolume())
                return;
            AppliedVolumeBox b = copyBox(*cp->localVolume(), box, full);
            b.sequence = meta.sequence;
            b.bytes = uint32_t(meta.payload.size());
            b.rawBytes = meta.rawBytes;
            b.appliedUs = steadyNowUs();
            b.latencyUs = latencyOf(*cp, meta.sequence, full);
            pushBox(std::move(b));
        });
    else
        cp->setVolumeCallback([this, cp](const VolumeUpdate& meta, const Box3i&, bool full) {
            if (cp->dbi().width() == 0)
                return;
            // The local render is the whole view again, whatever box changed.
            pushRect(appliedRect(*cp, meta, cp->dbi().bounds(), full, cp->viewId()));
        });
    // Runs inside poll(), right after the update is applied to the client's DBI. Its
    // latency is its own record's, not the stats' latency window, which volume updates
    // feed too.
    cp->setUpdateCallback([this, cp](const ImageUpdate& meta, const PixelRect& rect, bool full) {
        pushRect(appliedRect(*cp, meta, rect, full, meta.viewId));
    });
    cp->setHapticCallback([this](const HapticModel& m, uint64_t) {
        m_haptic = m;
        ++m_hapticModels;
        if (m_config.onHapticModel)
            m_config.onHapticModel(m);
    });
}

void ClientThread::pollUntilClosed(SessionClient& client, const ClientConfig& cc) {
    SessionClient* cp = &client;
    NewSamples newRtt;
    // The client's own time base (ClientConfig::clock), the steady clock by default.
    auto clockNow = [&] { return cc.clock ? cc.clock() : steadyNowUs(); };
    const uint64_t start = clockNow();
    uint64_t nextPing = start, nextPublish = start;
    uint64_t refusedSeen = 0;
    RateClock clock;
    clock.lastTickUs = start;
    clock.nextTickUs = start + 1000000;
    m_modeRates = {};
    m_rateHistory.clear();
    while (!m_stop && !cp->closed()) {
        cp->wait(1);
        const uint64_t now = clockNow();
        cp->pump(now);
        if (!cp->welcomed()) {
            if (cp->busyRefusals() > 0)
                m_closeReason = cp->closeReason(); // the server is there: the window says so
            // An offer the server holds for its turn is an answer on its way.
            const double limitS = cp->offerPending() ? std::max(m_config.connectTimeoutS,
                                                                SessionClient::kMaxOfferWaitS)
                                                     : m_config.connectTimeoutS;
            if (now - start > uint64_t(limitS * 1e6)) {
                // Something came that did not decode or open (a damaged welcome, forgeries):
                // say so, rather than suggest that nothing listens.
                const uint64_t unread = cp->stats().malformed();
                const std::string unreadText =
                    std::to_string(unread) +
                    " malformed or forged messages (a faulty network, an on-path attacker, or no "
                    "Trephine server at that address)";
                m_closeReason =
                    cp->busyRefusals() > 0
                        ? m_config.address + " is busy: " + cp->closeReason() + " (" +
                              std::to_string(cp->busyRefusals()) + " tries)"
                        : "no answer from " + m_config.address +
                              (unread == 0 ? " (is `trephine server` running?)"
                                           : " that this client could read: " + unreadText);
                m_fault.reset();
                break;
            }
        } else if (m_state != LinkState::Connected) {
            m_state = LinkState::Connected;
            m_closeReason.clear();
            m_fault.reset();
            nextPublish = now;
        }
        runCommands(*cp, cc.renderLocally);
        // A view refused (too large, which the client finds at the welcome, or over the session's
        // total, which the server says) is not for the next hello: it would have it refused.
        if (cp->viewsRefused() != refusedSeen) {
            refusedSeen = cp->viewsRefused();
            if (m_wantedView)
                m_wantedView = cp->viewAskedFor();
        }
        // A new instructor code stops the old one joining: reconnects prove the new one.
        if (cc.role == Role::Instructor && cp->codes())
            m_wantedCode = cp->codes()->instructor;
        publishFullCopies(*cp, now);
        if (cp->welcomed() && now >= nextPing) {
            cp->sendPing();
            nextPing = now + 250000;
        }
        if (now >= clock.nextTickUs)
            tickRates(*cp, now, clock);
        if (now >= nextPublish) {
            if (double rtt = newRtt.take(cp->stats().rttUs); rtt >= 0)
                m_lastRttUs = rtt;
            publish(cp, now);
            nextPublish = now + 10000; // 100 Hz is plenty for a 60 Hz window
        }
    }
}

void ClientThread::runCommands(SessionClient& client, bool renderLocally) {
    SessionClient* cp = &client;
    std::deque<Command> cmds;
    {
        std::lock_guard lock(m_cmdMutex);
        cmds.swap(m_commands);
    }
    // SessionClient holds a view or switch asked for before its connection is up and makes it
    // then (with the hello, or right after it); anything else waits for the welcome.
    const bool welcomed = cp->welcomed();
    const auto run = Handlers{
        [&](const ViewCmd& v) {
            // A view it refused (larger than the server serves) is not wanted again: in the next
            // hello it had every reconnect refused.
            if (cp->requestView(v.view) != 0) {
                m_wantedView = v.view;
                // Rendered here at once (volume design, renderLocally): the new view's picture
                // is published whole, as a DBI's full image is.
                if (renderLocally && cp->sync() == Sync::Volume)
                    m_needFull = true;
            }
        },
        [&](const SyncCmd& y) {
            m_wantedSync = y.sync;
            cp->requestSync(y.sync);
        },
        [&](const PingCmd&) { cp->sendPing(); },
        [&](const ToolState& t) { cp->sendToolState(t); },
        [&](const Annotate& a) { cp->annotate(a); },
        [&](const ViewAs& as) { cp->viewAs(as.clientId); },
        [&](const ClientRequest& r) { cp->send(r); },
    };
    for (const Command& c : cmds)
        if (welcomed || std::holds_alternative<ViewCmd>(c) || std::holds_alternative<SyncCmd>(c))
            std::visit(run, c);
}

void ClientThread::publishFullCopies(const SessionClient& c, uint64_t nowUs) {
    if (m_needFullVolume.exchange(false) && c.localVolume()) {
        AppliedVolumeBox b = copyBox(*c.localVolume(), {}, true);
        b.sequence = c.lastUpdateSequence();
        b.appliedUs = nowUs;
        pushBox(std::move(b));
    }
    if (m_needFull.exchange(false) && c.hasPicture()) {
        AppliedRect r;
        r.full = true;
        r.rect = c.dbi().bounds();
        r.pixels = c.dbi();
        r.viewId = c.viewId();
        r.view = c.view();
        r.sequence = c.lastUpdateSequence();
        r.appliedUs = nowUs;
        pushRect(std::move(r));
    }
}

void ClientThread::tickRates(const SessionClient& c, uint64_t nowUs, RateClock& clock) {
    // Our own 1 s rates from the totals: the client ticks its history per poll.
    std::array<ChannelRates, size_t(Channel::Count)> rates{};
    const double dt = double(nowUs - clock.lastTickUs) * 1e-6;
    const NetStats& st = c.stats();
    for (size_t ch = 0; ch < size_t(Channel::Count); ++ch) {
        std::array<uint64_t, 4> t = {st.totalBytesIn(Channel(ch)), st.totalBytesOut(Channel(ch)),
                                     st.totalMessagesIn(Channel(ch)),
                                     st.totalMessagesOut(Channel(ch))};
        rates[ch] = {double(t[0] - clock.lastTotals[ch][0]) / dt,
                     double(t[1] - clock.lastTotals[ch][1]) / dt,
                     double(t[2] - clock.lastTotals[ch][2]) / dt,
                     double(t[3] - clock.lastTotals[ch][3]) / dt};
        clock.lastTotals[ch] = t;
    }
    for (size_t m = 0; m < 2; ++m) {
        uint64_t n = st.modes[m].updates;
        m_modeRates[m] = double(n - clock.lastModeUpdates[m]) / dt;
        clock.lastModeUpdates[m] = n;
    }
    m_rateHistory.push_back(rates);
    if (m_rateHistory.size() > 120)
        m_rateHistory.pop_front();
    clock.lastTickUs = nowUs;
    // Behind by more than a tick (a stall: a large full volume applied, the
    // thread not scheduled), start afresh from now: catching up would tick once
    // a poll, each over ~1 ms, and publish rates of 0 or ~1000 a second.
    clock.nextTickUs += 1000000;
    if (clock.nextTickUs <= nowUs)
        clock.nextTickUs = nowUs + 1000000;
}

} // namespace trephine::net

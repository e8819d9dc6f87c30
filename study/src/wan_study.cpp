#include "study/wan_study.h"

#include "libsim/camera.h"
#include "libsim/error.h"
#include "libsim/skull.h"
#include "libsim/stats.h"
#include "net/net_stats.h"
#include "net/session_client.h"
#include "net/session_server.h"
#include "net/view.h"
#include "study/update_study.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>
#include <thread>

namespace trephine::study {

using namespace trephine::net;

net::LinkConditions WanLink::conditions() const {
    LinkConditions c;
    c.latencyMs = rttMs / 2.0;
    c.lossPercent = lossPct;
    c.rateMbps = rateMbit;
    return c;
}

WanLink wanTargetLink() {
    return {100, 1, 20};
}

std::string classroomLink(double rateMbit) {
    return rateMbit > 0 ? fmt::format("one shared {:.0f} Mbit/s link", rateMbit)
                        : std::string("loopback (through the relay, no rate limit)");
}

std::vector<WanLink> wanSweep(bool quick) {
    std::vector<WanLink> links;
    const std::vector<double> rtts =
        quick ? std::vector<double>{0, 100} : std::vector<double>{0, 20, 50, 100, 200, 300};
    const std::vector<double> losses =
        quick ? std::vector<double>{0, 1} : std::vector<double>{0, 1, 5};
    for (double rtt : rtts)
        for (double loss : losses)
            links.push_back({rtt, loss, 100});
    if (quick)
        links.push_back(wanTargetLink());
    else
        for (double rtt : {50.0, 100.0, 200.0})
            links.push_back({rtt, 1, 20});
    return links;
}

namespace {

constexpr double kNotMeasured = std::numeric_limits<double>::quiet_NaN();

struct Design {
    const char* name;
    Sync sync;
};
// The paper's two designs: DBI images with the study's codec, volume boxes at 1 byte a voxel.
constexpr Design kDesigns[] = {{"dbi", Sync::Dbi}, {"volume", Sync::Volume}};

// One client of the study and the incremental updates it applied (when, and their latency).
struct StudyClient {
    Sync sync = Sync::Dbi;
    std::unique_ptr<SessionClient> session;
    std::vector<std::pair<uint64_t, double>> applied; // steadyNowUs, latency ms
    double fullBytes = 0;                             // the join's full picture or volume
    uint64_t connectUs = 0, joinedUs = 0, pingedUs = 0;
    float yawDeg = 0;

    bool ready() const {
        const SessionClient& c = *session;
        return sync == Sync::Dbi ? c.hasFullImage()
                                 : c.sync() == Sync::Volume && c.localVolume() && c.hasFullImage();
    }
};

// A volume client renders its view itself: one alone does (its view change is that render), a
// classroom's watchers do not (a window ray casts on its GPU; 64 CPU renders would measure this
// machine's cores, not the link).
std::unique_ptr<StudyClient> makeClient(const Design& d, const Camera& view, Codec codec,
                                        bool renderLocally, const std::string& name) {
    auto c = std::make_unique<StudyClient>();
    c->sync = d.sync;
    ClientConfig cc;
    cc.name = name;
    cc.codec = codec;
    cc.sync = d.sync;
    cc.volumeCodec = Codec::Raw;
    cc.view = toViewSpec(view);
    cc.renderLocally = renderLocally;
    cc.renderThreads = 1;
    cc.recordCapacity = 16; // the callback keeps what the study needs
    c->session = std::make_unique<SessionClient>(cc);
    StudyClient* self = c.get();
    c->session->setRecordCallback([self](const UpdateRecord& r) {
        if (r.mode != self->sync)
            return;
        if (r.full) {
            if (!self->joinedUs)
                self->fullBytes += r.bytes;
        } else if (r.latencyUs >= 0) {
            self->applied.emplace_back(r.appliedUs, r.latencyUs * 1e-3);
        }
    });
    return c;
}

using Clients = std::vector<std::unique_ptr<StudyClient>>;

// One pass over every client; a short sleep when none had anything, so the server and the relay
// keep the cores.
void pumpAll(Clients& clients) {
    int events = 0;
    for (auto& c : clients) {
        c->session->wait(0);
        const uint64_t now = steadyNowUs();
        events += c->session->pump(now);
        if (!c->joinedUs && c->ready())
            c->joinedUs = now;
        // As every runner does: a client silent for ServerConfig::idleTimeoutS is sent away.
        if (c->joinedUs && now - c->pingedUs > 250000) {
            c->session->sendPing();
            c->pingedUs = now;
        }
    }
    if (events == 0)
        std::this_thread::sleep_for(std::chrono::microseconds(200));
}

template <typename F>
bool pumpAllUntil(Clients& clients, double timeoutS, F done) {
    const uint64_t deadline = steadyNowUs() + uint64_t(timeoutS * 1e6);
    while (!done()) {
        if (steadyNowUs() > deadline)
            return false;
        pumpAll(clients);
    }
    return true;
}

// Each says goodbye (a reset alone would hold its server place until ENet's timeout), then the
// server is given up to 10 s to let every place go, so the next run finds it empty.
void leaveAll(SessionServer& server, Clients& clients) {
    for (auto& c : clients)
        c->session->disconnect(200);
    const uint64_t deadline = steadyNowUs() + 10000000;
    while (server.clientCount() > 0 && steadyNowUs() < deadline)
        std::this_thread::sleep_for(std::chrono::milliseconds(10));
}

bool allJoined(const Clients& clients) {
    return std::all_of(clients.begin(), clients.end(), [](const auto& c) { return c->joinedUs; });
}

// A box of bone and its voxels, put back after every cut so each soak starts from the same bone.
struct BoxVoxels {
    int n = 0;
    Box3i box;
    std::vector<uint8_t> density, material;
};

struct SoakWindow {
    uint64_t startUs = 0, endUs = 0;
    int submitted = 0;
    double egressBytes = 0;
};

// Cuts and restores the box at cutHz for soakS (ending restored), pumping every client, then
// waits for the last update to arrive (at most 5 s).
SoakWindow runSoak(SessionServer& server, const LinkEmulator& link, const BoxVoxels& b,
                   Clients& clients, double soakS, double cutHz) {
    for (auto& c : clients)
        c->applied.clear();
    SoakWindow w;
    const uint64_t bytesBefore = link.bytesDown();
    w.startUs = steadyNowUs();
    const uint64_t periodUs = uint64_t(1e6 / cutHz);
    uint64_t next = w.startUs;
    for (uint64_t now = w.startUs; now < w.startUs + uint64_t(soakS * 1e6) || w.submitted % 2;
         now = steadyNowUs()) {
        if (now >= next) {
            if (w.submitted % 2 == 0)
                server.submitBoxCut(b.box);
            else
                server.submitVoxels(b.box, b.density, b.material);
            ++w.submitted;
            next += periodUs;
        }
        pumpAll(clients);
    }
    w.endUs = steadyNowUs();
    w.egressBytes = double(link.bytesDown() - bytesBefore);
    // The drain: until no client has heard an update for 0.5 s (the last restore included).
    uint64_t lastHeard = w.endUs;
    const uint64_t deadline = w.endUs + 5000000;
    while (steadyNowUs() < deadline && steadyNowUs() - lastHeard < 500000) {
        pumpAll(clients);
        for (auto& c : clients)
            if (!c->applied.empty())
                lastHeard = std::max(lastHeard, c->applied.back().first);
    }
    return w;
}

struct ClientFigures {
    double updatesPerS = 0, p50 = kNotMeasured, p99 = kNotMeasured, stallMs = 0;
    uint64_t updates = 0;
};

// A client's figures over a soak: updates applied within it, their latency (drain included) and
// the longest time its picture did not change while the drilling went on.
ClientFigures figuresOf(const StudyClient& c, const SoakWindow& w) {
    ClientFigures f;
    SampleWindow latency(c.applied.size() + 1);
    uint64_t last = w.startUs;
    for (const auto& [at, ms] : c.applied) {
        latency.add(ms);
        if (at > w.endUs)
            continue;
        ++f.updates;
        f.stallMs = std::max(f.stallMs, double(at - last) * 1e-3);
        last = at;
    }
    f.stallMs = std::max(f.stallMs, double(w.endUs - last) * 1e-3);
    const double s = double(w.endUs - w.startUs) * 1e-6;
    f.updatesPerS = double(f.updates) / s;
    if (latency.size()) {
        f.p50 = latency.percentile(50);
        f.p99 = latency.percentile(99);
    }
    return f;
}

std::vector<BoxVoxels> studyBoxes(SessionServer& server, const std::vector<int>& sizes) {
    const Volume now = server.volumeSnapshot();
    std::vector<BoxVoxels> boxes;
    for (int n : sizes) {
        BoxVoxels b;
        b.n = n;
        b.box = surfaceBox(now, n);
        now.copyBox(b.box, b.density, b.material);
        boxes.push_back(std::move(b));
    }
    return boxes;
}

ServerConfig wanServerConfig(const WanStudyConfig& config) {
    ServerConfig sc;
    sc.port = 0;
    sc.volumeName = config.volumeName;
    sc.hapticModels = false;
    // A classroom of in-process clients: all from one address, joining at once.
    const int most = config.classroom.empty()
                         ? 1
                         : *std::max_element(config.classroom.begin(), config.classroom.end());
    sc.maxClients = size_t(std::max(16, most + 1));
    sc.admission.waitingPerAddress = size_t(std::max(16, most + 1));
    sc.admission.connectBurst = double(std::max(24, most + 1));
    return sc;
}

// What one run needs: the server, the relay in front of it and the camera.
struct Bench {
    SessionServer& server;
    LinkEmulator& link;
    ENetAddress relay;
    Camera camera;
    const WanStudyConfig& config;
    std::vector<BoxVoxels> boxes;
    int step = 0, total = 0;
    void progress(const std::string& label) {
        if (config.progress)
            config.progress(label, step, total);
        ++step;
    }
};

WanRow rowOf(const Design& d, const WanLink& l, int clients, int box) {
    WanRow r;
    r.design = d.name;
    r.rttMs = l.rttMs;
    r.lossPct = l.lossPct;
    r.rateMbit = l.rateMbit;
    r.clients = clients;
    r.box = box;
    return r;
}

bool isTarget(const WanLink& l) {
    const WanLink t = wanTargetLink();
    return l.rttMs == t.rttMs && l.lossPct == t.lossPct && l.rateMbit == t.rateMbit;
}

// One design over one link: join, a 5-degree view change, then a soak per box.
void measureLink(Bench& bench, const Design& d, const WanLink& l, std::vector<WanRow>& rows) {
    bench.link.setConditions(l.conditions());
    Clients clients;
    clients.push_back(makeClient(d, bench.camera, bench.config.codec, true, "wan"));
    StudyClient& c = *clients.front();
    c.connectUs = steadyNowUs();
    c.session->connect(bench.relay);
    WanRow base = rowOf(d, l, 1, 0);
    if (!pumpAllUntil(clients, bench.config.joinTimeoutS, [&] { return allJoined(clients); })) {
        base.joinMs = -1;
        base.updatesPerS = base.latencyP50Ms = base.latencyP99Ms = kNotMeasured;
        base.viewChangeMs = base.maxStallMs = kNotMeasured;
        for (const BoxVoxels& b : bench.boxes) {
            bench.progress(fmt::format("{} {} ms {}% {} Mbit/s: no join", d.name, l.rttMs,
                                       l.lossPct, l.rateMbit));
            base.box = b.n;
            rows.push_back(base);
        }
        leaveAll(bench.server, clients);
        return;
    }
    base.joinMs = double(c.joinedUs - c.connectUs) * 1e-3;
    base.firstViewBytes = c.fullBytes;
    const Camera turned =
        orbitCamera(bench.camera, 5.0f, 0.0f, glm::distance(bench.camera.eye, bench.camera.target),
                    {bench.camera.width, bench.camera.height}, bench.server.volumeSnapshot());
    const uint64_t asked = steadyNowUs();
    c.session->requestView(toViewSpec(turned));
    base.viewChangeMs =
        pumpAllUntil(clients, bench.config.joinTimeoutS, [&] { return c.session->hasFullImage(); })
            ? double(steadyNowUs() - asked) * 1e-3
            : -1;
    const double soakS = isTarget(l) ? bench.config.targetSoakS : bench.config.soakS;
    for (const BoxVoxels& b : bench.boxes) {
        bench.progress(fmt::format("{} {}^3 {} ms {}% {} Mbit/s", d.name, b.n, l.rttMs, l.lossPct,
                                   l.rateMbit));
        const SoakWindow w =
            runSoak(bench.server, bench.link, b, clients, soakS, bench.config.cutHz);
        const ClientFigures f = figuresOf(c, w);
        WanRow r = base;
        r.box = b.n;
        r.updatesPerS = r.minUpdatesPerS = f.updatesPerS;
        r.latencyP50Ms = f.p50;
        r.latencyP99Ms = f.p99;
        r.maxStallMs = f.stallMs;
        r.updates = f.updates;
        r.soakS = double(w.endUs - w.startUs) * 1e-6;
        r.offeredPerS = double(w.submitted) / r.soakS;
        r.egressBytesPerS = w.egressBytes / r.soakS;
        rows.push_back(r);
    }
    leaveAll(bench.server, clients);
}

// The classroom's views: the driller's paper camera, then 15 others orbited about its target in
// 5-degree steps either side (+-5 ... +-35, +40): 16 distinct views, then again.
float classroomYaw(int index) {
    if (index == 0)
        return 0.0f;
    const int k = (index - 1) % 15 + 1;
    return float((k % 2 ? 1 : -1) * 5 * ((k + 1) / 2));
}

// `n` clients of one design on the one shared link: all join, then one soak at the classroom box.
void measureClassroom(Bench& bench, const Design& d, int n, WanResults& out) {
    const WanStudyConfig& config = bench.config;
    const WanLink l{0, 0, config.classroomRateMbit};
    LinkConditions shared = l.conditions();
    shared.shared = true;
    bench.link.setConditions(shared);
    const BoxVoxels* box = &bench.boxes.back();
    for (const BoxVoxels& b : bench.boxes)
        box = b.n == config.classroomBox ? &b : box;
    bench.progress(fmt::format("{} classroom of {}", d.name, n));
    Clients clients;
    const float distance = glm::distance(bench.camera.eye, bench.camera.target);
    const Volume volume = bench.server.volumeSnapshot();
    for (int i = 0; i < n; ++i) {
        const float yaw = classroomYaw(i);
        const Camera view = orbitCamera(bench.camera, yaw, 0.0f, distance,
                                        {bench.camera.width, bench.camera.height}, volume);
        clients.push_back(makeClient(d, view, config.codec, false, fmt::format("class-{}", i)));
        clients.back()->yawDeg = yaw;
        clients.back()->connectUs = steadyNowUs();
        clients.back()->session->connect(bench.relay);
    }
    WanRow row = rowOf(d, l, n, box->n);
    row.classroom = true;
    row.viewChangeMs = kNotMeasured;
    if (!pumpAllUntil(clients, config.joinTimeoutS * 2, [&] { return allJoined(clients); })) {
        const auto joined = std::count_if(clients.begin(), clients.end(),
                                          [](const auto& c) { return c->joinedUs != 0; });
        std::string why;
        for (const auto& c : clients)
            if (!c->joinedUs && why.empty())
                why =
                    c->session->closeReason().empty() ? "still waiting" : c->session->closeReason();
        fmt::print(stderr, "wan study: {} classroom of {}: {} joined within {:.0f} s ({})\n",
                   d.name, n, joined, config.joinTimeoutS * 2, why);
        row.joinMs = -1;
        row.updatesPerS = row.latencyP50Ms = row.latencyP99Ms = row.maxStallMs = kNotMeasured;
        out.rows.push_back(row);
        leaveAll(bench.server, clients);
        return;
    }
    const SoakWindow w =
        runSoak(bench.server, bench.link, *box, clients, config.classroomSoakS, config.cutHz);
    SampleWindow rates{size_t(n)}, p50s{size_t(n)};
    row.soakS = double(w.endUs - w.startUs) * 1e-6;
    row.minUpdatesPerS = std::numeric_limits<double>::infinity();
    for (int i = 0; i < n; ++i) {
        const StudyClient& c = *clients[size_t(i)];
        const ClientFigures f = figuresOf(c, w);
        const double joinMs = double(c.joinedUs - c.connectUs) * 1e-3;
        out.clients.push_back(
            {d.name, n, i, i == 0, c.yawDeg, joinMs, f.updatesPerS, f.p50, f.p99, f.stallMs});
        rates.add(f.updatesPerS);
        if (!std::isnan(f.p50))
            p50s.add(f.p50);
        row.latencyP99Ms = std::max(row.latencyP99Ms, std::isnan(f.p99) ? 0.0 : f.p99);
        row.maxStallMs = std::max(row.maxStallMs, f.stallMs);
        row.joinMs = std::max(row.joinMs, joinMs);
        row.minUpdatesPerS = std::min(row.minUpdatesPerS, f.updatesPerS);
        row.updates += f.updates;
        row.firstViewBytes += c.fullBytes;
    }
    row.updatesPerS = rates.percentile(50);
    row.latencyP50Ms = p50s.size() ? p50s.percentile(50) : kNotMeasured;
    row.offeredPerS = double(w.submitted) / row.soakS;
    row.egressBytesPerS = w.egressBytes / row.soakS;
    out.rows.push_back(row);
    leaveAll(bench.server, clients);
}

} // namespace

void checkWanStudy(const Volume& volume, const WanStudyConfig& config) {
    if (config.boxes.empty())
        throw Error("wan study: no box sizes given");
    // The update study's checks of the boxes: they fit below the bone where the study cuts.
    UpdateStudyConfig u;
    u.sizes = config.boxes;
    u.cycles = u.rounds = 1;
    checkUpdateStudy(volume, u);
    for (int n : config.classroom)
        if (n < 1 || n > 256)
            throw Error("wan study: a classroom of " + std::to_string(n) +
                        " clients (give 1 to 256)");
    if (!(config.soakS > 0 && config.targetSoakS > 0 && config.cutHz > 0))
        throw Error("wan study: soak times and the cut rate must be positive");
}

WanResults runWanStudy(const Volume& volume, const WanStudyConfig& config) {
    checkWanStudy(volume, config);
    const std::vector<WanLink> links = config.links.empty() ? wanSweep(false) : config.links;
    SessionServer server(volume, wanServerConfig(config));
    server.start();
    LinkEmulator link(0, parseAddress("127.0.0.1:" + std::to_string(server.port())), {});
    Bench bench{server,
                link,
                parseAddress("127.0.0.1:" + std::to_string(link.port())),
                cameraPreset("paper", volume, {config.window, config.window}),
                config,
                studyBoxes(server, config.boxes)};
    bench.total =
        int(std::size(kDesigns) * (links.size() * config.boxes.size() + config.classroom.size()));
    WanResults out;
    for (const Design& d : kDesigns)
        for (const WanLink& l : links)
            measureLink(bench, d, l, out.rows);
    for (int n : config.classroom)
        for (const Design& d : kDesigns)
            measureClassroom(bench, d, n, out);
    server.stop();
    if (config.progress)
        config.progress("done", bench.total, bench.total);
    return out;
}

namespace {

// A figure, or an empty cell when it was not measured.
std::string cell(double v, int decimals) {
    return std::isnan(v) ? std::string() : fmt::format("{:.{}f}", v, decimals);
}

} // namespace

std::string wanCsvHeader() {
    return "design,rtt_ms,loss_pct,rate_mbit,clients,box,updates_per_s,latency_p50_ms,"
           "latency_p99_ms,join_ms,view_change_ms,max_stall_ms,soak_s,offered_per_s,"
           "egress_bytes_per_s,min_client_updates_per_s,first_view_bytes,updates";
}

std::string wanCsvRow(const WanRow& r) {
    return fmt::format("{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{}", r.design,
                       cell(r.rttMs, 0), cell(r.lossPct, 1), cell(r.rateMbit, 0), r.clients, r.box,
                       cell(r.updatesPerS, 2), cell(r.latencyP50Ms, 2), cell(r.latencyP99Ms, 2),
                       cell(r.joinMs, 1), cell(r.viewChangeMs, 1), cell(r.maxStallMs, 1),
                       cell(r.soakS, 2), cell(r.offeredPerS, 1), cell(r.egressBytesPerS, 0),
                       cell(r.minUpdatesPerS, 2), cell(r.firstViewBytes, 0), r.updates);
}

std::string wanClientsCsvHeader() {
    return "design,clients,client,role,view_yaw_deg,join_ms,updates_per_s,latency_p50_ms,"
           "latency_p99_ms,max_stall_ms";
}

std::string wanClientsCsvRow(const WanClientRow& r) {
    return fmt::format("{},{},{},{},{},{},{},{},{},{}", r.design, r.clients, r.index,
                       r.driller ? "driller" : "watcher", cell(r.yawDeg, 0), cell(r.joinMs, 1),
                       cell(r.updatesPerS, 2), cell(r.latencyP50Ms, 2), cell(r.latencyP99Ms, 2),
                       cell(r.maxStallMs, 1));
}

} // namespace trephine::study

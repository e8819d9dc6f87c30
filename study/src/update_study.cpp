#include "study/update_study.h"

#include "libsim/camera.h"
#include "libsim/dirty_rect.h"
#include "libsim/error.h"
#include "libsim/skull.h"
#include "libsim/stats.h"
#include "net/codec.h"
#include "net/link_emulator.h"
#include "net/replay_feed.h"
#include "net/session_client.h"
#include "net/session_log.h"
#include "net/session_server.h"
#include "net/view.h"

#include <fmt/format.h>

#include <algorithm>
#include <memory>
#include <optional>

namespace trephine::study {

using namespace trephine::net;

namespace {

struct Method {
    std::string name;
    Sync sync = Sync::Dbi;
    bool fullRender = false;
    Codec volumeCodec = Codec::Raw;
};

std::vector<Method> methodsFor(Codec codec) {
    std::vector<Method> m{{"dbi", Sync::Dbi, false, Codec::Raw},
                          {"dbi-fullrender", Sync::Dbi, true, Codec::Raw},
                          {"volume", Sync::Volume, false, Codec::Raw}};
    if (codec != Codec::Raw)
        m.push_back({std::string("volume-") + codecName(codec), Sync::Volume, false, codec});
    return m;
}

// A stage or latency in us into a window in ms; -1 (not measured: a stage the method has not,
// a latency without the server's clock) adds no sample, so it cannot drag a median to 0.
void put(SampleWindow& w, double us) {
    if (us >= 0)
        w.add(us * 1e-3);
}

// The median of a window, 0 when nothing was measured.
double median(const SampleWindow& w) {
    return w.size() ? w.percentile(50) : 0.0;
}

// Polls the client until `done` says so; false after the timeout.
template <typename F>
bool pumpUntil(SessionClient& client, double timeoutS, F done) {
    const uint64_t deadline = steadyNowUs() + uint64_t(timeoutS * 1e6);
    while (!done()) {
        if (steadyNowUs() > deadline || client.closed())
            return false;
        client.poll(1);
    }
    return true;
}

} // namespace

std::vector<std::string> updateStudyMethods(Codec codec) {
    std::vector<std::string> names;
    for (const Method& m : methodsFor(codec))
        names.push_back(m.name);
    return names;
}

void checkUpdateStudy(const Volume& volume, const UpdateStudyConfig& config) {
    if (config.sizes.empty())
        throw Error("update study: no box sizes given");
    for (int n : config.sizes)
        if (n < 1 || n > std::min({volume.dims().x, volume.dims().y, volume.dims().z}))
            throw Error("update study: box size " + std::to_string(n) + " does not fit the volume");
    if (config.rounds < 1 || config.rounds > config.cycles)
        throw Error("update study: rounds must be in [1, cycles] (" +
                    std::to_string(config.rounds) + " rounds, " + std::to_string(config.cycles) +
                    " cycles)");
    const std::vector<Method> methods = methodsFor(config.codec);
    for (const std::string& name : config.methods)
        if (std::none_of(methods.begin(), methods.end(),
                         [&](const Method& m) { return m.name == name; }))
            throw Error("update study: unknown method '" + name + "'");
    for (size_t i = 0; i < config.sizes.size(); ++i)
        if (std::find(config.sizes.begin(), config.sizes.begin() + ptrdiff_t(i), config.sizes[i]) !=
            config.sizes.begin() + ptrdiff_t(i))
            throw Error("update study: box size " + std::to_string(config.sizes[i]) +
                        " is given twice");
    for (size_t i = 0; i < config.methods.size(); ++i)
        if (std::find(config.methods.begin(), config.methods.begin() + ptrdiff_t(i),
                      config.methods[i]) != config.methods.begin() + ptrdiff_t(i))
            throw Error("update study: method '" + config.methods[i] + "' is given twice");
    for (int n : config.sizes) {
        const Box3i box = surfaceBox(volume, n);
        // Without bone at the top of the box the cuts would be cuts of air, measured as if they
        // were drilling.
        const glm::ivec3 c((box.lo.x + box.hi.x) / 2, (box.lo.y + box.hi.y) / 2, box.hi.z - 1);
        if (box.empty() || volume.density(c.x, c.y, c.z) < kSurfaceDensity)
            throw Error("update study: the volume has no bone on its middle column, where the "
                        "study cuts (the paper camera looks down +z at it)");
        // A box that does not fit below the bone surface is clipped by the volume: its rows
        // would say N^3 for fewer voxels (120^3 on skull:128 is 120 x 120 x 98), and the byte
        // targets would be judged against them.
        if (box.count() != int64_t(n) * n * n)
            throw Error("update study: a " + std::to_string(n) +
                        "^3 box does not fit below "
                        "the bone surface of the volume (" +
                        std::to_string(box.hi.z - box.lo.z) + " voxels deep there)");
    }
}

namespace {

// Per size: the box, its BB_screen and its voxels as they are now, put back after every measured
// cut (so every round starts from the same bone).
struct Size {
    int n = 0;
    Box3i box;
    PixelRect screen;
    std::vector<uint8_t> density, material;
};

// The samples of one (method, size), pooled over the rounds.
struct Samples {
    explicit Samples(size_t capacity)
        : latency(capacity), bytes(capacity), erode(capacity), render(capacity), encode(capacity),
          transmit(capacity), apply(capacity), clientRender(capacity), grid(capacity) {}
    SampleWindow latency, bytes, erode, render, encode, transmit, apply, clientRender, grid;
};

// A sealed study's codes (the handshake's cost is part of what --sealed measures).
constexpr const char* kTraineeCode = "study-trainee";

ServerConfig studyServerConfig(const Volume& volume, const UpdateStudyConfig& config) {
    ServerConfig sc;
    sc.port = 0;
    sc.volumeName = config.volumeName;
    sc.hapticModels = false;
    if (config.sealed) {
        sc.traineeCode = kTraineeCode;
        sc.instructorCode = "study-instructor";
    }
    if (!config.record.empty())
        sc.recorder = SessionRecorder::create(
            config.record, makeLogHeader(volume, sc, config.volumeName, false, 0));
    return sc;
}

std::vector<Method> chosenMethods(const UpdateStudyConfig& config) {
    std::vector<Method> methods = methodsFor(config.codec);
    if (!config.methods.empty()) {
        std::erase_if(methods, [&](const Method& m) {
            return std::find(config.methods.begin(), config.methods.end(), m.name) ==
                   config.methods.end();
        });
    }
    return methods;
}

std::vector<Size> studySizes(const Volume& volume, const Volume& now, const Camera& camera,
                             const UpdateStudyConfig& config) {
    std::vector<Size> sizes;
    for (int n : config.sizes) {
        Size z;
        z.n = n;
        z.box = surfaceBox(volume, n);
        z.screen = dirtyScreenRect(camera, volume, z.box);
        now.copyBox(z.box, z.density, z.material);
        sizes.push_back(std::move(z));
    }
    return sizes;
}

// One method's client for one round: joins, waits for its picture (or volume), then cuts and
// restores each size's box warmup + cycles times, sampling every cut's update.
struct Round {
    int index = 0, cycles = 0;
    int* step = nullptr; // progress so far, of `total`
    int total = 0;
};

void measureMethod(SessionServer& server, const ENetAddress& address, const Method& method,
                   const Camera& camera, const std::vector<Size>& sizes,
                   std::vector<Samples>& samples, const UpdateStudyConfig& config,
                   const Round& round) {
    server.setFullRenderUpdates(method.fullRender);
    ClientConfig cc;
    cc.name = "study-" + method.name;
    cc.code = config.sealed ? kTraineeCode : "";
    cc.codec = config.codec;
    cc.sync = method.sync;
    cc.volumeCodec = method.volumeCodec;
    cc.view = toViewSpec(camera);
    cc.recordCapacity = size_t(round.cycles + config.warmup) * 4 + 16;
    SessionClient client(cc);
    std::optional<UpdateRecord> last;
    client.setRecordCallback([&](const UpdateRecord& r) {
        if (!r.full && r.mode == method.sync)
            last = r;
    });
    client.connect(address);
    const bool ready = pumpUntil(client, 60.0, [&] {
        return method.sync == Sync::Dbi
                   ? client.hasFullImage()
                   : client.sync() == Sync::Volume && client.localVolume() != nullptr &&
                         client.hasFullImage();
    });
    if (!ready)
        throw Error("update study: the " + method.name + " client never received its " +
                    (method.sync == Sync::Dbi ? "first image" : "volume") +
                    (client.closeReason().empty() ? "" : " (" + client.closeReason() + ")"));

    for (size_t si = 0; si < sizes.size(); ++si) {
        const Size& z = sizes[si];
        if (config.progress) {
            std::string label = method.name + " " + std::to_string(z.n) + "^3";
            if (config.rounds > 1)
                label += " (round " + std::to_string(round.index + 1) + "/" +
                         std::to_string(config.rounds) + ")";
            config.progress(label, *round.step, round.total);
        }
        ++*round.step;
        Samples& out = samples[si];
        auto waitOne = [&](const char* what) {
            last.reset();
            if (!pumpUntil(client, config.cycleTimeoutS, [&] { return last.has_value(); }))
                throw Error("update study: " + method.name + " " + std::to_string(z.n) + "^3: no " +
                            what + " update within " + std::to_string(int(config.cycleTimeoutS)) +
                            " s");
            return *last;
        };
        for (int c = 0; c < config.warmup + round.cycles; ++c) {
            server.submitBoxCut(z.box);
            const UpdateRecord r = waitOne("cut");
            server.submitVoxels(z.box, z.density, z.material);
            waitOne("restore");
            if (c < config.warmup)
                continue;
            put(out.latency, r.latencyUs);
            out.bytes.add(double(r.bytes));
            put(out.erode, r.erodeUs);
            put(out.render, r.serverRenderUs);
            put(out.encode, r.encodeUs);
            put(out.transmit, r.transmitUs);
            put(out.apply, r.applyUs);
            put(out.clientRender, r.clientRenderUs);
            put(out.grid, r.gridUs);
        }
    }
    client.disconnect(100);
}

UpdateStudyRow rowOf(const Method& method, const Size& z, const Samples& s) {
    UpdateStudyRow row;
    row.method = method.name;
    row.box = z.n;
    row.bbScreenW = z.screen.w;
    row.bbScreenH = z.screen.h;
    row.bytesPerUpdate = s.bytes.mean();
    row.rawBytesPerUpdate =
        method.sync == Sync::Dbi ? 5.0 * z.screen.w * z.screen.h : double(z.box.count());
    row.latencyP50Ms = median(s.latency);
    row.latencyP99Ms = s.latency.size() ? s.latency.percentile(99) : 0.0;
    row.updatesPerS = row.latencyP50Ms > 0 ? 1000.0 / row.latencyP50Ms : 0.0;
    row.stages = {median(s.erode),    median(s.render), median(s.encode),
                  median(s.transmit), median(s.apply),  median(s.clientRender)};
    row.stages.grid = median(s.grid);
    row.cycles = int(s.latency.size());
    return row;
}

} // namespace

std::vector<UpdateStudyRow> runUpdateStudy(const Volume& volume, const UpdateStudyConfig& config) {
    checkUpdateStudy(volume, config);
    const Camera camera = cameraPreset(config.camera, volume, {config.window, config.window});
    SessionServer server(volume, studyServerConfig(volume, config));
    server.start();
    const ENetAddress serverAddress = parseAddress("127.0.0.1:" + std::to_string(server.port()));
    // With a link to emulate, every client talks to the server through the relay.
    std::unique_ptr<LinkEmulator> link;
    if (config.link)
        link = std::make_unique<LinkEmulator>(0, serverAddress, *config.link);
    const ENetAddress address =
        link ? parseAddress("127.0.0.1:" + std::to_string(link->port())) : serverAddress;

    const std::vector<Method> methods = chosenMethods(config);
    const std::vector<Size> sizes = studySizes(volume, server.volumeSnapshot(), camera, config);
    std::vector<std::vector<Samples>> samples(methods.size());
    for (auto& perMethod : samples)
        perMethod.assign(sizes.size(), Samples(size_t(config.cycles)));

    const int total = int(methods.size() * sizes.size()) * config.rounds;
    int step = 0;
    for (int round = 0; round < config.rounds; ++round) {
        // This round's share of the cycles; the first rounds take the remainder.
        const int cycles = config.cycles / config.rounds + (round < config.cycles % config.rounds);
        for (size_t mi = 0; mi < methods.size(); ++mi)
            measureMethod(server, address, methods[mi], camera, sizes, samples[mi], config,
                          {round, cycles, &step, total});
    }

    std::vector<UpdateStudyRow> rows;
    for (size_t mi = 0; mi < methods.size(); ++mi)
        for (size_t si = 0; si < sizes.size(); ++si)
            rows.push_back(rowOf(methods[mi], sizes[si], samples[mi][si]));
    server.stop();
    if (config.progress)
        config.progress("done", total, total);
    return rows;
}

std::string updatesCsvHeader() {
    return "method,box,bb_screen_w,bb_screen_h,bytes_per_update,raw_bytes_per_update,"
           "updates_per_s,latency_p50_ms,latency_p99_ms,erode_ms,render_ms,encode_ms,"
           "transmit_ms,client_apply_ms,client_render_ms,cycles,grid_ms";
}

std::string updatesCsvRow(const UpdateStudyRow& r) {
    return fmt::format("{},{},{},{},{:.1f},{:.0f},{:.2f},{:.4f},{:.4f},{:.4f},{:.4f},{:.4f},{:.4f},"
                       "{:.4f},{:.4f},{},{:.4f}",
                       r.method.c_str(), r.box, r.bbScreenW, r.bbScreenH, r.bytesPerUpdate,
                       r.rawBytesPerUpdate, r.updatesPerS, r.latencyP50Ms, r.latencyP99Ms,
                       r.stages.erode, r.stages.render, r.stages.encode, r.stages.transmit,
                       r.stages.clientApply, r.stages.clientRender, r.cycles, r.stages.grid);
}

} // namespace trephine::study

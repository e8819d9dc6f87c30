#include "net/update_study.h"

#include "libsim/camera.h"
#include "libsim/dirty_rect.h"
#include "libsim/error.h"
#include "libsim/skull.h"
#include "libsim/stats.h"
#include "libsim/svg_plot.h"
#include "net/codec.h"
#include "net/session_client.h"
#include "net/session_server.h"
#include "net/view.h"

#include <algorithm>
#include <memory>
#include <optional>

namespace trephine::net {

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

double ms(double us) {
    return us < 0 ? 0.0 : us * 1e-3;
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

std::vector<UpdateStudyRow> runUpdateStudy(const Volume& volume, const UpdateStudyConfig& config) {
    if (config.sizes.empty())
        throw Error("update study: no box sizes given");
    for (int n : config.sizes)
        if (n < 1 || n > std::min({volume.dims().x, volume.dims().y, volume.dims().z}))
            throw Error("update study: box size " + std::to_string(n) + " does not fit the volume");
    const Camera camera = cameraPreset(config.camera, volume, {config.window, config.window});

    ServerConfig sc;
    sc.port = 0;
    sc.volumeName = config.volumeName;
    sc.hapticModels = false;
    SessionServer server(volume, sc);
    server.start();
    const ENetAddress address = parseAddress("127.0.0.1:" + std::to_string(server.port()));

    std::vector<Method> methods = methodsFor(config.codec);
    if (!config.methods.empty()) {
        for (const std::string& name : config.methods)
            if (std::none_of(methods.begin(), methods.end(),
                             [&](const Method& m) { return m.name == name; }))
                throw Error("update study: unknown method '" + name + "'");
        std::erase_if(methods, [&](const Method& m) {
            return std::find(config.methods.begin(), config.methods.end(), m.name) ==
                   config.methods.end();
        });
    }
    const int total = int(methods.size() * config.sizes.size());
    int step = 0;
    std::vector<UpdateStudyRow> rows;
    for (const Method& method : methods) {
        server.setFullRenderUpdates(method.fullRender);
        ClientConfig cc;
        cc.name = "study-" + method.name;
        cc.codec = config.codec;
        cc.sync = method.sync;
        cc.volumeCodec = method.volumeCodec;
        cc.view = toViewSpec(camera);
        cc.recordCapacity = size_t(config.cycles + config.warmup) * 4 + 16;
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

        for (int n : config.sizes) {
            if (config.progress)
                config.progress(method.name + " " + std::to_string(n) + "^3", step, total);
            ++step;
            const Box3i box = surfaceBox(volume, n);
            const PixelRect screen = dirtyScreenRect(camera, volume, box);
            // The box's voxels as they are now, put back after every measured cut.
            std::vector<uint8_t> density, material;
            {
                const Volume now = server.volumeSnapshot();
                density.reserve(size_t(box.count()));
                material.reserve(size_t(box.count()));
                for (int z = box.lo.z; z < box.hi.z; ++z)
                    for (int y = box.lo.y; y < box.hi.y; ++y)
                        for (int x = box.lo.x; x < box.hi.x; ++x) {
                            density.push_back(now.density(x, y, z));
                            material.push_back(uint8_t(now.material(x, y, z)));
                        }
            }
            SampleWindow latency, bytes, erode, render, encode, transmit, apply, clientRender;
            auto waitOne = [&](const char* what) {
                last.reset();
                if (!pumpUntil(client, config.cycleTimeoutS, [&] { return last.has_value(); }))
                    throw Error("update study: " + method.name + " " + std::to_string(n) +
                                "^3: no " + what + " update within " +
                                std::to_string(int(config.cycleTimeoutS)) + " s");
                return *last;
            };
            for (int c = 0; c < config.warmup + config.cycles; ++c) {
                server.submitBoxCut(box);
                const UpdateRecord r = waitOne("cut");
                server.submitVoxels(box, density, material);
                waitOne("restore");
                if (c < config.warmup)
                    continue;
                latency.add(ms(r.latencyUs));
                bytes.add(double(r.bytes));
                erode.add(ms(r.erodeUs));
                render.add(ms(r.serverRenderUs));
                encode.add(ms(r.encodeUs));
                transmit.add(ms(r.transmitUs));
                apply.add(ms(r.applyUs));
                clientRender.add(ms(r.clientRenderUs));
            }
            UpdateStudyRow row;
            row.method = method.name;
            row.box = n;
            row.bbScreenW = screen.w;
            row.bbScreenH = screen.h;
            row.bytesPerUpdate = bytes.mean();
            row.rawBytesPerUpdate =
                method.sync == Sync::Dbi ? 5.0 * screen.w * screen.h : double(box.count());
            row.latencyP50Ms = latency.percentile(50);
            row.latencyP99Ms = latency.percentile(99);
            row.updatesPerS = row.latencyP50Ms > 0 ? 1000.0 / row.latencyP50Ms : 0.0;
            row.stages = {erode.percentile(50),  render.percentile(50),
                          encode.percentile(50), transmit.percentile(50),
                          apply.percentile(50),  clientRender.percentile(50)};
            row.cycles = config.cycles;
            rows.push_back(row);
        }
        client.disconnect(100);
    }
    server.stop();
    if (config.progress)
        config.progress("done", total, total);
    return rows;
}

std::string updatesCsvHeader() {
    return "method,box,bb_screen_w,bb_screen_h,bytes_per_update,raw_bytes_per_update,"
           "updates_per_s,latency_p50_ms,latency_p99_ms,erode_ms,render_ms,encode_ms,"
           "transmit_ms,client_apply_ms,client_render_ms,cycles";
}

std::string updatesCsvRow(const UpdateStudyRow& r) {
    return formatString("%s,%d,%d,%d,%.1f,%.0f,%.2f,%.4f,%.4f,%.4f,%.4f,%.4f,%.4f,%.4f,%.4f,%d",
                        r.method.c_str(), r.box, r.bbScreenW, r.bbScreenH, r.bytesPerUpdate,
                        r.rawBytesPerUpdate, r.updatesPerS, r.latencyP50Ms, r.latencyP99Ms,
                        r.stages.erode, r.stages.render, r.stages.encode, r.stages.transmit,
                        r.stages.clientApply, r.stages.clientRender, r.cycles);
}

} // namespace trephine::net

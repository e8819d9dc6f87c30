// The trainer window. Sections:
// [SECTION] scene: what the server's scene gives the window (site, presets, surgical field)
// [SECTION] haptics: the window's device and the force in either design
// [SECTION] frame loop: snapshot -> rectangles / voxel boxes -> tool -> composite -> overlays ->
//           panels -> comparison figures
#include "ui/trainer_app.h"

#include "libsim/device.h"
#include "libsim/dirty_rect.h"
#include "libsim/error.h"
#include "libsim/force_model.h"
#include "libsim/haptics.h"
#include "libsim/skull.h"
#include "libsim/stats.h"
#include "libsim/volume.h"
#include "net/client_thread.h"
#include "net/codec.h"
#include "net/scene.h"
#include "net/view.h"
#include "ui/compositor.h"
#include "ui/mouse_tool.h"
#include "ui/panels.h"
#include "ui/volume_view.h"
#include "ui/window.h"

#include <GLFW/glfw3.h>
#include <imgui.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <deque>
#include <glm/gtc/matrix_transform.hpp>
#include <glm/gtx/quaternion.hpp>
#include <map>
#include <mutex>
#include <optional>
#include <thread>

namespace trephine::ui {

namespace {

// The default layout, 1280 x 900 with the 500-pixel view: the view over Forces; Session, View and
// Network in the middle column; Comparison over Dirty boxes on the right. Each panel gets the
// height its content takes, so none scrolls in a default window (panels stay movable).
constexpr int kPanelWidth = 380;   // the middle column
constexpr int kSideWidth = 400;    // the right-hand column
constexpr int kBottomHeight = 400; // Forces, under the view
constexpr int kMinHeight = 760;
// The band that says a trainee is taken over (opaque: tests find its pixels).
constexpr ImU32 kTakeOverBand = IM_COL32(112, 40, 150, 255);

// [SECTION] scene

// What the window takes from the server's scene (net/scene.h): it never opens or generates a
// volume, so a trainee needs the server's address only.
struct Scene {
    std::shared_ptr<const net::ReceivedScene> received;
    SurfaceSite site{};
    float boundingRadiusMm = 0.0f;
};

Scene sceneFrom(std::shared_ptr<const net::ReceivedScene> received) {
    Scene s;
    s.boundingRadiusMm = net::sceneBoundingRadius(received->scene);
    if (const net::SceneSite* site = net::findSite(received->scene, net::kDefaultSiteName))
        s.site = {site->position, site->normal};
    else // a scene without a burr site: look at the top of the volume
        s.site = {glm::vec3(0, 0, received->scene.extentMm.z * 0.5f), glm::vec3(0, 0, 1)};
    s.received = std::move(received);
    return s;
}

struct ToolMeshCache {
    Compositor* comp = nullptr;
    std::map<std::pair<int, int>, GpuMesh> meshes;
    const GpuMesh& get(ToolKind kind, float diameterMm) {
        auto key = std::make_pair(int(kind), int(std::lround(diameterMm * 10.0f)));
        auto it = meshes.find(key);
        if (it != meshes.end())
            return it->second;
        ToolShape shape;
        try {
            shape = kind == ToolKind::Perforator ? ToolShape::perforator(diameterMm)
                                                 : ToolShape::burr(diameterMm);
        } catch (const Error&) {
            shape = ToolShape::burr(4.0f);
        }
        return meshes[key] = comp->upload(makeToolMesh(shape));
    }
    ~ToolMeshCache() {
        for (auto& [k, m] : meshes)
            comp->destroy(m);
    }
};

// [SECTION] haptics

// The haptic loop's force in either design, chosen per tick. DBI: the server's force models,
// extrapolated and blended as HapticLoop does without a source (the multi-rate scheme). Volume:
// the ForceModel on the client's own copy of the volume, read under ClientThread::withLocalVolume's
// shared lock, so the 1 kHz loop no longer depends on the server's models (it falls back to them
// while no local volume is held). The blender keeps running in volume mode so that a switch back
// to DBI blends from where it is. force() runs on the haptic thread only.
class WindowForceSource : public ForceSource {
public:
    WindowForceSource(const WindowDevice& device, BlendConfig blend)
        : m_device(device), m_blender(blend) {}
    void setClient(const net::ClientThread* client) { m_client = client; } // before the loop runs
    // Any thread: the newest server model (blended in on the next tick; one answering an older
    // tool state than the newest seen is dropped, as HapticLoop drops it).
    void setModel(const HapticModelData& m) { m_serverModel.offer(m, 0.0); }
    // Any thread: compute forces locally (the picture comes from the local volume).
    void setLocal(bool local) { m_local = local; }
    uint64_t localTicks() const { return m_localTicks.load(); }
    uint64_t serverTicks() const { return m_serverTicks.load(); }

    glm::vec3 force(const ToolPose& pose, double now) override {
        if (const NewestModel::Taken taken = m_serverModel.take(); taken.model)
            m_blender.setModel(taken.model->first, now);
        const glm::vec3 extrapolated = m_blender.update(pose.position, now);
        if (m_local.load(std::memory_order_relaxed) && m_client) {
            const WindowDevice::Tool t = m_device.tool();
            glm::vec3 f(0.0f);
            try {
                const ToolShape shape = t.kind == ToolKind::Perforator
                                            ? ToolShape::perforator(t.diameterMm)
                                            : ToolShape::burr(t.diameterMm);
                const ForceModel& model = m_models.get(shape);
                const float speed = t.drilling ? t.speed : 0.0f;
                // The poses change once a frame, so the velocity is the frame's (per tick it was
                // 0 for ~15 ticks, then 16 times the true speed for one: a spiking drag).
                const glm::vec3 velocity = m_device.velocity();
                if (m_client->withLocalVolume([&](const Volume& v) {
                        f = model.compute(v, pose, speed, velocity).force;
                    })) {
                    m_localTicks.fetch_add(1, std::memory_order_relaxed);
                    return f;
                }
            } catch (const Error&) {
                // A shape the factories refuse: no local model; the server's is all there is.
            }
        }
        m_serverTicks.fetch_add(1, std::memory_order_relaxed);
        return extrapolated;
    }

private:
    const WindowDevice& m_device;
    const net::ClientThread* m_client = nullptr;
    ModelBlender m_blender;
    ForceModelCache m_models;
    NewestModel m_serverModel;
    std::atomic<bool> m_local{false};
    std::atomic<uint64_t> m_localTicks{0}, m_serverTicks{0};
};

SyncDesign designOf(net::Sync s) {
    return s == net::Sync::Volume ? SyncDesign::Volume : SyncDesign::Dbi;
}
net::Sync syncOf(SyncDesign d) {
    return d == SyncDesign::Volume ? net::Sync::Volume : net::Sync::Dbi;
}

// The window's copy of the volume for the GPU, rebuilt from the client thread's applied boxes.
void writeBox(Volume& v, const net::AppliedVolumeBox& b) {
    const glm::ivec3 size = b.box.size();
    size_t o = 0;
    for (int z = b.box.lo.z; z < b.box.hi.z; ++z)
        for (int y = b.box.lo.y; y < b.box.hi.y; ++y) {
            const size_t i = v.index(b.box.lo.x, y, z);
            std::memcpy(v.densityData() + i, b.density.data() + o, size_t(size.x));
            std::memcpy(v.materialData() + i, b.material.data() + o, size_t(size.x));
            o += size_t(size.x);
        }
}

glm::mat4 toolMatrix(glm::vec3 position, glm::quat orientation) {
    return glm::translate(glm::mat4(1.0f), position) * glm::mat4_cast(orientation);
}

// "X,Y,Z[:LABEL]" (mm) as an Annotate add; a malformed one is a one-line error naming it.
net::Annotate parseMark(const std::string& text) {
    const std::string where = "--mark '" + text + "'";
    const size_t colon = text.find(':');
    const std::string coords = text.substr(0, colon);
    net::Annotate a;
    a.op = net::Annotate::Op::Add;
    a.label = colon == std::string::npos ? std::string() : text.substr(colon + 1);
    if (a.label.size() > net::kMaxNameLength)
        throw Error(where + ": the label is longer than " + std::to_string(net::kMaxNameLength) +
                    " bytes");
    float v[3];
    const char* p = coords.c_str();
    for (int i = 0; i < 3; ++i) {
        char* end = nullptr;
        v[i] = std::strtof(p, &end);
        const char want = i < 2 ? ',' : '\0';
        if (end == p || *end != want || !std::isfinite(v[i]) ||
            std::abs(v[i]) > net::kMaxAnnotationDistanceMm)
            throw Error(where + ": expected X,Y,Z[:LABEL] with X, Y, Z in mm");
        p = end + (i < 2 ? 1 : 0);
    }
    a.position = {v[0], v[1], v[2]};
    return a;
}

} // namespace

// [SECTION] frame loop

int runTrainerWindow(const TrainerOptions& o) {
    using Clock = std::chrono::steady_clock;
    if (o.sync != "dbi" && o.sync != "volume")
        throw Error("window: --sync must be dbi or volume, not '" + o.sync + "'");
    if (!o.marks.empty() && !o.instructor)
        throw Error("window: --mark: only an instructor places marks");
    std::vector<net::Annotate> scriptedMarks;
    for (const std::string& m : o.marks)
        scriptedMarks.push_back(parseMark(m));
    bool marksSent = scriptedMarks.empty();
    MarkControls markControls;
    MarkUndo markUndo; // the last removal of marks, for the Session panel's undo
    markControls.canMark = o.instructor;
    if (!o.takeOver.empty() && !o.instructor)
        throw Error("window: --take-over: only an instructor takes over a trainee");
    TakeOverControls takeOverControls;
    takeOverControls.canTakeOver = o.instructor;
    ScriptedTakeOver scriptedTakeOver{o.takeOver};
    if (!o.viewAs.empty() && !o.instructor)
        throw Error("window: --view-as: only an instructor views as another participant");
    ViewAsControls viewAsControls;
    viewAsControls.canViewAs = o.instructor;
    viewAsControls.scripted = o.viewAs;
    std::optional<glm::vec3> pointerPick; // the bone under the pointer, last seen over the view
    const int viewSize = o.size;
    WindowConfig wc;
    wc.width = viewSize + kPanelWidth + kSideWidth;
    wc.height = std::max(viewSize + kBottomHeight, kMinHeight);
    wc.title =
        std::string("Trephine - ") + (o.instructor ? "instructor" : "trainee") + " - " + o.address;
    wc.visible = o.visible;
    Window window(wc);
    // A scripted screenshot is the same whatever the pointer of the display happens to hover (no
    // tooltip or highlighted panel from it).
    if (!o.screenshot.empty() && !o.script.empty())
        ImGui::GetIO().ConfigFlags |= ImGuiConfigFlags_NoMouse;
    Compositor comp;
    comp.resize(viewSize, viewSize);
    VolumeView volumeView; // the replicated-volume design's picture
    ToolMeshCache tools{&comp, {}};
    GpuMesh fieldMesh;

    net::ClientThreadConfig cc;
    cc.address = o.address;
    cc.client.name = o.name;
    cc.client.role = o.instructor ? net::Role::Instructor : net::Role::Trainee;
    cc.client.codec = net::parseCodec(o.codec);
    cc.client.sync = o.sync == "volume" ? net::Sync::Volume : net::Sync::Dbi;
    cc.client.volumeCodec = net::parseCodec(o.volumeCodec);
    // The window ray casts the volume itself (VolumeView), in whichever design it starts: the
    // client thread then hands over voxel boxes instead of re-rendering on the CPU. In DBI mode
    // the flag changes nothing, so one setting serves both designs and every switch.
    cc.client.renderLocally = false;
    cc.client.view.width = cc.client.view.height = 1; // the real view needs the server's scene
    // The haptic loop sends the tool states; the client thread hands it each force model.
    WindowDevice device;
    net::ClientThread* clientPtr = nullptr;
    HapticLoopConfig hc;
    hc.rateHz = 1000.0;
    hc.sendRateHz = 100.0;
    WindowForceSource forces(device, hc.blend);
    HapticLoop haptics(device, hc, [&](const DeviceState& s, double) {
        WindowDevice::Tool t = device.tool();
        net::ToolState ts;
        ts.toolKind = uint8_t(t.kind);
        ts.diameterMm = t.diameterMm;
        ts.position = s.pose.position;
        ts.orientation = s.pose.orientation;
        ts.speed = t.drilling ? t.speed : 0.0f;
        ts.drilling = t.drilling;
        // The device sample: the server's step and velocity follow the loop's sampling, not when
        // the client thread got round to sending it (and the force round trip starts here).
        ts.clientTimeUs = net::steadyNowUs();
        clientPtr->sendToolState(ts);
    });
    const auto loopT0 = Clock::now();
    cc.onHapticModel = [&](const net::HapticModel& m) {
        HapticModelData d;
        d.position = m.position;
        d.force = m.force;
        d.gradient = m.gradient;
        d.contact = m.contact;
        d.toolSequence = m.toolSequence;
        haptics.setModel(d, std::chrono::duration<double>(Clock::now() - loopT0).count());
        forces.setModel(d);
    };
    net::ClientThread client(cc);
    clientPtr = &client;
    forces.setClient(&client);
    forces.setLocal(cc.client.sync == net::Sync::Volume);
    haptics.setForceSource(&forces);
    client.start();
    haptics.start();
    // However the window ends (an exception from a GL upload or a screenshot included), the
    // haptic thread stops before the client it sends to is destroyed, then the client.
    struct StopThreads {
        HapticLoop& haptics;
        net::ClientThread& client;
        ~StopThreads() {
            haptics.stop();
            client.stop();
        }
    } stopThreads{haptics, client};

    std::optional<Scene> scene;
    std::optional<uint64_t> sceneSeen; // the id of the last scene taken (or refused)
    std::string sceneError;            // the scene lacks what the options ask for (a preset)
    Camera baseCamera;                 // the view before orbiting
    ViewControls viewControls;
    viewControls.distanceMm = o.distanceMm;
    viewControls.yawDeg = o.orbitDeg;
    viewControls.pitchDeg = o.tiltDeg;
    Camera wantedCamera;
    ToolControls toolControls;
    toolControls.canDrill = !o.instructor;
    DirtyBoxPanelState boxState;
    NetworkHistory netHistory;
    ForceHistory forceHistory;
    ParticipantForces participantForces; // instructor: every other participant's force
    DirtyBoxHistory boxHistory;

    Dbi cpuDbi;               // pass 1's picture on the CPU, for the cursor's depth lookups
    Camera cpuDbiCamera;      // the camera cpuDbi was rendered (or read back) with
    bool haveImage = false;   // the textures hold a full image of the current view
    uint32_t imageViewId = 0; // viewId of the image in the textures
    net::ViewSpec imageView;  // and its view: the camera it was rendered with
    // [Replicated volume] the window's copy of the volume, mirrored in volumeView's textures.
    Volume gpuVolume;
    bool haveVolume = false;  // volumeView holds a whole volume
    bool volumeDirty = false; // the ray cast changed since cpuDbi was read back
    Camera volumeCamera;      // the camera cpuDbi was read back with
    // Which design feeds the picture: the one whose full update (whole DBI or whole volume)
    // arrived last. Until the new design's first full update the old picture stays.
    SyncDesign picture = designOf(cc.client.sync);
    uint64_t pictureSinceUs = 0;
    SyncDesign wanted = picture; // the toggle (the design asked for)
    int volumeRefusalsSeen = 0;  // ClientSnapshot::volumeRefusals handled
    ComparisonHistory comparison;
    std::array<std::vector<double>, kSyncDesignCount> frameMs; // this second's frames per design
    // This second's updates on screen per design (full ones excluded: a join or a switch): bytes,
    // raw bytes and latency from the cause at the server to the end of the frame that first drew
    // them, so both designs' latencies include their own drawing (the volume's GPU upload and
    // ray cast, the DBI's texture upload and restore).
    struct DrawnUpdate {
        SyncDesign design;
        double latencyUs; // cause -> applied by the client thread; -1: unknown
        uint64_t appliedUs;
        uint32_t bytes, rawBytes;
    };
    std::vector<DrawnUpdate> drawnThisFrame;
    struct LiveSecond {
        std::vector<double> latencyMs;
        double bytes = 0, rawBytes = 0;
        int updates = 0;
    };
    std::array<LiveSecond, kSyncDesignCount> liveSecond;
    std::array<uint64_t, kSyncDesignCount> framesPerDesign{};
    SampleWindow volumeUploadMs(256), volumeBoxMs(1024); // the volume client's GPU apply stage
    uint64_t volumeUploads = 0, volumeBoxUpdates = 0;
    uint64_t ticksAtLastSecond = 0;
    double lastSecondAt = 0.0, firstPictureAt = -1.0;
    size_t nextSwitch = 0;
    int switchesRequested = 0, switchesCompleted = 0;
    auto requestDesign = [&](SyncDesign d) {
        wanted = d;
        client.requestSync(syncOf(d));
        ++switchesRequested;
    };
    uint64_t hapticSeen = 0;
    glm::vec3 toolPos(0.0f);
    glm::quat toolRot(1, 0, 0, 0);
    bool toolValid = false;
    double nextSecond = 1.0, lastRectAt = 0.0, scriptStart = -1;
    uint64_t updatesAtLastSecond = 0;
    bool scriptDone = o.script.empty();
    int settledFrames = 0, frames = 0, pictureFrames = 0;
    double lastPictureFrameAt = 0.0; // [--frames] when the last frame that counted was drawn
    bool scriptedEnd = false;        // --screenshot taken or --frames drawn (or failed, said)
    int exitCode = 0;
    const auto t0 = Clock::now();
    auto seconds = [&] { return std::chrono::duration<double>(Clock::now() - t0).count(); };

    auto makeCamera = [&]() {
        return orbitCamera(baseCamera, viewControls.yawDeg, viewControls.pitchDeg,
                           viewControls.distanceMm, {viewSize, viewSize}, scene->boundingRadiusMm);
    };

    while (!window.shouldClose() && !(o.quit && o.quit->load())) {
        const auto frameStart = Clock::now();
        const double now = seconds();
        auto snap = client.snapshot();
        // The server refused the volume design (its whole volume does not fit a message): the
        // client thread goes on in DBI, and so does the toggle.
        if (snap->volumeRefusals != volumeRefusalsSeen) {
            volumeRefusalsSeen = snap->volumeRefusals;
            std::fprintf(stderr, "window: %s; staying with %s\n", snap->closeReason.c_str(),
                         syncDesignName(SyncDesign::Dbi));
            wanted = SyncDesign::Dbi;
        }
        // Taking over (the server's roster): a held trainee's drill is paused, and an instructor
        // drills only while it holds a trainee.
        const uint16_t selfId = snap->welcome ? snap->welcome->clientId : 0;
        const uint16_t heldByOther = o.instructor ? 0 : takenOverBy(snap->participants, selfId);
        const uint16_t holding = o.instructor ? heldBy(snap->participants, selfId) : 0;
        toolControls.canDrill = o.instructor ? holding != 0 : heldByOther == 0;

        // The scene the server sent after its welcome, and again when a reconnect's scene is
        // another (a server restarted on another volume: the old skull's scalp, drape and camera
        // stayed around the new one); the same scene again keeps the view as it is.
        if (snap->scene && snap->scene->scene.sceneId != sceneSeen) {
            sceneSeen = snap->scene->scene.sceneId;
            scene = sceneFrom(snap->scene);
            sceneError.clear();
            comp.destroy(fieldMesh); // the previous scene's, if any
            fieldMesh = comp.upload(scene->received->field);
            std::optional<Camera> preset;
            if (o.camera == "site")
                preset = cameraLookingAt(scene->site.position, scene->site.normal, o.distanceMm,
                                         45.0f, {viewSize, viewSize}, scene->boundingRadiusMm);
            else
                preset = net::presetCamera(scene->received->scene, o.camera, {viewSize, viewSize});
            if (preset) {
                baseCamera = *preset;
                viewControls.distanceMm = glm::length(baseCamera.eye - baseCamera.target);
                viewControls.setHome(); // --orbit, --tilt and this distance
                wantedCamera = makeCamera();
                client.requestView(net::toViewSpec(wantedCamera));
            } else {
                sceneError = "the server's scene has no camera preset '" + o.camera + "'";
                scene.reset();
            }
        }
        if (scene && viewControls.dirty) {
            viewControls.dirty = false;
            if (snap->viewingAs != 0) // the View panel moved: our own camera again
                client.viewAs(0);
            wantedCamera = makeCamera();
            client.requestView(net::toViewSpec(wantedCamera));
        }

        // Applied rectangles: only their pixels are uploaded. A full image newer than the last
        // whole volume makes the DBI the picture again (a switch back has completed).
        for (net::AppliedRect& r : client.drainRects()) {
            if (r.full) {
                if (r.pixels.width() != viewSize || r.pixels.height() != viewSize)
                    continue; // the placeholder view before ours
                if (haveVolume && r.appliedUs < pictureSinceUs)
                    continue; // older than the volume that replaced the DBI
                comp.uploadFull(r.pixels);
                haveImage = true;
                imageViewId = r.viewId;
                imageView = r.view;
                if (picture != SyncDesign::Dbi)
                    ++switchesCompleted;
                picture = SyncDesign::Dbi;
                pictureSinceUs = r.appliedUs;
                cpuDbi = std::move(r.pixels);
                cpuDbiCamera = net::toCamera(r.view);
            } else if (haveImage && r.viewId == imageViewId) {
                comp.uploadRect(r.rect, r.pixels);
                if (picture == SyncDesign::Dbi && cpuDbi.bounds().contains(r.rect))
                    cpuDbi.apply(r.pixels, r.rect.x, r.rect.y);
                drawnThisFrame.push_back(
                    {SyncDesign::Dbi, r.latencyUs, r.appliedUs, r.bytes, r.rawBytes});
            } else {
                continue;
            }
            lastRectAt = now;
            netHistory.addUpdate({now, r.latencyUs, r.bytes, r.rawBytes, r.full});
            boxHistory.add({now, r.rect, r.sequence, r.bytes, r.latencyUs, r.full});
        }
        // Applied voxel boxes (volume design): the whole volume is uploaded, a box re-uploads
        // only its voxels and the gradients around them. Both are timed: the volume client's
        // apply stage on the GPU side.
        for (net::AppliedVolumeBox& b : client.drainVolumeBoxes()) {
            const auto applyStart = Clock::now();
            if (b.full) {
                if (haveImage && b.appliedUs < pictureSinceUs && picture == SyncDesign::Dbi)
                    continue; // older than the DBI that replaced the volume
                gpuVolume = Volume(b.dims, b.spacing);
                writeBox(gpuVolume, b);
                volumeView.upload(gpuVolume);
                volumeUploadMs.add(
                    std::chrono::duration<double, std::milli>(Clock::now() - applyStart).count());
                ++volumeUploads;
                haveVolume = true;
                if (picture != SyncDesign::Volume)
                    ++switchesCompleted;
                picture = SyncDesign::Volume;
                pictureSinceUs = b.appliedUs;
            } else if (haveVolume && b.dims == gpuVolume.dims() && !b.box.empty() &&
                       glm::all(glm::greaterThanEqual(b.box.lo, glm::ivec3(0))) &&
                       glm::all(glm::lessThanEqual(b.box.hi, b.dims)) &&
                       b.density.size() == size_t(b.box.count()) &&
                       b.material.size() == size_t(b.box.count())) {
                writeBox(gpuVolume, b);
                volumeView.updateBox(gpuVolume, b.box);
                volumeBoxMs.add(
                    std::chrono::duration<double, std::milli>(Clock::now() - applyStart).count());
                ++volumeBoxUpdates;
                drawnThisFrame.push_back(
                    {SyncDesign::Volume, b.latencyUs, b.appliedUs, b.bytes, b.rawBytes});
            } else {
                continue;
            }
            volumeDirty = true;
            lastRectAt = now;
            PixelRect screen;
            if (!b.full && snap->view.width > 1)
                screen = dirtyScreenRect(net::toCamera(snap->view), gpuVolume, b.box);
            netHistory.addUpdate({now, b.latencyUs, b.bytes, b.rawBytes, b.full});
            if (!screen.empty())
                boxHistory.add({now, screen, b.sequence, b.bytes, b.latencyUs, b.full});
        }
        netHistory.expire(now);
        // Forces on the local copy only while it is the picture and no switch away is under way:
        // the server stops sending voxels at the request, so the copy would go stale.
        forces.setLocal(picture == SyncDesign::Volume && wanted == SyncDesign::Volume);
        const bool havePicture = picture == SyncDesign::Volume ? haveVolume : haveImage;
        if (havePicture && firstPictureAt < 0)
            firstPictureAt = now;
        const bool switching = wanted != picture;
        // The DBI is drawn, and picked, with the camera it was rendered with: a new view's full
        // image can reach the textures before a snapshot names the view (tools drawn with the old
        // matrices over the new picture for a frame, a jitter while orbiting). The local volume is
        // drawn with the view the client holds now.
        const net::ViewSpec& shownView =
            picture == SyncDesign::Dbi && haveImage ? imageView : snap->view;
        const bool viewMatches = shownView.width == viewSize && shownView.height == viewSize;
        const Camera dbiCamera = net::toCamera(shownView);
        if (picture == SyncDesign::Volume && !(volumeCamera == dbiCamera)) {
            volumeDirty = true;       // a new view: the picture for picking must be read back again
            boxHistory.boxes.clear(); // the old view's rectangles (a DBI's go with its full image)
        }

        // The scripted toggle: flip at the next time, once the switch before it has completed.
        if (nextSwitch < o.switchSyncAtS.size() && firstPictureAt >= 0 && !switching &&
            now - firstPictureAt >= o.switchSyncAtS[nextSwitch]) {
            ++nextSwitch;
            requestDesign(wanted == SyncDesign::Dbi ? SyncDesign::Volume : SyncDesign::Dbi);
        }

        // The frame begins (events polled, ImGui's new frame) before the tool reads the input:
        // ImGui 1.86 zeroes io.MouseWheel at the end of each frame, so read before NewFrame the
        // wheel was always 0, and keys came a frame late.
        window.beginFrame();

        // Tool: the script, or the mouse device on the bone under the cursor; the Session panel's
        // last values (drawn below) kept within their ranges first.
        toolControls = withinRanges(toolControls);
        ImGuiIO& io = ImGui::GetIO();
        if (scene && havePicture && o.script == "burrhole") {
            if (scriptStart < 0)
                scriptStart = now;
            ScriptPose p = burrholePose(scene->site, now - scriptStart);
            toolControls.kind = 0;
            toolPos = p.position;
            toolRot = glm::rotation(glm::vec3(0, 0, 1), p.axis);
            toolControls.drilling = p.drilling;
            toolValid = true;
            if (p.done && !scriptDone) {
                scriptDone = true;
                lastRectAt = now;
            }
        } else if (scene && havePicture && viewMatches) {
            // M marks the bone under the pointer now: over air or off the view it marks nothing
            // (it marked the last bone point the pointer had crossed, wherever that was).
            bool markKey = false;
            if (!io.WantCaptureKeyboard) {
                if (ImGui::IsKeyPressed(GLFW_KEY_B))
                    toolControls.kind = 0;
                if (ImGui::IsKeyPressed(GLFW_KEY_P))
                    toolControls.kind = 1;
                if (ImGui::IsKeyPressed(GLFW_KEY_LEFT_BRACKET))
                    toolControls.burrMm = std::max(kBurrMinDiameterMm, toolControls.burrMm - 0.5f);
                if (ImGui::IsKeyPressed(GLFW_KEY_RIGHT_BRACKET))
                    toolControls.burrMm = std::min(kBurrMaxDiameterMm, toolControls.burrMm + 0.5f);
                if (ImGui::IsKeyPressed(GLFW_KEY_DOWN))
                    toolControls.pushMm = steppedPush(toolControls.pushMm, 1.0f);
                if (ImGui::IsKeyPressed(GLFW_KEY_UP))
                    toolControls.pushMm = steppedPush(toolControls.pushMm, -1.0f);
                markKey = markControls.canMark && ImGui::IsKeyPressed(GLFW_KEY_M);
            }
            const bool overView = io.MousePos.x >= 0 && io.MousePos.y >= 0 &&
                                  io.MousePos.x < float(viewSize) &&
                                  io.MousePos.y < float(viewSize) && !io.WantCaptureMouse;
            if (overView) {
                toolControls.pushMm = steppedPush(toolControls.pushMm, io.MouseWheel);
                int px = int(io.MousePos.x), py = viewSize - 1 - int(io.MousePos.y);
                // Unprojected with the camera cpuDbi was made with: in volume mode its depth is
                // read back after this pick, so for one frame after a view change (or a switch
                // from DBI) it is still the old picture's, which the new camera would turn into a
                // point off the bone.
                if (auto hit = pickSurface(cpuDbi, cpuDbiCamera, px, py)) {
                    pointerPick = *hit;
                    markControls.addAtPointer = markControls.addAtPointer || markKey;
                    ToolShape shape =
                        toolControls.kind == 1
                            ? ToolShape::perforator()
                            : ToolShape::burr(std::clamp(toolControls.burrMm, kBurrMinDiameterMm,
                                                         kBurrMaxDiameterMm));
                    ToolPose pose = toolPoseAt(*hit, dbiCamera, shape, toolControls.pushMm);
                    toolPos = pose.position;
                    toolRot = pose.orientation;
                    toolValid = true;
                }
            }
            toolControls.drilling = toolControls.canDrill && toolValid && overView &&
                                    ImGui::IsMouseDown(ImGuiMouseButton_Left);
        }
        const ToolKind kind = toolControls.kind == 1 ? ToolKind::Perforator : ToolKind::Burr;
        const float diameter =
            kind == ToolKind::Perforator ? kPerforatorDiameterMm : toolControls.burrMm;
        {
            DeviceState ds;
            ds.pose.position = toolPos;
            ds.pose.orientation = toolRot;
            ds.buttons = toolControls.drilling ? 1u : 0u;
            ds.valid = toolValid && snap->state == net::LinkState::Connected;
            device.set(ds, {kind, diameter, toolControls.speed, toolControls.drilling}, now);
        }

        // Forces: the server's samples, and the force extrapolated at the tool each frame.
        if (snap->hapticModel && snap->hapticModels != hapticSeen) {
            hapticSeen = snap->hapticModels;
            forceHistory.addServer(now, snap->hapticModel->force);
        }
        forceHistory.expire(now);
        if (o.instructor)
            participantForces.update(now, snap->relayedModels);
        // The 1 kHz extrapolated force, straight from the haptic loop's recorder.
        // The loop keeps its own clock: its newest tick is now on the window's, so the two
        // series share one time axis in the Forces panel.
        forceHistory.extrapolated.clear();
        const std::vector<HapticSample> ticks = haptics.samples();
        const double tickShift = ticks.empty() ? 0.0 : now - ticks.back().time;
        for (const HapticSample& h : ticks)
            forceHistory.extrapolated.push_back({h.time + tickShift, h.force});
        const HapticLoopStats hstats = haptics.stats();
        if (now >= nextSecond) {
            const auto& rt = snap->rates;
            uint64_t u = snap->updatesApplied;
            netHistory.addSecond(rt[size_t(net::Channel::Image)].bytesInPerS,
                                 rt[size_t(net::Channel::ToolState)].bytesOutPerS,
                                 rt[size_t(net::Channel::Haptic)].bytesInPerS,
                                 double(u - updatesAtLastSecond), snap->rttUs);
            updatesAtLastSecond = u;
            nextSecond += 1.0;
        }

        // Composite: pass 1 the DBI (or the ray cast of the local volume), pass 2 the anatomy
        // and the tools with the same matrices and depth test, blitted top-left.
        const float viewTop = 0.0f;
        if (havePicture && viewMatches) {
            if (picture == SyncDesign::Volume) {
                comp.beginEmpty(dbiCamera);
                volumeView.draw(dbiCamera);
                if (volumeDirty) {
                    // The picture's depth before the tools, for the cursor's depth lookups and
                    // the marks' occlusion: read back only when the volume or the view changed,
                    // and only the depth (the colour once, for the report, after the loop).
                    comp.readBackDepth(cpuDbi);
                    volumeCamera = cpuDbiCamera = dbiCamera;
                    volumeDirty = false;
                }
            } else {
                comp.begin(dbiCamera);
            }
            if (scene)
                comp.draw(fieldMesh, glm::mat4(1.0f));
            for (const auto& [id, t] : snap->others)
                comp.draw(tools.get(ToolKind(t.toolKind), t.diameterMm),
                          toolMatrix(t.position, t.orientation), participantColor(int(id)));
            if (toolValid)
                comp.draw(tools.get(kind, diameter), toolMatrix(toolPos, toolRot),
                          participantColor(0));
            comp.blitTo(0, window.height() - viewSize);
        }

        // Overlays in the view: labels, dirty boxes, connection state.
        ImDrawList* fg = ImGui::GetForegroundDrawList();
        if (havePicture && viewMatches) {
            // Labels and marks belong to the view: one that projects outside it (orbited or
            // zoomed away) is cut at its edge, not drawn over the panels beside and under it.
            fg->PushClipRect(ImVec2(0.0f, viewTop), ImVec2(float(viewSize), viewTop + viewSize));
            glm::dmat4 vp = viewProjection(dbiCamera);
            auto label = [&](glm::vec3 p, glm::vec3 axis, glm::vec4 c, const std::string& text) {
                WindowPoint w = projectToWindow(vp, dbiCamera, glm::dvec3(p + axis * 40.0f));
                if (w.w <= 0)
                    return;
                ImVec2 at(float(w.window.x) + 8.0f, viewTop + float(viewSize - w.window.y));
                fg->AddRectFilled(ImVec2(at.x - 3, at.y - 2),
                                  ImVec2(at.x + ImGui::CalcTextSize(text.c_str()).x + 3,
                                         at.y + ImGui::GetFontSize() + 2),
                                  IM_COL32(0, 0, 0, 140), 3.0f);
                fg->AddText(at, ImGui::GetColorU32(ImVec4(c.r, c.g, c.b, 1.0f)), text.c_str());
            };
            for (const auto& [id, t] : snap->others)
                label(t.position, t.orientation * glm::vec3(0, 0, 1), participantColor(int(id)),
                      participantName(snap->participants, id) + (t.drilling ? " (drilling)" : ""));
            if (toolValid)
                label(toolPos, toolRot * glm::vec3(0, 0, 1), participantColor(0),
                      o.name + (toolControls.drilling ? " (drilling)" : ""));
            // The instructors' marks: a ring on the bone and its label beside it; faint where the
            // bone in this view lies more than 2 mm in front of the mark (it is behind it).
            const glm::vec4 mc = markColor();
            for (const net::AnnotationInfo& a : snap->annotations) {
                WindowPoint w = projectToWindow(vp, dbiCamera, glm::dvec3(a.position));
                if (w.w <= 0)
                    continue;
                const int px = int(w.window.x), py = int(w.window.y);
                bool hidden = false;
                if (cpuDbi.bounds().contains(PixelRect{px, py, 1, 1}) &&
                    cpuDbi.width() == dbiCamera.width && cpuDbi.height() == dbiCamera.height) {
                    const double bone = eyeZFromWindowDepth(dbiCamera, cpuDbi.depth(px, py));
                    const double mark = eyeZFromWindowDepth(dbiCamera, w.window.z);
                    hidden = bone - mark > 2.0; // eye z is negative in front of the eye
                }
                const ImU32 markCol =
                    ImGui::GetColorU32(ImVec4(mc.r, mc.g, mc.b, hidden ? 0.35f : 1.0f));
                const ImVec2 c(float(w.window.x), viewTop + float(viewSize - w.window.y));
                fg->AddCircle(c, 8.0f, IM_COL32(0, 0, 0, 160), 0, 4.5f);
                fg->AddCircle(c, 8.0f, markCol, 0, 2.5f);
                fg->AddCircleFilled(c, 2.5f, markCol);
                if (!a.label.empty()) {
                    const ImVec2 at(c.x + 12.0f, c.y - ImGui::GetFontSize() * 0.5f);
                    fg->AddRectFilled(ImVec2(at.x - 3, at.y - 2),
                                      ImVec2(at.x + ImGui::CalcTextSize(a.label.c_str()).x + 3,
                                             at.y + ImGui::GetFontSize() + 2),
                                      IM_COL32(0, 0, 0, 140), 3.0f);
                    fg->AddText(at, markCol, a.label.c_str());
                }
            }
            fg->PopClipRect();
            drawDirtyBoxOverlay(boxState, boxHistory, now, 0.0f, viewTop, viewSize);
        }
        // A view larger than the server serves is refused by the client (the window waited for
        // its first image for good, the reason in one line of the Network panel).
        const int64_t maxViewPixels = snap->welcome ? snap->welcome->maxViewPixels : 0;
        const bool viewTooLarge = snap->state == net::LinkState::Connected && snap->welcome &&
                                  int64_t(viewSize) * viewSize > maxViewPixels;
        auto tooLargeText = [&] {
            return "The server serves views of at most " + std::to_string(maxViewPixels) +
                   " pixels; this view is " + std::to_string(viewSize) + " x " +
                   std::to_string(viewSize) + ": restart with " + o.sizeOption + " " +
                   std::to_string(int(std::sqrt(double(maxViewPixels)))) + " or less";
        };
        {
            std::string status;
            if (viewTooLarge)
                status = tooLargeText();
            else if (snap->state == net::LinkState::Connecting)
                status = "Connecting to " + o.address + " (attempt " +
                         std::to_string(snap->attempts) + ")...";
            else if (snap->state == net::LinkState::Retrying)
                status = "Not connected: " + snap->closeReason + "\nRetrying...";
            else if (!sceneError.empty())
                status = "Cannot show the session: " + sceneError;
            else if (!havePicture)
                status = "Waiting for the first image of the skull...";
            else if (snap->waitingForView)
                status = "Waiting for the new view...";
            else if (switching)
                status = std::string("Switching to ") + syncDesignName(wanted) +
                         ": waiting for its first full update...";
            if (!status.empty()) {
                ImVec2 sz = ImGui::CalcTextSize(status.c_str(), nullptr, false, viewSize - 40.0f);
                ImVec2 at((float(viewSize) - sz.x) * 0.5f,
                          havePicture ? 12.0f : viewTop + (float(viewSize) - sz.y) * 0.5f);
                fg->AddRectFilled(ImVec2(at.x - 10, at.y - 8),
                                  ImVec2(at.x + sz.x + 10, at.y + sz.y + 8),
                                  IM_COL32(20, 20, 24, 210), 6.0f);
                fg->AddText(nullptr, 0.0f, at, IM_COL32(255, 200, 90, 255), status.c_str(), nullptr,
                            viewSize - 40.0f);
            }
            // Taken over, or holding a trainee: said at the foot of the view, on a solid band.
            std::string held;
            if (heldByOther)
                held = participantName(snap->participants, heldByOther) +
                       " has taken over: your drill is paused";
            else if (holding)
                held = "You hold " + participantName(snap->participants, holding) +
                       ": your drill cuts, theirs is paused";
            if (!held.empty()) {
                const ImVec2 sz = ImGui::CalcTextSize(held.c_str());
                const ImVec2 at((float(viewSize) - sz.x) * 0.5f,
                                viewTop + float(viewSize) - sz.y - 18.0f);
                fg->AddRectFilled(ImVec2(at.x - 12, at.y - 8),
                                  ImVec2(at.x + sz.x + 12, at.y + sz.y + 8), kTakeOverBand, 6.0f);
                fg->AddText(at, IM_COL32(255, 255, 255, 255), held.c_str());
            }
        }

        // Panels: Forces under the view, and two columns right of it (kPanelWidth, above).
        const float right = float(viewSize), colW = float(kPanelWidth);
        const float side = right + colW, sideW = float(kSideWidth);
        const float H = float(window.height());
        const float sessionH = std::floor(H * 0.31f), viewPanelH = 165.0f;
        const float networkY = sessionH + viewPanelH, comparisonH = std::floor(H * 0.535f);
        ImGui::SetNextWindowPos(ImVec2(right, 0), ImGuiCond_FirstUseEver);
        ImGui::SetNextWindowSize(ImVec2(colW, sessionH), ImGuiCond_FirstUseEver);
        drawSessionPanel(*snap, toolControls, markControls, takeOverControls, viewAsControls,
                         o.instructor ? "instructor" : "trainee", o.address, o.name);
        // Marks asked for (the panel, the M key, --mark once joined); the server lists them back.
        if (!marksSent && snap->welcome && snap->state == net::LinkState::Connected) {
            for (const net::Annotate& a : scriptedMarks)
                client.annotate(a);
            marksSent = true;
        }
        for (const net::Annotate& a : markRequests(markControls, markUndo, *snap, pointerPick))
            client.annotate(a);
        // Take over (the panel's buttons, --take-over once the trainee is listed) or hand back.
        if (snap->welcome && snap->state == net::LinkState::Connected)
            if (const auto id = scriptedTakeOver.due(snap->attempts, snap->participants))
                client.takeOver(*id);
        if (takeOverControls.asked)
            client.takeOver(*takeOverControls.asked);
        takeOverControls.asked.reset();
        // View as (the panel, --view-as once the participant is listed).
        if (scene && snap->welcome && snap->state == net::LinkState::Connected)
            if (const auto id =
                    viewAsControls.due(snap->attempts, snap->welcome->clientId, snap->participants))
                client.viewAs(*id);
        if (viewAsControls.asked)
            client.viewAs(*viewAsControls.asked);
        viewAsControls.asked.reset();
        ImGui::SetNextWindowPos(ImVec2(right, sessionH), ImGuiCond_FirstUseEver);
        ImGui::SetNextWindowSize(ImVec2(colW, viewPanelH), ImGuiCond_FirstUseEver);
        drawViewPanel(viewControls, snap->waitingForView || !havePicture,
                      picture == SyncDesign::Volume ? "local render" : "DBI",
                      havePicture ? &dbiCamera : nullptr);
        ImGui::SetNextWindowPos(ImVec2(right, networkY), ImGuiCond_FirstUseEver);
        ImGui::SetNextWindowSize(ImVec2(colW, H - networkY), ImGuiCond_FirstUseEver);
        drawNetworkPanel(*snap, netHistory, now);
        ImGui::SetNextWindowPos(ImVec2(side, 0), ImGuiCond_FirstUseEver);
        ImGui::SetNextWindowSize(ImVec2(sideW, comparisonH), ImGuiCond_FirstUseEver);
        SyncDesign shown = wanted;
        if (drawComparisonPanel(shown, picture, comparison, now) && shown != wanted)
            requestDesign(shown);
        if (ImGui::Begin("Comparison")) { // appends to the panel: what only the window knows
            // Short lines: the 400-pixel panel cut the longer ones off.
            ImGui::TextDisabled("frame ms: start to swap + glFinish, median of 1 s");
            ImGui::TextDisabled("volume GPU: full %.1f ms (%llu), box p50 %.2f ms (%llu)",
                                volumeUploadMs.size() ? volumeUploadMs.percentile(50) : 0.0,
                                (unsigned long long)volumeUploads,
                                volumeBoxMs.size() ? volumeBoxMs.percentile(50) : 0.0,
                                (unsigned long long)volumeBoxUpdates);
            ImGui::TextDisabled("haptic ticks: %llu local volume, %llu server models",
                                (unsigned long long)forces.localTicks(),
                                (unsigned long long)forces.serverTicks());
        }
        ImGui::End();
        ImGui::SetNextWindowPos(ImVec2(0, float(viewSize)), ImGuiCond_FirstUseEver);
        ImGui::SetNextWindowSize(ImVec2(right, H - float(viewSize)), ImGuiCond_FirstUseEver);
        drawForcesPanel(forceHistory, hstats.achievedRateHz, now,
                        o.instructor ? &participantForces : nullptr, &snap->participants);
        ImGui::SetNextWindowPos(ImVec2(side, comparisonH), ImGuiCond_FirstUseEver);
        ImGui::SetNextWindowSize(ImVec2(sideW, H - comparisonH), ImGuiCond_FirstUseEver);
        drawDirtyBoxPanel(boxState, boxHistory, now);

        // Screenshot / frame budget.
        ++frames;
        if (viewTooLarge && (!o.screenshot.empty() || o.frames > 0)) {
            std::fprintf(stderr, "trephine: %s\n", tooLargeText().c_str());
            exitCode = 1;
            window.endFrame(nullptr);
            scriptedEnd = true;
            break;
        }
        // Connected too: a picture kept from before a lost link is not the session's now.
        const bool connected = snap->state == net::LinkState::Connected;
        const bool settled = connected && havePicture && viewMatches && scene && scriptDone &&
                             !switching && nextSwitch == o.switchSyncAtS.size() &&
                             !snap->waitingForView && now - lastRectAt > 0.5 && marksSent &&
                             (o.takeOver.empty() || holding != 0) &&
                             (o.viewAs.empty() || snap->viewingAs != 0) &&
                             snap->annotations.size() >= scriptedMarks.size();
        settledFrames = settled ? settledFrames + 1 : 0;
        Dbi capture;
        bool shoot = !o.screenshot.empty() && settledFrames >= std::max(o.frames, 1);
        const bool timedOut = !o.screenshot.empty() && now > o.timeoutS;
        window.endFrame(shoot || timedOut ? &capture : nullptr);
        if (havePicture && viewMatches) {
            // The frame's time in the design it drew: from its start to the swap, waiting for
            // the GPU work (llvmpipe renders on glFinish); the pacing sleep is not included.
            glFinish();
            frameMs[int(picture)].push_back(
                std::chrono::duration<double, std::milli>(Clock::now() - frameStart).count());
            ++framesPerDesign[int(picture)];
            const uint64_t drawnUs = net::steadyNowUs();
            for (const DrawnUpdate& u : drawnThisFrame) {
                if (u.design != picture)
                    continue; // in the textures, not on screen (the other design's picture)
                LiveSecond& l = liveSecond[int(u.design)];
                ++l.updates;
                l.bytes += u.bytes;
                l.rawBytes += u.rawBytes;
                if (u.latencyUs >= 0 && drawnUs >= u.appliedUs)
                    l.latencyMs.push_back((u.latencyUs + double(drawnUs - u.appliedUs)) * 1e-3);
            }
        }
        drawnThisFrame.clear();
        // The Comparison panel's point for this second, for the design that fed the picture;
        // the other keeps its last figures.
        if (now - lastSecondAt >= 1.0) {
            const uint64_t ticks = hstats.ticks;
            const double hz = double(ticks - ticksAtLastSecond) / (now - lastSecondAt);
            std::vector<double>& fm = frameMs[int(picture)];
            // No point while a switch is under way: the server has stopped the old design's
            // updates, so the second measures the wait, and it would stay as the old design's
            // greyed figures once the switch completes.
            if (havePicture && !fm.empty() && !switching) {
                const net::ModeFigures& m = snap->modes[size_t(syncOf(picture))];
                const LiveSecond& l = liveSecond[int(picture)];
                ComparisonFigures f;
                f.updatesPerS = m.updateRatePerS;
                f.bytesPerUpdate = l.updates ? l.bytes / l.updates : -1.0;
                f.rawBytesPerUpdate = l.updates ? l.rawBytes / l.updates : -1.0;
                f.latencyP50Ms = l.latencyMs.empty() ? -1.0 : percentile(l.latencyMs, 50.0);
                f.latencyP99Ms = l.latencyMs.empty() ? -1.0 : percentile(l.latencyMs, 99.0);
                f.frameMs = percentile(fm, 50.0);
                f.hapticHz = hz;
                comparison.record(picture, now, f);
            }
            for (auto& v : frameMs)
                v.clear();
            liveSecond = {};
            ticksAtLastSecond = ticks;
            lastSecondAt = now;
        }
        if (shoot || timedOut) {
            writeScreenshot(o.screenshot, capture);
            if (timedOut) {
                // What the view was still waiting for, where the script asked for something.
                std::string waiting = net::linkStateName(snap->state);
                if (!o.takeOver.empty() && holding == 0)
                    waiting += "; --take-over: no trainee '" + o.takeOver + "' taken over";
                if (!marksSent || snap->annotations.size() < scriptedMarks.size())
                    waiting += "; --mark: the marks not listed yet";
                std::fprintf(stderr,
                             "trephine: screenshot %s taken after %.0f s without a settled view "
                             "(%s)\n",
                             o.screenshot.c_str(), now, waiting.c_str());
                exitCode = 1;
            } else {
                std::printf("screenshot %s (%dx%d) after %d frames\n", o.screenshot.c_str(),
                            capture.width(), capture.height(), frames);
            }
            scriptedEnd = true;
            break;
        }
        // --frames without a screenshot: that many frames showing the picture, or, with none
        // by --timeout, a failure said in one line (it used to exit 0 after N frames of
        // "connecting", which a scripted run took for success).
        // Frames count only while connected: a lost server's last picture counted on to exit 0
        // (and in volume mode, with the view gone, the run never ended). --timeout also bounds
        // the time since the last counted frame.
        if (o.screenshot.empty() && o.frames > 0) {
            if (connected && havePicture && viewMatches) {
                ++pictureFrames;
                lastPictureFrameAt = now;
            }
            if (pictureFrames >= o.frames) {
                scriptedEnd = true;
                break;
            }
            if (pictureFrames == 0 && now > o.timeoutS) {
                std::fprintf(stderr, "trephine: no picture from %s after %.0f s (%s)\n",
                             o.address.c_str(), now, net::linkStateName(snap->state));
                exitCode = 1;
                scriptedEnd = true;
                break;
            }
            if (pictureFrames > 0 && now - lastPictureFrameAt > o.timeoutS) {
                std::fprintf(stderr,
                             "trephine: no picture from %s for %.0f s after %d of %d frames (%s: "
                             "%s)\n",
                             o.address.c_str(), now - lastPictureFrameAt, pictureFrames, o.frames,
                             net::linkStateName(snap->state),
                             snap->closeReason.empty() ? "no reason given"
                                                       : snap->closeReason.c_str());
                exitCode = 1;
                scriptedEnd = true;
                break;
            }
        }
        std::this_thread::sleep_until(frameStart + std::chrono::milliseconds(10));
    }
    // Closed before the screenshot or the frames it was run for: a script must not read exit 0
    // as done (the PNG it waits for is not there).
    if (!scriptedEnd && (!o.screenshot.empty() || o.frames > 0)) {
        std::fprintf(stderr, "trephine: the window was closed before %s\n",
                     o.screenshot.empty() ? "its --frames were drawn"
                                          : ("the screenshot " + o.screenshot).c_str());
        exitCode = 1;
    }
    haptics.stop(); // (stopThreads would; the report below reads the stopped client)
    client.stop();
    for (SyncDesign d : {SyncDesign::Dbi, SyncDesign::Volume}) {
        if (!comparison.measured(d))
            continue;
        const ComparisonFigures& f = comparison.series(d).last;
        std::printf("window: %s: %.1f updates/s, %.0f bytes/update (raw %.0f), latency p50 %.2f "
                    "ms p99 %.2f ms, frame %.2f ms, haptics %.0f Hz\n",
                    syncDesignName(d), f.updatesPerS, f.bytesPerUpdate, f.rawBytesPerUpdate,
                    f.latencyP50Ms, f.latencyP99Ms, f.frameMs, f.hapticHz);
    }
    if (o.report && picture == SyncDesign::Volume && haveVolume &&
        cpuDbi.width() == volumeCamera.width && cpuDbi.height() == volumeCamera.height) {
        // The local volume's picture in colour, as last shown (the loop read back its depth).
        comp.beginEmpty(volumeCamera);
        volumeView.draw(volumeCamera);
        cpuDbi = comp.readBack();
    }
    if (o.report) {
        TrainerReport& r = *o.report;
        r.comparison = comparison;
        r.picture = picture;
        r.view = cpuDbi;
        // The camera `view` was made with (the snapshot's view is the placeholder once the
        // client has stopped, or another while a new view's image is on its way).
        r.camera = picture == SyncDesign::Volume ? volumeCamera : cpuDbiCamera;
        r.switchesRequested = switchesRequested;
        r.switchesCompleted = switchesCompleted;
        r.volumeUploads = volumeUploads;
        r.volumeBoxUpdates = volumeBoxUpdates;
        r.localForceTicks = forces.localTicks();
        r.serverForceTicks = forces.serverTicks();
        r.frames = framesPerDesign;
    }
    comp.destroy(fieldMesh);
    return exitCode;
}

} // namespace trephine::ui

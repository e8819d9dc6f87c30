// The trainer window. Sections:
// [SECTION] scene: volume-derived data (site, surgical field) built off the main thread
// [SECTION] haptics: the window's tool as the trainee core's tool source
// [SECTION] drawing: the view's labels, messages and the panels' layout
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
#include "net/client_model.h"
#include "net/client_thread.h"
#include "net/codec.h"
#include "net/scene.h"
#include "net/tool_model.h"
#include "net/trainee_core.h"
#include "net/view.h"
#include "ui/compositor.h"
#include "ui/mouse_tool.h"
#include "ui/panels.h"
#include "ui/scripted_driver.h"
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
            shape = net::toolShape(kind, diameterMm);
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

// The window's tool for the trainee core: the pose and tool the frame set on the WindowDevice,
// and the velocity of the frames' poses (per 1 kHz tick it was 0 for ~15 ticks, then 16 times the
// true speed for one: a spiking drag).
class WindowTools : public net::ToolSource {
public:
    explicit WindowTools(WindowDevice& device) : m_device(device) {}
    Device& device() override { return m_device; }
    net::ToolState toolAt(const ToolPose& pose, double) override {
        const WindowDevice::Tool t = m_device.tool();
        net::ToolState ts;
        ts.toolKind = uint8_t(t.kind);
        ts.diameterMm = t.diameterMm;
        ts.position = pose.position;
        ts.orientation = pose.orientation;
        ts.speed = t.drilling ? t.speed : 0.0f;
        ts.drilling = t.drilling;
        return ts;
    }
    glm::vec3 velocity(const ToolPose&, double) override { return m_device.velocity(); }

private:
    WindowDevice& m_device;
};

using net::designOf;
using net::syncOf;

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

// [Replicated volume] the window's copy of the volume, mirrored in a VolumeView's textures, and
// the GPU side of the volume client's apply stage (timed: the Comparison panel shows it).
struct LocalVolume {
    VolumeView view; // needs the window's GL context
    Volume volume;
    bool have = false;  // `view` holds a whole volume
    bool dirty = false; // the ray cast changed since the picking picture was read back
    Camera camera;      // the camera the picking picture was read back with
    SampleWindow uploadMs{256}, boxMs{1024};
    uint64_t uploads = 0, boxUpdates = 0;

    // A whole volume: replaces the copy and its textures.
    void replace(const net::AppliedVolumeBox& b) {
        const auto start = std::chrono::steady_clock::now();
        volume = Volume(b.dims, b.spacing);
        writeBox(volume, b);
        view.upload(volume);
        uploadMs.add(msSince(start));
        ++uploads;
        have = true;
    }
    // A box of the copy: its voxels and the gradients around them re-uploaded; false (nothing
    // done) when it does not fit the volume held.
    bool update(const net::AppliedVolumeBox& b) {
        const auto start = std::chrono::steady_clock::now();
        if (!have || b.dims != volume.dims() || b.box.empty() ||
            !glm::all(glm::greaterThanEqual(b.box.lo, glm::ivec3(0))) ||
            !glm::all(glm::lessThanEqual(b.box.hi, b.dims)) ||
            b.density.size() != size_t(b.box.count()) || b.material.size() != size_t(b.box.count()))
            return false;
        writeBox(volume, b);
        view.updateBox(volume, b.box);
        boxMs.add(msSince(start));
        ++boxUpdates;
        return true;
    }
    static double msSince(std::chrono::steady_clock::time_point t) {
        return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t)
            .count();
    }
};

// Which design feeds the picture, and which the Comparison toggle asks for. A design becomes the
// picture when its full update (a whole DBI or a whole volume) arrives; until then the old
// picture stays, and the view is switching.
struct DesignSwitch {
    SyncDesign picture = SyncDesign::Dbi;
    SyncDesign wanted = SyncDesign::Dbi;
    uint64_t pictureSinceUs = 0; // when the picture's full update was applied
    int refusalsSeen = 0;        // ClientSnapshot::volumeRefusals handled
    int requested = 0, completed = 0;

    bool switching() const { return wanted != picture; }
    void request(SyncDesign d, net::ClientThread& client) {
        wanted = d;
        client.requestSync(syncOf(d));
        ++requested;
    }
    void arrived(SyncDesign d, uint64_t appliedUs) {
        if (picture != d)
            ++completed;
        picture = d;
        pictureSinceUs = appliedUs;
    }
};

glm::mat4 toolMatrix(glm::vec3 position, glm::quat orientation) {
    return glm::translate(glm::mat4(1.0f), position) * glm::mat4_cast(orientation);
}

// [SECTION] drawing

// The view's labels (every tool's owner, ours last) and the instructors' marks, cut at the view's
// edge; `own` null: no tool of ours is shown.
void drawViewLabels(const net::ClientSnapshot& snap, const Camera& camera, const Dbi& cpuDbi,
                    int viewSize, const ToolPose* own, const std::string& ownLabel) {
    ImDrawList* fg = ImGui::GetForegroundDrawList();
    const float viewTop = 0.0f;
    // Labels and marks belong to the view: one that projects outside it (orbited or
    // zoomed away) is cut at its edge, not drawn over the panels beside and under it.
    fg->PushClipRect(ImVec2(0.0f, viewTop), ImVec2(float(viewSize), viewTop + viewSize));
    glm::dmat4 vp = viewProjection(camera);
    auto label = [&](glm::vec3 p, glm::vec3 axis, glm::vec4 c, const std::string& text) {
        WindowPoint w = projectToWindow(vp, camera, glm::dvec3(p + axis * 40.0f));
        if (w.w <= 0)
            return;
        ImVec2 at(float(w.window.x) + 8.0f, viewTop + float(viewSize - w.window.y));
        fg->AddRectFilled(
            ImVec2(at.x - 3, at.y - 2),
            ImVec2(at.x + ImGui::CalcTextSize(text.c_str()).x + 3, at.y + ImGui::GetFontSize() + 2),
            IM_COL32(0, 0, 0, 140), 3.0f);
        fg->AddText(at, ImGui::GetColorU32(ImVec4(c.r, c.g, c.b, 1.0f)), text.c_str());
    };
    for (const auto& [id, t] : snap.others)
        label(t.position, t.orientation * glm::vec3(0, 0, 1), participantColor(int(id)),
              participantName(snap.participants, id) + (t.drilling ? " (drilling)" : ""));
    if (own)
        label(own->position, own->orientation * glm::vec3(0, 0, 1), participantColor(0), ownLabel);
    // The instructors' marks: a ring on the bone and its label beside it; faint where the
    // bone in this view lies more than 2 mm in front of the mark (it is behind it).
    const glm::vec4 mc = markColor();
    for (const net::AnnotationInfo& a : snap.annotations) {
        WindowPoint w = projectToWindow(vp, camera, glm::dvec3(a.position));
        if (w.w <= 0)
            continue;
        const int px = int(w.window.x), py = int(w.window.y);
        bool hidden = false;
        if (cpuDbi.bounds().contains(PixelRect{px, py, 1, 1}) && cpuDbi.width() == camera.width &&
            cpuDbi.height() == camera.height) {
            const double bone = eyeZFromWindowDepth(camera, cpuDbi.depth(px, py));
            const double mark = eyeZFromWindowDepth(camera, w.window.z);
            hidden = bone - mark > 2.0; // eye z is negative in front of the eye
        }
        const ImU32 markCol = ImGui::GetColorU32(ImVec4(mc.r, mc.g, mc.b, hidden ? 0.35f : 1.0f));
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
}

// A line about the link or the picture over the view (centred when no picture is shown).
void drawViewMessage(const std::string& status, bool havePicture, int viewSize) {
    ImDrawList* fg = ImGui::GetForegroundDrawList();
    const float viewTop = 0.0f;
    if (!status.empty()) {
        ImVec2 sz = ImGui::CalcTextSize(status.c_str(), nullptr, false, viewSize - 40.0f);
        ImVec2 at((float(viewSize) - sz.x) * 0.5f,
                  havePicture ? 12.0f : viewTop + (float(viewSize) - sz.y) * 0.5f);
        fg->AddRectFilled(ImVec2(at.x - 10, at.y - 8), ImVec2(at.x + sz.x + 10, at.y + sz.y + 8),
                          IM_COL32(20, 20, 24, 210), 6.0f);
        fg->AddText(nullptr, 0.0f, at, IM_COL32(255, 200, 90, 255), status.c_str(), nullptr,
                    viewSize - 40.0f);
    }
}

// Taken over, or holding a trainee: said at the foot of the view, on a solid band.
void drawHeldBand(const std::string& held, int viewSize) {
    ImDrawList* fg = ImGui::GetForegroundDrawList();
    const float viewTop = 0.0f;
    if (!held.empty()) {
        const ImVec2 sz = ImGui::CalcTextSize(held.c_str());
        const ImVec2 at((float(viewSize) - sz.x) * 0.5f, viewTop + float(viewSize) - sz.y - 18.0f);
        fg->AddRectFilled(ImVec2(at.x - 12, at.y - 8), ImVec2(at.x + sz.x + 12, at.y + sz.y + 8),
                          kTakeOverBand, 6.0f);
        fg->AddText(at, IM_COL32(255, 255, 255, 255), held.c_str());
    }
}

// Where each panel opens (they stay movable): Session, View and Network in the middle column
// (kPanelWidth), Comparison over Dirty boxes on the right (kSideWidth), Forces under the view.
struct PanelLayout {
    struct Box {
        float x, y, w, h;
    };
    Box session, view, network, comparison, dirtyBoxes, forces, assessment;
};

PanelLayout panelLayout(int viewSize, float height) {
    const float right = float(viewSize), colW = float(kPanelWidth);
    const float side = right + colW, sideW = float(kSideWidth);
    const float sessionH = std::floor(height * 0.31f), viewPanelH = 165.0f;
    const float networkY = sessionH + viewPanelH, comparisonH = std::floor(height * 0.535f);
    PanelLayout l;
    l.session = {right, 0, colW, sessionH};
    l.view = {right, sessionH, colW, viewPanelH};
    l.network = {right, networkY, colW, height - networkY};
    l.comparison = {side, 0, sideW, comparisonH};
    // Dirty boxes share the rest of the right column with Assessment, below it.
    const float boxesH = std::floor((height - comparisonH) * 0.4f);
    l.dirtyBoxes = {side, comparisonH, sideW, boxesH};
    l.assessment = {side, comparisonH + boxesH, sideW, height - comparisonH - boxesH};
    l.forces = {0, float(viewSize), right, height - float(viewSize)};
    return l;
}

void placeNextPanel(const PanelLayout::Box& b) {
    ImGui::SetNextWindowPos(ImVec2(b.x, b.y), ImGuiCond_FirstUseEver);
    ImGui::SetNextWindowSize(ImVec2(b.w, b.h), ImGuiCond_FirstUseEver);
}

// The window's trainee core: the client asks for a 1x1 placeholder view until the scene is
// known, and hands voxel boxes over for the GPU rather than rendering them itself.
net::TraineeCoreConfig coreConfigFor(const TrainerOptions& o) {
    net::TraineeCoreConfig coreConfig;
    net::ClientThreadConfig& cc = coreConfig.client;
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
    coreConfig.haptics.rateHz = 1000.0;
    coreConfig.haptics.sendRateHz = 100.0;
    return coreConfig;
}

WindowConfig windowConfigFor(const TrainerOptions& o) {
    WindowConfig wc;
    wc.width = o.size + kPanelWidth + kSideWidth;
    wc.height = std::max(o.size + kBottomHeight, kMinHeight);
    wc.title =
        std::string("Trephine - ") + (o.instructor ? "instructor" : "trainee") + " - " + o.address;
    wc.visible = o.visible;
    return wc;
}

// The Comparison panel's last figures of each design measured, on stdout when the window ends.
void printComparison(const ComparisonHistory& comparison) {
    for (SyncDesign d : {SyncDesign::Dbi, SyncDesign::Volume}) {
        if (!comparison.measured(d))
            continue;
        const ComparisonFigures& f = comparison.series(d).last;
        std::printf("window: %s: %.1f updates/s, %.0f bytes/update (raw %.0f), latency p50 %.2f "
                    "ms p99 %.2f ms, frame %.2f ms, haptics %.0f Hz\n",
                    syncDesignName(d), f.updatesPerS, f.bytesPerUpdate, f.rawBytesPerUpdate,
                    f.latencyP50Ms, f.latencyP99Ms, f.frameMs, f.hapticHz);
    }
}

// [SECTION] frame loop

using Clock = std::chrono::steady_clock;

// However the window ends (an exception from a GL upload or a screenshot included), the haptic
// thread stops before the client it sends to, then the client (the core's order).
struct StopCore {
    net::TraineeCore& core;
    ~StopCore() { core.stop(); }
};

// The trainee core: the client thread, and the haptic loop that sends the tool states the frames
// set on the device and feels the force in either design.
net::TraineeCore& started(net::TraineeCore& core, net::ToolSource& tools) {
    core.connect();
    core.startHaptics(tools);
    return core;
}

// This frame's incremental updates, counted as on screen at the end of the frame that first drew
// them, so both designs' latencies include their own drawing (the volume's GPU upload and ray
// cast, the DBI's texture upload and restore).
struct DrawnUpdate {
    SyncDesign design;
    double latencyUs; // cause -> applied by the client thread; -1: unknown
    uint64_t appliedUs;
    uint32_t bytes, rawBytes;
};

// What one frame found out, for the steps after: the snapshot, the picture and the tool drawn.
struct FrameState {
    Clock::time_point start;
    double now = 0.0;
    std::shared_ptr<const net::ClientSnapshot> snap;
    uint16_t heldByOther = 0; // a trainee's holder
    uint16_t holding = 0;     // the trainee an instructor holds
    SyncDesign picture = SyncDesign::Dbi;
    bool havePicture = false;
    bool switching = false;
    bool viewMatches = false;
    Camera dbiCamera; // the camera the picture is drawn (and picked) with
    ToolKind kind = ToolKind::Burr;
    float diameter = 0.0f;
    HapticLoopStats hstats;
    int64_t maxViewPixels = 0;
    bool viewTooLarge = false;
};

// The trainer window: its members are declared in the order the window needs them built, so
// they go in reverse: the core stops (StopCore) before the device and tools its threads use, and
// the GL objects go before the window's context.
class TrainerWindow {
public:
    explicit TrainerWindow(const TrainerOptions& o);
    int run();

private:
    static WindowConfig checkedWindowConfig(const TrainerOptions& o);
    double seconds() const { return std::chrono::duration<double>(Clock::now() - t0).count(); }
    Camera makeCamera() const;
    bool frame();
    void takeSnapshot(FrameState& f);
    void takeScene(const FrameState& f);
    void applyRects(const FrameState& f);
    void applyVolumeBoxes(const FrameState& f);
    void choosePicture(FrameState& f);
    void updateTool(FrameState& f);
    void mouseTool(const FrameState& f);
    void composite(const FrameState& f);
    void drawOverlays(FrameState& f);
    std::string tooLargeText(const FrameState& f) const;
    void drawPanels(const FrameState& f);
    bool endFrame(const FrameState& f);
    void closingFigures();

    const TrainerOptions& o;
    const int viewSize;

    // The scripted driver (--script, --mark, --take-over, --screenshot, --frames, ...) and the
    // Session panel's controls.
    ScriptedDriver script;
    MarkControls markControls;
    MarkUndo markUndo; // the last removal of marks, for the Session panel's undo
    TakeOverControls takeOverControls;
    ViewAsControls viewAsControls;
    std::optional<glm::vec3> pointerPick; // the bone under the pointer, last seen over the view

    // GL: the window and what draws into it.
    Window window;
    Compositor comp;
    LocalVolume local; // the replicated-volume design's picture
    ToolMeshCache tools{&comp, {}};
    GpuMesh fieldMesh;

    // Connection: the trainee core and the device its haptic loop reads.
    const net::TraineeCoreConfig coreConfig;
    WindowDevice device;
    WindowTools windowTools{device};
    net::TraineeCore core{coreConfig};
    net::ClientThread& client = core.client();
    StopCore stopCore{started(core, windowTools)};

    // Scene and camera.
    std::optional<Scene> scene;
    std::optional<uint64_t> sceneSeen; // the id of the last scene taken (or refused)
    std::string sceneError;            // the scene lacks what the options ask for (a preset)
    Camera baseCamera;                 // the view before orbiting
    ViewControls viewControls;
    Camera wantedCamera;

    // Panels' controls and the model behind them.
    ToolControls toolControls;
    DirtyBoxPanelState boxState;
    net::ClientModel model; // the panels' histories and the report's figures

    // Picture: the DBI's textures and their CPU mirror, and the design that feeds them.
    Dbi cpuDbi;               // pass 1's picture on the CPU, for the cursor's depth lookups
    Camera cpuDbiCamera;      // the camera cpuDbi was rendered (or read back) with
    bool haveImage = false;   // the textures hold a full image of the current view
    uint32_t imageViewId = 0; // viewId of the image in the textures
    net::ViewSpec imageView;  // and its view: the camera it was rendered with
    DesignSwitch designs;
    std::vector<DrawnUpdate> drawnThisFrame;
    std::array<uint64_t, kSyncDesignCount> framesPerDesign{};
    double firstPictureAt = -1.0;

    // Tool: our own pose, drawn and sent to the haptic loop.
    glm::vec3 toolPos{0.0f};
    glm::quat toolRot{1, 0, 0, 0};
    bool toolValid = false;
    double lastRectAt = 0.0;
    const Clock::time_point t0 = Clock::now();
};

// --view-as is checked after the script's options and before a window opens.
WindowConfig TrainerWindow::checkedWindowConfig(const TrainerOptions& o) {
    if (!o.viewAs.empty() && !o.instructor)
        throw Error("window: --view-as: only an instructor views as another participant");
    return windowConfigFor(o);
}

TrainerWindow::TrainerWindow(const TrainerOptions& options)
    : o(options), viewSize(options.size), script(options), window(checkedWindowConfig(options)),
      coreConfig(coreConfigFor(options)) {
    markControls.canMark = o.instructor;
    takeOverControls.canTakeOver = o.instructor;
    viewAsControls.canViewAs = o.instructor;
    viewAsControls.scripted = o.viewAs;
    // A scripted screenshot is the same whatever the pointer of the display happens to hover (no
    // tooltip or highlighted panel from it).
    if (script.ignoresPointer())
        ImGui::GetIO().ConfigFlags |= ImGuiConfigFlags_NoMouse;
    comp.resize(viewSize, viewSize);
    viewControls.distanceMm = o.distanceMm;
    viewControls.yawDeg = o.orbitDeg;
    viewControls.pitchDeg = o.tiltDeg;
    toolControls.canDrill = !o.instructor;
    designs.picture = designs.wanted = designOf(coreConfig.client.client.sync);
}

Camera TrainerWindow::makeCamera() const {
    return orbitCamera(baseCamera, viewControls.yawDeg, viewControls.pitchDeg,
                       viewControls.distanceMm, {viewSize, viewSize}, scene->boundingRadiusMm);
}

int TrainerWindow::run() {
    while (!window.shouldClose() && !(o.quit && o.quit->load()))
        if (!frame())
            break;
    script.closed(); // before its screenshot or frames: exit 1
    core.stop();     // (stopCore would; the report below reads the stopped client)
    printComparison(model.comparison);
    closingFigures();
    comp.destroy(fieldMesh);
    return script.exitCode();
}

// One frame: snapshot -> scene -> rectangles / voxel boxes -> tool -> composite -> overlays ->
// panels -> the frame's end; false: the window ends.
bool TrainerWindow::frame() {
    FrameState f;
    f.start = Clock::now();
    f.now = seconds();
    takeSnapshot(f);
    takeScene(f);
    applyRects(f);
    applyVolumeBoxes(f);
    choosePicture(f);
    // The frame begins (events polled, ImGui's new frame) before the tool reads the input:
    // ImGui 1.86 zeroes io.MouseWheel at the end of each frame, so read before NewFrame the
    // wheel was always 0, and keys came a frame late.
    window.beginFrame();
    updateTool(f);
    composite(f);
    drawOverlays(f);
    drawPanels(f);
    return endFrame(f);
}

void TrainerWindow::takeSnapshot(FrameState& f) {
    f.snap = client.snapshot();
    const net::ClientSnapshot& snap = *f.snap;
    model.addSnapshot(f.snap, f.now);
    // The server refused the volume design (its whole volume does not fit a message): the
    // client thread goes on in DBI, and so does the toggle.
    if (snap.volumeRefusals != designs.refusalsSeen) {
        designs.refusalsSeen = snap.volumeRefusals;
        std::fprintf(stderr, "window: %s; staying with %s\n", snap.closeReason.c_str(),
                     syncDesignName(SyncDesign::Dbi));
        designs.wanted = SyncDesign::Dbi;
    }
    // Taking over (the server's roster): a held trainee's drill is paused, and an instructor
    // drills only while it holds a trainee.
    const uint16_t selfId = snap.welcome ? snap.welcome->clientId : 0;
    f.heldByOther = o.instructor ? 0 : takenOverBy(snap.participants, selfId);
    f.holding = o.instructor ? heldBy(snap.participants, selfId) : 0;
    toolControls.canDrill = o.instructor ? f.holding != 0 : f.heldByOther == 0;
}

// The scene the server sent after its welcome, and again when a reconnect's scene is another (a
// server restarted on another volume: the old skull's scalp, drape and camera would stay around
// the new one); the same scene again keeps the view as it is.
void TrainerWindow::takeScene(const FrameState& f) {
    const auto& snap = f.snap;
    if (snap->scene && snap->scene->scene.sceneId != sceneSeen) {
        sceneSeen = snap->scene->scene.sceneId;
        scene = sceneFrom(snap->scene);
        sceneError.clear();
        comp.destroy(fieldMesh); // the previous scene's, if any
        fieldMesh = comp.upload(scene->received->field);
        std::optional<Camera> preset;
        if (o.camera == "site")
            preset = cameraLookingAt(scene->site.position, scene->site.normal, o.distanceMm, 45.0f,
                                     {viewSize, viewSize}, scene->boundingRadiusMm);
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
}

// Applied rectangles: only their pixels are uploaded. A full image newer than the last whole
// volume makes the DBI the picture again (a switch back has completed).
void TrainerWindow::applyRects(const FrameState& f) {
    for (net::AppliedRect& r : client.drainRects()) {
        if (r.full) {
            if (r.pixels.width() != viewSize || r.pixels.height() != viewSize)
                continue; // the placeholder view before ours
            if (local.have && r.appliedUs < designs.pictureSinceUs)
                continue; // older than the volume that replaced the DBI
            comp.uploadFull(r.pixels);
            haveImage = true;
            imageViewId = r.viewId;
            imageView = r.view;
            designs.arrived(SyncDesign::Dbi, r.appliedUs);
            cpuDbi = std::move(r.pixels);
            cpuDbiCamera = net::toCamera(r.view);
        } else if (haveImage && r.viewId == imageViewId) {
            comp.uploadRect(r.rect, r.pixels);
            if (designs.picture == SyncDesign::Dbi && cpuDbi.bounds().contains(r.rect))
                cpuDbi.apply(r.pixels, r.rect.x, r.rect.y);
            drawnThisFrame.push_back(
                {SyncDesign::Dbi, r.latencyUs, r.appliedUs, r.bytes, r.rawBytes});
        } else {
            continue;
        }
        lastRectAt = f.now;
        model.addRect(r, f.now);
    }
}

// Applied voxel boxes (volume design): the whole volume is uploaded, a box re-uploads only its
// voxels and the gradients around them. Both are timed: the volume client's apply stage on the
// GPU side.
void TrainerWindow::applyVolumeBoxes(const FrameState& f) {
    for (net::AppliedVolumeBox& b : client.drainVolumeBoxes()) {
        if (b.full) {
            if (haveImage && b.appliedUs < designs.pictureSinceUs &&
                designs.picture == SyncDesign::Dbi)
                continue; // older than the DBI that replaced the volume
            local.replace(b);
            designs.arrived(SyncDesign::Volume, b.appliedUs);
        } else if (local.update(b)) {
            drawnThisFrame.push_back(
                {SyncDesign::Volume, b.latencyUs, b.appliedUs, b.bytes, b.rawBytes});
        } else {
            continue;
        }
        local.dirty = true;
        lastRectAt = f.now;
        PixelRect screen;
        if (!b.full && f.snap->view.width > 1)
            screen = dirtyScreenRect(net::toCamera(f.snap->view), local.volume, b.box);
        model.addVolumeBox(b, screen, f.now);
    }
}

// The design that feeds this frame's picture, and the camera it is drawn with.
void TrainerWindow::choosePicture(FrameState& f) {
    f.picture = designs.picture; // for the rest of the frame
    const SyncDesign picture = f.picture;
    // Forces on the local copy only while it is the picture and no switch away is under way:
    // the server stops sending voxels at the request, so the copy would go stale.
    core.setLocalForces(picture == SyncDesign::Volume && designs.wanted == SyncDesign::Volume);
    f.havePicture = picture == SyncDesign::Volume ? local.have : haveImage;
    if (f.havePicture && firstPictureAt < 0)
        firstPictureAt = f.now;
    f.switching = designs.switching();
    // The DBI is drawn, and picked, with the camera it was rendered with: a new view's full
    // image can reach the textures before a snapshot names the view (tools drawn with the old
    // matrices over the new picture for a frame, a jitter while orbiting). The local volume is
    // drawn with the view the client holds now.
    const net::ViewSpec& shownView =
        picture == SyncDesign::Dbi && haveImage ? imageView : f.snap->view;
    f.viewMatches = shownView.width == viewSize && shownView.height == viewSize;
    f.dbiCamera = net::toCamera(shownView);
    if (picture == SyncDesign::Volume && !(local.camera == f.dbiCamera)) {
        local.dirty = true;        // a new view: the picture for picking must be read back again
        model.boxes.boxes.clear(); // the old view's rectangles (a DBI's go with its full image)
    }

    // The scripted toggle: flip at the next time, once the switch before it has completed.
    if (const auto due = script.switchDue(f.now, firstPictureAt, f.switching, designs.wanted))
        designs.request(*due, client);
}

// Tool: the script, or the mouse device on the bone under the cursor; the Session panel's last
// values (drawn below) kept within their ranges first.
void TrainerWindow::updateTool(FrameState& f) {
    toolControls = withinRanges(toolControls);
    if (scene && f.havePicture && script.drivesTool()) {
        const ScriptPose p = script.tool(scene->site, f.now);
        toolControls.kind = 0;
        toolPos = p.position;
        toolRot = glm::rotation(glm::vec3(0, 0, 1), p.axis);
        toolControls.drilling = p.drilling;
        toolValid = true;
        if (script.toolJustDone())
            lastRectAt = f.now; // the view settles from the script's end
    } else if (scene && f.havePicture && f.viewMatches) {
        mouseTool(f);
    }
    f.kind = toolControls.kind == 1 ? ToolKind::Perforator : ToolKind::Burr;
    f.diameter = f.kind == ToolKind::Perforator ? kPerforatorDiameterMm : toolControls.burrMm;
    {
        DeviceState ds;
        ds.pose.position = toolPos;
        ds.pose.orientation = toolRot;
        ds.buttons = toolControls.drilling ? 1u : 0u;
        ds.valid = toolValid && f.snap->state == net::LinkState::Connected;
        device.set(ds, {f.kind, f.diameter, toolControls.speed, toolControls.drilling}, f.now);
    }

    // The 1 kHz extrapolated force, straight from the haptic loop's recorder, on the
    // window's clock (the model folded the server's samples with the snapshot).
    model.setHapticTicks(core.hapticSamples(), f.now);
    f.hstats = core.hapticStats();
}

// The mouse device: keys pick the tool and its push, the pointer over the view places it on the
// bone under it.
void TrainerWindow::mouseTool(const FrameState& f) {
    ImGuiIO& io = ImGui::GetIO();
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
                          io.MousePos.x < float(viewSize) && io.MousePos.y < float(viewSize) &&
                          !io.WantCaptureMouse;
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
                    : ToolShape::burr(
                          std::clamp(toolControls.burrMm, kBurrMinDiameterMm, kBurrMaxDiameterMm));
            ToolPose pose = toolPoseAt(*hit, f.dbiCamera, shape, toolControls.pushMm);
            toolPos = pose.position;
            toolRot = pose.orientation;
            toolValid = true;
        }
    }
    toolControls.drilling =
        toolControls.canDrill && toolValid && overView && ImGui::IsMouseDown(ImGuiMouseButton_Left);
}

// Composite: pass 1 the DBI (or the ray cast of the local volume), pass 2 the anatomy and the
// tools with the same matrices and depth test, blitted top-left.
void TrainerWindow::composite(const FrameState& f) {
    if (!(f.havePicture && f.viewMatches))
        return;
    if (f.picture == SyncDesign::Volume) {
        comp.beginEmpty(f.dbiCamera);
        local.view.draw(f.dbiCamera);
        if (local.dirty) {
            // The picture's depth before the tools, for the cursor's depth lookups and
            // the marks' occlusion: read back only when the volume or the view changed,
            // and only the depth (the colour once, for the report, after the loop).
            comp.readBackDepth(cpuDbi);
            local.camera = cpuDbiCamera = f.dbiCamera;
            local.dirty = false;
        }
    } else {
        comp.begin(f.dbiCamera);
    }
    if (scene)
        comp.draw(fieldMesh, glm::mat4(1.0f));
    // A tool near a critical structure takes its zone's colour (the server's SafetyWarning).
    for (const auto& [id, t] : f.snap->others)
        comp.draw(tools.get(ToolKind(t.toolKind), t.diameterMm),
                  toolMatrix(t.position, t.orientation),
                  toolZoneColor(*f.snap, id).value_or(participantColor(int(id))));
    const uint16_t self = f.snap->welcome ? f.snap->welcome->clientId : 0;
    if (toolValid)
        comp.draw(tools.get(f.kind, f.diameter), toolMatrix(toolPos, toolRot),
                  toolZoneColor(*f.snap, self).value_or(participantColor(0)));
    comp.blitTo(0, window.height() - viewSize);
}

// Overlays in the view: labels, dirty boxes, connection state.
void TrainerWindow::drawOverlays(FrameState& f) {
    const net::ClientSnapshot& snap = *f.snap;
    const float viewTop = 0.0f;
    const ToolPose ownTool{toolPos, toolRot};
    if (f.havePicture && f.viewMatches) {
        drawViewLabels(snap, f.dbiCamera, cpuDbi, viewSize, toolValid ? &ownTool : nullptr,
                       o.name + (toolControls.drilling ? " (drilling)" : ""));
        drawDirtyBoxOverlay(boxState, model.boxes, f.now, 0.0f, viewTop, viewSize);
    }
    // A view larger than the server serves is refused by the client (the window waited for
    // its first image for good, the reason in one line of the Network panel).
    f.maxViewPixels = snap.welcome ? snap.welcome->maxViewPixels : 0;
    f.viewTooLarge = snap.state == net::LinkState::Connected && snap.welcome &&
                     int64_t(viewSize) * viewSize > f.maxViewPixels;
    std::string status;
    if (f.viewTooLarge)
        status = tooLargeText(f);
    else if (snap.state == net::LinkState::Connecting)
        status =
            "Connecting to " + o.address + " (attempt " + std::to_string(snap.attempts) + ")...";
    else if (snap.state == net::LinkState::Retrying)
        status = "Not connected: " + snap.closeReason + "\nRetrying...";
    else if (!sceneError.empty())
        status = "Cannot show the session: " + sceneError;
    else if (!f.havePicture)
        status = "Waiting for the first image of the skull...";
    else if (snap.waitingForView)
        status = "Waiting for the new view...";
    else if (f.switching)
        status = std::string("Switching to ") + syncDesignName(designs.wanted) +
                 ": waiting for its first full update...";
    drawViewMessage(status, f.havePicture, viewSize);
    // Taken over, or holding a trainee: said at the foot of the view, on a solid band.
    std::string held;
    if (f.heldByOther)
        held = participantName(snap.participants, f.heldByOther) +
               " has taken over: your drill is paused";
    else if (f.holding)
        held = "You hold " + participantName(snap.participants, f.holding) +
               ": your drill cuts, theirs is paused";
    drawHeldBand(held, viewSize);
    drawSafetyBanner(snap, viewSize);
}

std::string TrainerWindow::tooLargeText(const FrameState& f) const {
    return "The server serves views of at most " + std::to_string(f.maxViewPixels) +
           " pixels; this view is " + std::to_string(viewSize) + " x " + std::to_string(viewSize) +
           ": restart with " + o.sizeOption + " " +
           std::to_string(int(std::sqrt(double(f.maxViewPixels)))) + " or less";
}

// Panels: Forces under the view, and two columns right of it; and what their controls ask of
// the server.
void TrainerWindow::drawPanels(const FrameState& f) {
    const net::ClientSnapshot& snap = *f.snap;
    const SyncDesign picture = f.picture;
    const PanelLayout layout = panelLayout(viewSize, float(window.height()));
    placeNextPanel(layout.session);
    drawSessionPanel(snap, toolControls, markControls, takeOverControls, viewAsControls,
                     o.instructor ? "instructor" : "trainee", o.address, o.name);
    // Marks asked for (the panel, the M key, --mark once joined); the server lists them back.
    script.sendDue(snap, client);
    for (const net::Annotate& a : markRequests(markControls, markUndo, snap, pointerPick))
        client.annotate(a);
    // Take over (the panel's buttons, --take-over once the trainee is listed) or hand back.
    if (takeOverControls.asked)
        client.takeOver(*takeOverControls.asked);
    takeOverControls.asked.reset();
    // View as (the panel, --view-as once the participant is listed).
    if (scene && snap.welcome && snap.state == net::LinkState::Connected)
        if (const auto id =
                viewAsControls.due(snap.attempts, snap.welcome->clientId, snap.participants))
            client.viewAs(*id);
    if (viewAsControls.asked)
        client.viewAs(*viewAsControls.asked);
    viewAsControls.asked.reset();
    placeNextPanel(layout.view);
    drawViewPanel(viewControls, snap.waitingForView || !f.havePicture,
                  picture == SyncDesign::Volume ? "local render" : "DBI",
                  f.havePicture ? &f.dbiCamera : nullptr);
    placeNextPanel(layout.network);
    drawNetworkPanel(snap, model.network, f.now);
    placeNextPanel(layout.comparison);
    SyncDesign shown = designs.wanted;
    if (drawComparisonPanel(shown, picture, model.comparison, f.now) && shown != designs.wanted)
        designs.request(shown, client);
    if (ImGui::Begin("Comparison")) { // appends to the panel: what only the window knows
        // Short lines: the 400-pixel panel cut the longer ones off.
        ImGui::TextDisabled("frame ms: start to swap + glFinish, median of 1 s");
        ImGui::TextDisabled("volume GPU: full %.1f ms (%llu), box p50 %.2f ms (%llu)",
                            local.uploadMs.size() ? local.uploadMs.percentile(50) : 0.0,
                            (unsigned long long)local.uploads,
                            local.boxMs.size() ? local.boxMs.percentile(50) : 0.0,
                            (unsigned long long)local.boxUpdates);
        ImGui::TextDisabled("haptic ticks: %llu local volume, %llu server models",
                            (unsigned long long)core.localForceTicks(),
                            (unsigned long long)core.serverForceTicks());
    }
    ImGui::End();
    placeNextPanel(layout.forces);
    drawForcesPanel(model.forces, f.hstats.achievedRateHz, f.now,
                    o.instructor ? &model.participants : nullptr, &snap.participants);
    placeNextPanel(layout.dirtyBoxes);
    drawDirtyBoxPanel(boxState, model.boxes, f.now);
    placeNextPanel(layout.assessment);
    drawAssessmentPanel(snap);
}

// The frame's end: the scripted run's rules (a view too large ends it, a settled view is
// captured), the swap, and the frame's figures; false: the window ends.
bool TrainerWindow::endFrame(const FrameState& f) {
    const SyncDesign picture = f.picture;
    ScriptedDriver::Frame scripted;
    scripted.snap = f.snap.get();
    scripted.havePicture = f.havePicture;
    scripted.viewMatches = f.viewMatches;
    scripted.haveScene = scene.has_value();
    scripted.switching = f.switching;
    scripted.sinceLastUpdateS = f.now - lastRectAt;
    scripted.holding = f.holding;
    if (f.viewTooLarge)
        scripted.viewTooLarge = tooLargeText(f);
    if (script.abortsBeforeEnd(scripted)) {
        window.endFrame(nullptr);
        return false;
    }
    Dbi capture;
    window.endFrame(script.wantsCapture(scripted, f.now) ? &capture : nullptr);
    if (f.havePicture && f.viewMatches) {
        // The frame's time in the design it drew: from its start to the swap, waiting for
        // the GPU work (llvmpipe renders on glFinish); the pacing sleep is not included.
        glFinish();
        model.addFrame(picture,
                       std::chrono::duration<double, std::milli>(Clock::now() - f.start).count());
        ++framesPerDesign[int(picture)];
        const uint64_t drawnUs = net::steadyNowUs();
        for (const DrawnUpdate& u : drawnThisFrame)
            if (u.design == picture) // else in the textures, not on screen
                model.addDrawn(u.design, u.latencyUs, u.appliedUs, drawnUs, u.bytes, u.rawBytes);
    }
    drawnThisFrame.clear();
    // The Comparison panel's point for this second, for the design that fed the picture; the
    // other keeps its last figures. None while a switch is under way: the server has stopped
    // the old design's updates, so the second measures the wait.
    model.tickComparison(f.now, picture, f.havePicture && !f.switching, f.hstats.ticks);
    if (script.afterFrame(scripted, f.now, capture))
        return false;
    std::this_thread::sleep_until(f.start + std::chrono::milliseconds(10));
    return true;
}

// The report's figures, once the core has stopped.
void TrainerWindow::closingFigures() {
    if (o.report && designs.picture == SyncDesign::Volume && local.have &&
        cpuDbi.width() == local.camera.width && cpuDbi.height() == local.camera.height) {
        // The local volume's picture in colour, as last shown (the loop read back its depth).
        comp.beginEmpty(local.camera);
        local.view.draw(local.camera);
        cpuDbi = comp.readBack();
    }
    if (o.report) {
        TrainerReport& r = *o.report;
        r.comparison = model.comparison;
        r.picture = designs.picture;
        r.view = cpuDbi;
        // The camera `view` was made with (the snapshot's view is the placeholder once the
        // client has stopped, or another while a new view's image is on its way).
        r.camera = designs.picture == SyncDesign::Volume ? local.camera : cpuDbiCamera;
        r.switchesRequested = designs.requested;
        r.switchesCompleted = designs.completed;
        r.volumeUploads = local.uploads;
        r.volumeBoxUpdates = local.boxUpdates;
        r.localForceTicks = core.localForceTicks();
        r.serverForceTicks = core.serverForceTicks();
        r.frames = framesPerDesign;
        net::ClientReportExtras extras = core.reportExtras();
        extras.durationS = seconds();
        extras.session = {{"server", o.address},
                          {"codec", o.codec},
                          {"name", o.name},
                          {"sync", designs.picture == SyncDesign::Volume ? "volume" : "dbi"}};
        r.session = model.report(extras);
    }
}

} // namespace

int runTrainerWindow(const TrainerOptions& o) {
    if (o.sync != "dbi" && o.sync != "volume")
        throw Error("window: --sync must be dbi or volume, not '" + o.sync + "'");
    TrainerWindow window(o);
    return window.run();
}

} // namespace trephine::ui

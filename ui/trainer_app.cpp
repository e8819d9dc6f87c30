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
#include "ui/device_drive.h"
#include "ui/layout.h"
#include "ui/link_message.h"
#include "ui/mouse_tool.h"
#include "ui/panels.h"
#include "ui/scripted_driver.h"
#include "ui/shortcuts.h"
#include "ui/volume_view.h"
#include "ui/window.h"

#include <GLFW/glfw3.h>
#include <fmt/format.h>
#include <imgui.h>
#include <imgui_internal.h> // ClearActiveID: Enter or Escape leaves a text field

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <deque>
#include <functional>
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
constexpr int kBottomHeight = 400; // Forces, under the view
constexpr int kMinHeight = 760;
// Our mouse tool's opacity (MeshStyle).
constexpr float kOwnToolAlpha = 0.45f;
// Idle after this long without a change (idleFor); then a redraw at most this often.
constexpr double kIdleAfterS = 0.5, kIdleRedrawS = 0.5;
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
    net::ToolState toolAt(const ToolPose& pose, double) override { return m_device.toolAt(pose); }
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

// A held trainee's tool (paused by a take-over): drawn grey, its label says who holds it.
constexpr glm::vec4 kHeldToolColour{0.55f, 0.55f, 0.55f, 1.0f};

glm::vec4 toolColour(const net::ClientSnapshot& snap, uint16_t id) {
    return takenOverBy(snap.participants, id) ? kHeldToolColour
                                              : participantColor(snap.participants, id);
}

std::string heldSuffix(const net::ClientSnapshot& snap, uint16_t id) {
    const uint16_t holder = takenOverBy(snap.participants, id);
    return holder ? " (held by " + participantName(snap.participants, holder) + ")" : "";
}

// The view's labels (every tool's owner, ours last) and the instructors' marks, placed so they
// avoid each other and cut at the view's edge; `own` null: no tool of ours is shown.
void drawViewLabels(const net::ClientSnapshot& snap, const Camera& camera, const Dbi& cpuDbi,
                    glm::ivec2 viewSize, const ToolPose* own, const std::string& ownLabel) {
    ImDrawList* fg = ImGui::GetForegroundDrawList();
    const float viewTop = 0.0f;
    // Labels and marks belong to the view: one that projects outside it (orbited or
    // zoomed away) is cut at its edge, not drawn over the panels beside and under it.
    fg->PushClipRect(ImVec2(0.0f, viewTop), ImVec2(float(viewSize.x), viewTop + viewSize.y));
    const glm::dmat4 vp = viewProjection(camera);
    struct Label {
        std::string text;
        ImU32 colour;
    };
    std::vector<Label> labels;
    std::vector<LabelRequest> requests;
    const float textH = ImGui::GetFontSize();
    auto add = [&](ImVec2 anchor, ImU32 colour, const std::string& text) {
        labels.push_back({text, colour});
        requests.push_back({anchor.x, anchor.y, ImGui::CalcTextSize(text.c_str()).x, textH});
    };
    // The instructors' marks: a ring on the bone and its label; faint where the bone in this
    // view lies more than 2 mm in front of the mark (it is behind it). Placed first: a mark's
    // label stays beside its ring, tools' labels make way.
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
        const ImVec2 c(float(w.window.x), viewTop + float(viewSize.y - w.window.y));
        fg->AddCircle(c, 8.0f, IM_COL32(0, 0, 0, 160), 0, 4.5f);
        fg->AddCircle(c, 8.0f, markCol, 0, 2.5f);
        fg->AddCircleFilled(c, 2.5f, markCol);
        if (!a.label.empty())
            add(c, markCol, a.label);
    }
    auto toolLabel = [&](glm::vec3 p, glm::vec3 axis, glm::vec4 c, const std::string& text) {
        WindowPoint w = projectToWindow(vp, camera, glm::dvec3(p + axis * 40.0f));
        if (w.w > 0)
            add(ImVec2(float(w.window.x), viewTop + float(viewSize.y - w.window.y)),
                ImGui::GetColorU32(ImVec4(c.r, c.g, c.b, 1.0f)), text);
    };
    for (const auto& [id, t] : snap.others)
        toolLabel(t.position, t.orientation * glm::vec3(0, 0, 1), toolColour(snap, id),
                  participantName(snap.participants, id) + (t.drilling ? " (drilling)" : "") +
                      heldSuffix(snap, id));
    const uint16_t self = snap.welcome ? snap.welcome->clientId : 0;
    if (own)
        toolLabel(own->position, own->orientation * glm::vec3(0, 0, 1), toolColour(snap, self),
                  ownLabel + heldSuffix(snap, self));
    const std::vector<UiRect> at =
        placeLabels(requests, UiRect{0, viewTop, float(viewSize.x), float(viewSize.y)});
    for (size_t i = 0; i < labels.size(); ++i) {
        const UiRect& r = at[i];
        fg->AddRectFilled(ImVec2(r.x - 3, r.y - 2), ImVec2(r.x + r.w + 3, r.y + r.h + 2),
                          IM_COL32(0, 0, 0, 140), 3.0f);
        fg->AddText(ImVec2(r.x, r.y), labels[i].colour, labels[i].text.c_str());
    }
    fg->PopClipRect();
}

// A line about the link or the picture over the view (centred when no picture is shown).
void drawViewMessage(const std::string& status, bool havePicture, glm::ivec2 viewSize) {
    ImDrawList* fg = ImGui::GetForegroundDrawList();
    const float viewTop = 0.0f;
    if (!status.empty()) {
        ImVec2 sz = ImGui::CalcTextSize(status.c_str(), nullptr, false, viewSize.x - 40.0f);
        ImVec2 at((float(viewSize.x) - sz.x) * 0.5f,
                  havePicture ? 12.0f : viewTop + (float(viewSize.y) - sz.y) * 0.5f);
        fg->AddRectFilled(ImVec2(at.x - 10, at.y - 8), ImVec2(at.x + sz.x + 10, at.y + sz.y + 8),
                          IM_COL32(20, 20, 24, 210), 6.0f);
        fg->AddText(nullptr, 0.0f, at, IM_COL32(255, 200, 90, 255), status.c_str(), nullptr,
                    viewSize.x - 40.0f);
    }
}

// The hole under the pointer, top left in the view: its depth below the bone around it, what its
// floor shows, and the feed while the button is held.
void drawHoleReadout(const std::optional<HoleReading>& hole, bool feeding, float feedMmPerS) {
    std::string text = hole ? fmt::format("hole {:.1f} mm deep, floor: {}", hole->depthMm,
                                          holeFloorName(hole->floor))
                            : std::string("hole: no bone around to measure from");
    if (hole && hole->floor >= HoleFloor::Dura)
        text += " (through the inner table)";
    if (feeding)
        text += fmt::format("\nfeeding {:.1f} mm/s", feedMmPerS);
    ImDrawList* fg = ImGui::GetForegroundDrawList();
    const ImVec2 at(10.0f, 10.0f), sz = ImGui::CalcTextSize(text.c_str());
    fg->AddRectFilled(ImVec2(at.x - 6, at.y - 4), ImVec2(at.x + sz.x + 6, at.y + sz.y + 4),
                      IM_COL32(0, 0, 0, 150), 4.0f);
    fg->AddText(at, IM_COL32(235, 235, 235, 255), text.c_str());
}

// Taken over, or holding a trainee: said at the foot of the view, on a solid band.
void drawHeldBand(const std::string& held, glm::ivec2 viewSize) {
    ImDrawList* fg = ImGui::GetForegroundDrawList();
    const float viewTop = 0.0f;
    if (!held.empty()) {
        // Wrapped to the view: a small view (--window-size 300) shows the whole sentence.
        const float wrap = std::max(40.0f, float(viewSize.x) - 40.0f);
        const ImVec2 sz = ImGui::CalcTextSize(held.c_str(), nullptr, false, wrap);
        const ImVec2 at((float(viewSize.x) - sz.x) * 0.5f,
                        viewTop + float(viewSize.y) - sz.y - 18.0f);
        fg->AddRectFilled(ImVec2(at.x - 12, at.y - 8), ImVec2(at.x + sz.x + 12, at.y + sz.y + 8),
                          kTakeOverBand, 6.0f);
        fg->AddText(nullptr, 0.0f, at, IM_COL32(255, 255, 255, 255), held.c_str(), nullptr, wrap);
    }
}

// Where each panel goes: laid out again whenever the window's size, the view's or the full-view
// toggle changes (panels stay movable in between), so none is cut off by a smaller window.
void placeNextPanel(const UiRect& b, bool relayout) {
    const ImGuiCond cond = relayout ? ImGuiCond_Always : ImGuiCond_FirstUseEver;
    ImGui::SetNextWindowPos(ImVec2(b.x, b.y), cond);
    ImGui::SetNextWindowSize(ImVec2(b.w, b.h), cond);
}

// The view's size in a window of `window` pixels: what the panels' columns on the right
// (panelsWidth) and Forces under the view leave (at least 64 x 64); the whole window in the
// full-window view.
glm::ivec2 viewAreaFor(glm::ivec2 window, bool fullView) {
    const int columns = int(panelsWidth(window.x, fullView));
    return glm::max(glm::ivec2(window.x - columns, fullView ? window.y : window.y - kBottomHeight),
                    glm::ivec2(64));
}

// The window's trainee core: the client asks for a 1x1 placeholder view until the scene is
// known, and hands voxel boxes over for the GPU rather than rendering them itself.
net::TraineeCoreConfig coreConfigFor(const TrainerOptions& o, std::function<void()> onNews) {
    net::TraineeCoreConfig coreConfig;
    coreConfig.client.onNews = std::move(onNews);
    net::ClientThreadConfig& cc = coreConfig.client;
    cc.address = o.address;
    cc.client.name = o.name;
    cc.client.code = o.code;
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
    wc.width =
        o.windowWidth > 0 ? o.windowWidth : o.size + int(kPanelColumnWidth + kSideColumnWidth);
    wc.height = o.windowHeight > 0 ? o.windowHeight : std::max(o.size + kBottomHeight, kMinHeight);
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
        std::printf(
            "window: %s: %.1f updates/s, %.0f bytes/update (raw %.0f), update latency p50 %.2f "
            "ms p99 %.2f ms, frame %.2f ms, haptics %.0f Hz\n",
            syncDesignName(d), f.updatesPerS, f.bytesPerUpdate, f.rawBytesPerUpdate, f.latencyP50Ms,
            f.latencyP99Ms, f.frameMs, f.hapticHz);
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
    Camera dbiCamera;    // the camera the picture is drawn with
    Camera imageCamera;  // [DBI] the camera the held image was rendered (and is picked) with
    bool warped = false; // [DBI] drawn warped from imageCamera to dbiCamera (a view on its way)
    ToolKind kind = ToolKind::Burr;
    float diameter = 0.0f;
    HapticLoopStats hstats;
    std::string viewNotServed; // why the server does not serve this view ("" when it does)
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
    void fitViewToWindow(const FrameState& f);
    void requestWantedView();
    void requestResizedView(const FrameState& f);
    void takeScene(const FrameState& f);
    void requestMovedView(const FrameState& f);
    void applyRects(const FrameState& f);
    void applyVolumeBoxes(const FrameState& f);
    void choosePicture(FrameState& f);
    void aimWarp(FrameState& f) const;
    void updateTool(FrameState& f);
    void mouseTool(const FrameState& f);
    void viewGestures(const InjectedInput& in, glm::vec2 delta);
    void composite(const FrameState& f);
    void drawOverlays(FrameState& f);
    void drawPanels(const FrameState& f);
    void drawComparisonExtras();
    void drawFrameRate(double now);
    bool endFrame(const FrameState& f);
    double idleFor(const FrameState& f);
    void closingFigures();

    const TrainerOptions& o;
    glm::ivec2 viewSize;         // the view's (and the DBI's) width and height
    glm::ivec2 windowSize{0};    // the window's size the view was last fitted to (0: not yet)
    bool fittedFullView = false; // ... and whether it was the full-window view
    // A resize within kResizeSettleS of the last waits to be asked for until the size holds that
    // long: a window's edge dragged would otherwise ask the server for a new view every frame.
    static constexpr double kResizeSettleS = 0.1;
    double lastResizeAt = -1e9;
    bool resizePending = false; // a size not yet asked for

    // The scripted driver (--script, --mark, --take-over, --screenshot, --frames, ...) and the
    // Session panel's controls.
    ScriptedDriver script;
    MarkControls markControls;
    MarkUndo markUndo; // the last removal of marks, for the Session panel's undo
    TakeOverControls takeOverControls;
    ViewAsControls viewAsControls;
    ReplayControls replayControls;        // a served log's timeline (drawn only for one)
    std::optional<glm::vec3> pointerPick; // the bone under the pointer, last seen over the view

    // GL: the window and what draws into it.
    Window window;
    Compositor comp;
    LocalVolume local; // the replicated-volume design's picture
    ToolMeshCache tools{&comp, {}};
    GpuMesh fieldMesh;

    // Connection: the trainee core and the device its haptic loop reads.
    std::atomic<bool> news{false}; // the client thread has something new to show (onNews)
    const net::TraineeCoreConfig coreConfig;
    WindowDevice device;
    WindowTools windowTools{device};
    DeviceDrive drive{o.device, o.pedalMap, device}; // --device and --pedal-map (device_drive.h)
    net::TraineeCore core{coreConfig};
    net::ClientThread& client = core.client();
    StopCore stopCore{started(core, drive.tools() ? *drive.tools() : windowTools)};

    // Scene and camera.
    std::optional<Scene> scene;
    std::optional<uint64_t> sceneSeen; // the id of the last scene taken (or refused)
    std::string sceneError;            // the scene lacks what the options ask for (a preset)
    Camera baseCamera;                 // the view before orbiting
    ViewControls viewControls;
    Camera wantedCamera;

    // Panels' controls and the model behind them.
    ToolControls toolControls;
    WindowToggles toggles;           // F1's overlay, H's full-window view
    ViewNote note;                   // a key's feedback over the view
    KeyActions frameKeys;            // what this frame's key presses asked for
    size_t tapsDone = 0;             // [Tests] of TrainerOptions::tapKeys
    std::array<int, 5> laidOutFor{}; // window w, h, view w, h, full view: the panels' layout
    int attemptsWhenConnected = -1;  // the link's attempts when last up (-1: never)
    int fpsFrames = 0;               // frames since fpsSince
    double fpsSince = 0.0, fps = 0.0;
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
    Feed feed;                       // the held button's stroke
    glm::vec3 hapticForce{0.0f};     // the force the haptic loop output last (the bone's answer)
    float feedRateMmPerS = 0.0f;     // this frame's feed
    std::optional<HoleReading> hole; // the hole under the pointer, for the view's readout
    double lastToolAt = -1.0;        // the last frame's time, for the feed's step
    InjectedInput inputWas;          // the last frame's pointer: clicks and drags
    InjectedInput injected;          // [Tests] this frame's TrainerOptions::input
    double lastRectAt = 0.0;
    double lastActiveAt = 0.0; // idleFor's last activity
    const Clock::time_point t0 = Clock::now();
};

// --view-as is checked after the script's options and before a window opens.
WindowConfig TrainerWindow::checkedWindowConfig(const TrainerOptions& o) {
    if (!o.viewAs.empty() && !o.instructor)
        throw Error("window: --view-as: only an instructor views as another participant");
    return windowConfigFor(o);
}

TrainerWindow::TrainerWindow(const TrainerOptions& options)
    : o(options), viewSize(options.size, options.size), script(options),
      window(checkedWindowConfig(options)), coreConfig(coreConfigFor(options, [this] {
          news = true;
          Window::wake();
      })) {
    markControls.canMark = o.instructor;
    takeOverControls.canTakeOver = o.instructor;
    viewAsControls.canViewAs = o.instructor;
    viewAsControls.scripted = o.viewAs;
    // A scripted screenshot is the same whatever the pointer of the display happens to hover (no
    // tooltip or highlighted panel from it).
    if (script.ignoresPointer())
        ImGui::GetIO().ConfigFlags |= ImGuiConfigFlags_NoMouse;
    comp.resize(viewSize.x, viewSize.y);
    viewControls.distanceMm = o.distanceMm;
    viewControls.yawDeg = o.orbitDeg;
    viewControls.pitchDeg = o.tiltDeg;
    toolControls.canDrill = !o.instructor;
    designs.picture = designs.wanted = designOf(coreConfig.client.client.sync);
}

Camera TrainerWindow::makeCamera() const {
    return orbitCamera(baseCamera, viewControls.yawDeg, viewControls.pitchDeg,
                       viewControls.distanceMm, viewSize, scene->boundingRadiusMm);
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
    if (o.input) { // a test's hands, once a frame
        injected = o.input(firstPictureAt < 0.0 ? -1.0 : f.now - firstPictureAt);
        if (injected.windowWidth > 0 && injected.windowHeight > 0)
            window.resize(injected.windowWidth, injected.windowHeight);
    }
    takeSnapshot(f);
    fitViewToWindow(f);
    takeScene(f);
    applyRects(f);
    applyVolumeBoxes(f);
    choosePicture(f);
    if (f.havePicture && tapsDone < o.tapKeys.size()) { // [Tests] a tap inside one frame
        window.injectKey(o.tapKeys[tapsDone], GLFW_PRESS);
        window.injectKey(o.tapKeys[tapsDone++], GLFW_RELEASE);
    }
    // The frame begins (events polled, ImGui's new frame) before the tool reads the input:
    // ImGui 1.86 zeroes io.MouseWheel at the end of each frame, so read before NewFrame the
    // wheel was always 0, and keys came a frame late.
    window.beginFrame();
    updateTool(f);
    requestMovedView(f);
    aimWarp(f); // a gesture may have moved the camera: this frame draws it
    composite(f);
    drawOverlays(f);
    drawPanels(f);
    return endFrame(f);
}

// A resized window (seen by the last frame's events): the view takes the area the panels leave,
// and the server is asked for a DBI of its new size; until it comes the old picture is drawn
// warped (scaled) into the new view. The window opens fitted to --size, so the first size seen is
// kept.
void TrainerWindow::fitViewToWindow(const FrameState& f) {
    const double now = f.now;
    const glm::ivec2 size(window.width(), window.height());
    if ((size == windowSize && toggles.fullView == fittedFullView) || size.x <= 0 || size.y <= 0) {
        // Unchanged, or minimised: keep the view; a dragged size that has held is asked for.
        if (resizePending && now - lastResizeAt >= kResizeSettleS && scene)
            requestResizedView(f);
        return;
    }
    const bool first = windowSize == glm::ivec2(0);
    windowSize = size;
    fittedFullView = toggles.fullView;
    if (first)
        return;
    const glm::ivec2 view = viewAreaFor(size, toggles.fullView);
    if (view == viewSize)
        return;
    viewSize = view;
    comp.resizeView(view.x, view.y); // the DBI held stays, and its rectangles still fit it
    // The first change goes at once (a maximised window, H's full view); the frames of a drag
    // draw the held picture scaled until the size holds. The volume design's picture is drawn
    // here, and its view goes at once: the server renders nothing for it.
    const bool settled =
        designs.picture == SyncDesign::Volume || now - lastResizeAt >= kResizeSettleS;
    lastResizeAt = now;
    if (!scene)
        return;
    if (settled) {
        requestResizedView(f);
    } else {
        wantedCamera = makeCamera(); // drawn (warped) until it is asked for
        resizePending = true;
    }
}

// A resize keeps what is viewed: our own camera, or, viewing as a participant, theirs, at the new
// size (as the client asks for a participant's view that moves).
void TrainerWindow::requestResizedView(const FrameState& f) {
    if (f.snap->viewingAs == 0) {
        requestWantedView();
        return;
    }
    resizePending = false;
    net::ViewSpec v = f.snap->view;
    v.width = uint16_t(viewSize.x);
    v.height = uint16_t(viewSize.y);
    client.requestView(v);
}

void TrainerWindow::requestWantedView() {
    resizePending = false;
    wantedCamera = makeCamera();
    client.requestView(net::toViewSpec(wantedCamera));
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
    // Nobody drills a replay: the server cuts only what the log holds.
    toolControls.canDrill = !snap.replay && (o.instructor ? f.holding != 0 : f.heldByOther == 0);
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
                                     viewSize, scene->boundingRadiusMm);
        else
            preset = net::presetCamera(scene->received->scene, o.camera, viewSize);
        if (preset) {
            baseCamera = *preset;
            viewControls.distanceMm = glm::length(baseCamera.eye - baseCamera.target);
            viewControls.setHome(); // --orbit, --tilt and this distance
            requestWantedView();
        } else {
            sceneError = "the server's scene has no camera preset '" + o.camera + "'";
            scene.reset();
        }
    }
    requestMovedView(f);
}

// The View panel (last frame) or a gesture (this frame) moved the camera: the server is asked for
// the new view, and this frame already draws the held DBI warped to it.
void TrainerWindow::requestMovedView(const FrameState& f) {
    if (scene && viewControls.dirty) {
        viewControls.dirty = false;
        if (f.snap->viewingAs != 0) // the View panel moved: our own camera again
            client.viewAs(0);
        requestWantedView();
    }
}

// Applied rectangles: only their pixels are uploaded. A full image newer than the last whole
// volume makes the DBI the picture again (a switch back has completed).
void TrainerWindow::applyRects(const FrameState& f) {
    for (net::AppliedRect& r : client.drainRects()) {
        const std::optional<net::HeldPicture> held =
            haveImage
                ? std::optional(net::HeldPicture{imageViewId, {imageView.width, imageView.height}})
                : std::nullopt;
        const net::PicturePart part = net::picturePart(r, viewSize, held);
        if (part == net::PicturePart::Whole) {
            if (local.have && r.appliedUs < designs.pictureSinceUs)
                continue; // older than the volume that replaced the DBI
            comp.uploadFull(r.pixels);
            haveImage = true;
            imageViewId = r.viewId;
            imageView = r.view;
            designs.arrived(SyncDesign::Dbi, r.appliedUs);
            cpuDbi = std::move(r.pixels);
            cpuDbiCamera = net::toCamera(r.view);
            if (o.onPicture)
                o.onPicture(cpuDbiCamera);
        } else if (part == net::PicturePart::Rect) {
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
    // The DBI is picked with the camera it was rendered with (a new view's full image can reach
    // the textures before a snapshot names the view), and drawn with it or warped (aimWarp). The
    // local volume is drawn with the view the client holds now.
    const net::ViewSpec& shownView =
        picture == SyncDesign::Dbi && haveImage ? imageView : f.snap->view;
    f.viewMatches = shownView.width == viewSize.x && shownView.height == viewSize.y;
    f.dbiCamera = f.imageCamera = net::toCamera(shownView);
    aimWarp(f);
    if (picture == SyncDesign::Volume && !(local.camera == f.dbiCamera)) {
        local.dirty = true;        // a new view: the picture for picking must be read back again
        model.boxes.boxes.clear(); // the old view's rectangles (a DBI's go with its full image)
    }

    // The scripted toggle: flip at the next time, once the switch before it has completed.
    if (const auto due = script.switchDue(f.now, firstPictureAt, f.switching, designs.wanted))
        designs.request(*due, client);
}

// [DBI] While a new view is on its way, or after a resize, the held image is drawn warped to the
// camera the window has now: ours, or (viewing as someone) the image's own at this view's size.
void TrainerWindow::aimWarp(FrameState& f) const {
    f.warped = false;
    if (f.picture != SyncDesign::Dbi || !haveImage)
        return;
    Camera target = f.imageCamera;
    if (scene && f.snap->viewingAs == 0)
        target = wantedCamera;
    target.width = viewSize.x;
    target.height = viewSize.y;
    f.warped = !(target == f.imageCamera);
    f.dbiCamera = target;
}

// Tool: the script, or the mouse device on the bone under the cursor; the Session panel's last
// values (drawn below) kept within their ranges first.
void TrainerWindow::updateTool(FrameState& f) {
    toolControls = withinRanges(toolControls);
    {
        const ImGuiIO& io = ImGui::GetIO();
        frameKeys = applyKeys(window.keyPresses(), io.WantTextInput, markControls.labelActive,
                              io.WantCaptureKeyboard && !io.WantTextInput, toolControls, toggles);
        if (frameKeys.leaveTextField)
            ImGui::ClearActiveID();
    }
    const std::vector<HapticSample> ticks = core.hapticSamples();
    hapticForce = ticks.empty() ? glm::vec3(0.0f) : ticks.back().force;
    if (scene && f.havePicture && script.drivesTool()) {
        const net::ScriptPose p = script.tool(scene->site, f.now);
        toolControls.kind = int(ToolKind::Burr); // the script's burr, as in every shell
        toolControls.diameter(ToolKind::Burr) = net::kBurrholeDiameterMm;
        toolPos = p.position;
        toolRot = glm::rotation(glm::vec3(0, 0, 1), p.axis);
        toolControls.drilling = p.drilling;
        toolValid = true;
        if (script.toolJustDone())
            lastRectAt = f.now; // the view settles from the script's end
    } else if (scene && f.havePicture && drive.drivesTool()) {
        const ToolShape shape =
            ToolShape::of(selectedKind(toolControls), selectedDiameter(toolControls));
        const auto pose = drive.frame(homePose(scene->site, shape, feed.config().liftMm),
                                      f.dbiCamera, toolControls);
        toolValid = pose.has_value();
        if (pose) {
            toolPos = pose->position;
            toolRot = pose->orientation;
        }
    } else if (scene && f.havePicture && f.viewMatches) {
        drive.pedalOnly(toolControls);
        mouseTool(f);
    }
    f.kind = selectedKind(toolControls);
    f.diameter = selectedDiameter(toolControls);
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
    model.setHapticTicks(ticks, f.now);
    f.hstats = core.hapticStats();
}

// The mouse device: keys pick the tool and its push; over the view the pointer shows the bone
// under it with the handpiece lifted clear along the surface's normal, the held left button feeds
// the cutter in (Feed), a right drag orbits and Ctrl or Shift with the wheel zooms.
void TrainerWindow::mouseTool(const FrameState& f) {
    ImGuiIO& io = ImGui::GetIO();
    // Keys from the window's queue (a tap inside one frame counts). M marks the bone under the
    // pointer now: over air or off the view it marks nothing, and says so.
    const KeyActions& keys = frameKeys;
    const bool markKey = markControls.canMark && keys.markAtPointer;
    if (keys.labelledMark) {
        if (pointerPick)
            markControls.addAtPointer = true;
        else
            note.show("Enter: point at the bone in the view first, then press M", f.now);
    }
    // The mouse, or what a test drives in its place.
    InjectedInput in;
    if (o.input) {
        in = injected;
    } else {
        in = {io.MousePos.x,
              io.MousePos.y,
              ImGui::IsMouseDown(ImGuiMouseButton_Left),
              ImGui::IsMouseDown(ImGuiMouseButton_Right),
              io.MouseWheel,
              io.KeyCtrl || io.KeyShift};
    }
    const bool clicked = in.left && !inputWas.left;
    const glm::vec2 delta = inputWas.x >= 0.0f && in.x >= 0.0f
                                ? glm::vec2(in.x - inputWas.x, in.y - inputWas.y)
                                : glm::vec2(0.0f);
    inputWas = in;
    const bool overView = in.x >= 0 && in.y >= 0 && in.x < float(viewSize.x) &&
                          in.y < float(viewSize.y) && (o.input || !io.WantCaptureMouse);
    const float dt = lastToolAt < 0.0 ? 0.0f : float(std::min(f.now - lastToolAt, 0.05));
    lastToolAt = f.now;
    if (overView)
        viewGestures(in, delta);
    const ToolShape shape =
        ToolShape::of(selectedKind(toolControls), selectedDiameter(toolControls));
    const int px = int(in.x), py = viewSize.y - 1 - int(in.y);
    // Unprojected with the camera cpuDbi was made with: in volume mode its depth is read back
    // after this pick, so for one frame after a view change (or a switch from DBI) it is still
    // the old picture's, which the new camera would turn into a point off the bone.
    std::optional<glm::vec3> hit;
    glm::vec3 axis(0.0f);
    const float ringMm = 0.5f * shape.diameterMm + 2.0f; // the bone around a hole the cutter cut
    hole.reset();
    // While the picture is drawn warped, the bone under the pointer is not where cpuDbi says: the
    // pick waits one round trip for the exact picture rather than land the tool off the bone.
    if (overView && !f.warped)
        hit = pickSurface(cpuDbi, cpuDbiCamera, px, py);
    if (hit) {
        pointerPick = *hit;
        markControls.addAtPointer = markControls.addAtPointer || markKey;
        // The normal of the bone beyond a cutter's hole around the point (the ring readHole
        // measures from), so neither one voxel's step nor the hole's own walls tilt the
        // handpiece.
        const float mmPerPx = 2.0f * glm::length(cpuDbiCamera.eye - *hit) *
                              std::tan(glm::radians(cpuDbiCamera.fovYDeg) * 0.5f) /
                              float(std::max(1, cpuDbiCamera.height));
        const int radiusPx = int(std::ceil(ringMm / mmPerPx));
        axis = surfaceNormal(cpuDbi, cpuDbiCamera, px, py, radiusPx)
                   .value_or(glm::normalize(cpuDbiCamera.eye - *hit));
        hole = readHole(cpuDbi, cpuDbiCamera, {px, py}, feed.held() ? feed.axis() : axis, ringMm);
    }
    if (!in.left || !toolControls.canDrill)
        feed.release();
    else if (!feed.held() && hit && clicked)
        feed.press(*hit, axis, toolControls.pushMm);
    if (feed.held()) {
        // The pointer moved: the stroke follows it across the axis (where the pointer's ray
        // meets the plane of the first contact), not to the picked floor of its own hole.
        if (overView && (delta.x != 0.0f || delta.y != 0.0f))
            if (const auto p = rayOnPlane(cpuDbiCamera, px, py, feed.surface(), feed.axis()))
                feed.slideTo(*p);
        const float vmax =
            maxFeedMmPerS(shape.kind, toolControls.speed, scene->received->scene.spacing);
        feedRateMmPerS = feed.advance(dt, hapticForce, vmax);
        const ToolPose pose = toolPoseAlong(feed.surface(), feed.axis(), shape, feed.depthMm());
        toolPos = pose.position;
        toolRot = pose.orientation;
        toolValid = true;
    } else {
        feedRateMmPerS = 0.0f;
        if (hit) { // lifted clear of the bone around the pointer (a hole's rim), along its normal
            const float lift = feed.config().liftMm + (hole ? hole->depthMm : 0.0f);
            const ToolPose pose = toolPoseAlong(*hit, axis, shape, -lift);
            toolPos = pose.position;
            toolRot = pose.orientation;
            toolValid = true;
        }
    }
    if (markKey && !hit)
        note.show(overView ? "M: no bone under the pointer, nothing marked"
                           : "M: point at the bone in the view, then press M",
                  f.now);
    toolControls.drilling = toolControls.canDrill && toolValid && feed.held();
}

// Gestures in the view: a right drag orbits, Ctrl or Shift with the wheel zooms, the plain wheel
// sets the depth a stroke starts at (as the Session panel's push).
void TrainerWindow::viewGestures(const InjectedInput& in, glm::vec2 delta) {
    if (in.wheel != 0.0f) {
        if (in.zoomKey) {
            viewControls.distanceMm = std::clamp(viewControls.distanceMm * std::pow(0.9f, in.wheel),
                                                 kViewMinDistanceMm, kViewMaxDistanceMm);
            viewControls.dirty = true;
        } else {
            toolControls.pushMm = steppedPush(toolControls.pushMm, in.wheel);
        }
    }
    if (in.right && (delta.x != 0.0f || delta.y != 0.0f)) {
        viewControls.yawDeg = std::clamp(viewControls.yawDeg - delta.x * kOrbitDegPerPx,
                                         kViewMinYawDeg, kViewMaxYawDeg);
        viewControls.pitchDeg = std::clamp(viewControls.pitchDeg + delta.y * kOrbitDegPerPx,
                                           kViewMinPitchDeg, kViewMaxPitchDeg);
        viewControls.dirty = true;
    }
}

// Composite: pass 1 the DBI (or the ray cast of the local volume), pass 2 the anatomy and the
// tools with the same matrices and depth test, blitted top-left.
void TrainerWindow::composite(const FrameState& f) {
    if (!(f.havePicture && (f.viewMatches || f.warped)))
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
            if (o.onPicture)
                o.onPicture(cpuDbiCamera);
        }
    } else if (f.warped) {
        comp.beginWarped(f.imageCamera, f.dbiCamera);
    } else {
        comp.begin(f.dbiCamera);
    }
    if (scene)
        comp.draw(fieldMesh, glm::mat4(1.0f));
    // A tool near a critical structure takes its zone's colour (the server's SafetyWarning).
    for (const auto& [id, t] : f.snap->others)
        comp.draw(tools.get(ToolKind(t.toolKind), t.diameterMm),
                  toolMatrix(t.position, t.orientation),
                  toolZoneColor(*f.snap, id).value_or(toolColour(*f.snap, id)));
    const uint16_t self = f.snap->welcome ? f.snap->welcome->clientId : 0;
    // Ours, placed by the mouse, is translucent: it always sits over the cut it makes.
    if (toolValid)
        comp.draw(tools.get(f.kind, f.diameter), toolMatrix(toolPos, toolRot),
                  toolZoneColor(*f.snap, self).value_or(toolColour(*f.snap, self)),
                  MeshStyle{script.drivesTool() ? 1.0f : kOwnToolAlpha});
    if (o.onComposite)
        o.onComposite(comp.readBack(), f.dbiCamera);
    comp.blitTo(0, window.height() - viewSize.y);
}

// Overlays in the view: labels, dirty boxes, connection state.
void TrainerWindow::drawOverlays(FrameState& f) {
    const net::ClientSnapshot& snap = *f.snap;
    const float viewTop = 0.0f;
    const ToolPose ownTool{toolPos, toolRot};
    if (f.havePicture && (f.viewMatches || f.warped)) {
        drawViewLabels(snap, f.dbiCamera, cpuDbi, viewSize, toolValid ? &ownTool : nullptr,
                       o.name + (toolControls.drilling ? " (drilling)" : ""));
        drawDirtyBoxOverlay(boxState, model.boxes, f.now, 0.0f, viewTop, viewSize.y);
        if (hole || feed.held())
            drawHoleReadout(hole, feed.held(), feedRateMmPerS);
    }
    f.viewNotServed = net::viewNotServedText(snap, viewSize.x, viewSize.y, o.sizeOption);
    if (snap.state == net::LinkState::Connected)
        attemptsWhenConnected = snap.attempts;
    const LinkMessage link = linkMessage(snap.state, snap.attempts, attemptsWhenConnected,
                                         snap.closeReason, o.address, f.havePicture);
    if (link.dim) // the picture is stale: dimmed under the message, the panels not
        ImGui::GetBackgroundDrawList()->AddRectFilled(
            ImVec2(0, viewTop), ImVec2(float(viewSize.x), viewTop + float(viewSize.y)),
            IM_COL32(0, 0, 0, 150));
    std::string status;
    if (!f.viewNotServed.empty())
        status = f.viewNotServed;
    else if (!link.text.empty())
        status = link.text;
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
    note.draw(f.now, 0.0f, viewTop, float(viewSize.x));
    drawFrameRate(f.now);
    drawSafetyBanner(snap, viewSize.x);
}

// Panels: Forces under the view, and two columns right of it; and what their controls ask of
// the server.
void TrainerWindow::drawPanels(const FrameState& f) {
    const net::ClientSnapshot& snap = *f.snap;
    const SyncDesign picture = f.picture;
    const WindowLayout layout =
        windowLayout(window.width(), window.height(), viewSize.x, viewSize.y, toggles.fullView);
    const std::array<int, 5> shape{window.width(), window.height(), viewSize.x, viewSize.y,
                                   int(toggles.fullView)};
    const bool relayout = shape != laidOutFor;
    laidOutFor = shape;
    // The full-window view draws no panel; what their controls asked for still goes out.
    const bool show = layout.panels;
    const PanelLayout& box = layout.boxes;
    if (show) {
        placeNextPanel(box.session, relayout);
        drawSessionPanel(snap, toolControls, markControls, takeOverControls, viewAsControls,
                         o.instructor ? "instructor" : "trainee", o.address, o.name);
    }
    // Marks asked for (the panel, the M key, --mark once joined); the server lists them back.
    script.sendDue(snap, client);
    for (const net::Annotate& a : markRequests(markControls, markUndo, snap, pointerPick))
        client.annotate(a);
    // Take over (the panel's buttons, --take-over once the trainee is listed) or hand back.
    if (takeOverControls.asked)
        client.takeOver(*takeOverControls.asked);
    takeOverControls.asked.reset();
    if (takeOverControls.remove)
        client.remove(*takeOverControls.remove);
    takeOverControls.remove.reset();
    if (takeOverControls.newCode)
        client.newCode(*takeOverControls.newCode);
    takeOverControls.newCode.reset();
    for (net::ClientRequest& r : std::exchange(takeOverControls.requests, {}))
        client.send(std::move(r));
    // View as (the panel, --view-as once the participant is listed).
    if (scene && snap.welcome && snap.state == net::LinkState::Connected)
        if (const auto id =
                viewAsControls.due(snap.attempts, snap.welcome->clientId, snap.participants))
            client.viewAs(*id);
    if (viewAsControls.asked)
        client.viewAs(*viewAsControls.asked);
    viewAsControls.asked.reset();
    if (show) {
        placeNextPanel(box.view, relayout);
        drawViewPanel(viewControls, snap.waitingForView || !f.havePicture,
                      picture == SyncDesign::Volume ? "local render" : "DBI",
                      f.havePicture ? &f.dbiCamera : nullptr);
        placeNextPanel(box.network, relayout);
        drawNetworkPanel(snap, model.network, f.now);
        placeNextPanel(box.comparison, relayout);
        SyncDesign shown = designs.wanted;
        if (drawComparisonPanel(shown, picture, model.comparison, f.now) && shown != designs.wanted)
            designs.request(shown, client);
        drawComparisonExtras();
        placeNextPanel(box.forces, relayout);
        drawForcesPanel(model.forces, f.hstats.achievedRateHz, f.now,
                        o.instructor ? &model.participants : nullptr, &snap.participants);
        placeNextPanel(box.dirtyBoxes, relayout);
        drawDirtyBoxPanel(boxState, model.boxes, f.now);
        placeNextPanel(box.assessment, relayout);
        drawAssessmentPanel(snap);
    }
    // A replay's timeline over the view's bottom, in the full-window view too.
    if (snap.replay && snap.state == net::LinkState::Connected) {
        const uint64_t positionUs = net::replayPositionAfter(
            *snap.replay, net::steadyNowUs() - std::min(net::steadyNowUs(), snap.publishedUs));
        replayControls.keys(frameKeys.playPause, frameKeys.replaySteps, *snap.replay, positionUs);
        drawReplayTimeline(*snap.replay, positionUs, replayControls, layout.view);
        for (const net::ReplayControl& c : replayControls.asked)
            client.controlReplay(c);
    }
    replayControls.asked.clear();
    drawShortcutOverlay(toggles);
}

// Frames drawn per second, counted over each second, in the view's top right corner (where a
// game's readout sits): "-" until a second has passed.
void TrainerWindow::drawFrameRate(double now) {
    ++fpsFrames;
    if (now - fpsSince >= 1.0) {
        fps = double(fpsFrames) / (now - fpsSince);
        fpsFrames = 0;
        fpsSince = now;
    }
    char text[32];
    if (fps > 0)
        std::snprintf(text, sizeof text, "%.0f fps", fps);
    else
        std::snprintf(text, sizeof text, "- fps");
    ImDrawList* fg = ImGui::GetForegroundDrawList();
    const ImVec2 sz = ImGui::CalcTextSize(text);
    const ImVec2 at(float(viewSize.x) - sz.x - 8.0f, 6.0f);
    fg->AddRectFilled(ImVec2(at.x - 4, at.y - 2), ImVec2(at.x + sz.x + 4, at.y + sz.y + 2),
                      IM_COL32(0, 0, 0, 140), 3.0f);
    fg->AddText(at, IM_COL32(200, 220, 200, 255), text);
}

// What only the window knows, appended to the Comparison panel.
void TrainerWindow::drawComparisonExtras() {
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
    scripted.pointerBusy = o.input && !injected.done;
    scripted.viewNotServed = f.viewNotServed;
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
    // Idle (nothing new for a while, no input, nothing moving): wait for an event, or for the
    // client thread's wake-up when something new arrives, redrawing a few times a second only;
    // else about 100 frames a second.
    if (idleFor(f) >= kIdleAfterS)
        window.waitEvents(kIdleRedrawS);
    else
        std::this_thread::sleep_until(f.start + std::chrono::milliseconds(10));
    return true;
}

// Seconds since anything changed that a frame shows: input, an update, a snapshot with news, the
// tool feeding or scripted, a view or a design on its way. Scripted runs (screenshots, frame
// counts) are never idle, so their timing stays as it was.
double TrainerWindow::idleFor(const FrameState& f) {
    const ImGuiIO& io = ImGui::GetIO();
    bool input = io.MouseDelta.x != 0.0f || io.MouseDelta.y != 0.0f || io.MouseWheel != 0.0f ||
                 io.MouseWheelH != 0.0f || !io.InputQueueCharacters.empty();
    for (bool down : io.MouseDown)
        input |= down;
    for (bool down : io.KeysDown)
        input |= down;
    const bool busy = news.exchange(false) || input || lastRectAt == f.now || feed.held() ||
                      script.drivesTool() || viewControls.dirty || (resizePending && scene) ||
                      f.snap->waitingForView || (f.snap->replay && f.snap->replay->playing) ||
                      replayControls.dragS || f.switching || !f.havePicture || o.frames > 0 ||
                      !o.screenshot.empty() || !o.switchSyncAtS.empty() || bool(o.input);
    if (busy)
        lastActiveAt = f.now;
    return f.now - lastActiveAt;
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
        for (const char* name :
             {"Session", "View", "Network", "Comparison", "Forces", "Dirty boxes", "Assessment"})
            if (const ImGuiWindow* w = ImGui::FindWindowByName(name); w && w->Active)
                r.panels[name] = {w->Pos.x, w->Pos.y, w->Size.x, w->Size.y};
        r.toolKind = int(selectedKind(toolControls));
        r.toolDiameterMm = selectedDiameter(toolControls);
        r.pushMm = toolControls.pushMm;
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

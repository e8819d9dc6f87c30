// The trainer window. Sections:
// [SECTION] scene: volume-derived data (site, surgical field) built off the main thread
// [SECTION] frame loop: snapshot -> rectangles -> tool -> composite -> overlays -> panels
#include "ui/trainer_app.h"

#include "libsim/device.h"
#include "libsim/error.h"
#include "libsim/haptics.h"
#include "libsim/skull.h"
#include "libsim/volume.h"
#include "libsim_image/volume_slices.h"
#include "net/client_thread.h"
#include "net/codec.h"
#include "net/view.h"
#include "ui/compositor.h"
#include "ui/mouse_tool.h"
#include "ui/panels.h"
#include "ui/window.h"

#include <GLFW/glfw3.h>
#include <imgui.h>

#include <chrono>
#include <cstdio>
#include <future>
#include <glm/gtc/matrix_transform.hpp>
#include <glm/gtx/quaternion.hpp>
#include <glm/gtx/rotate_vector.hpp>
#include <map>
#include <thread>

namespace trephine::ui {

namespace {

constexpr int kPanelWidth = 420;
constexpr int kBottomHeight = 250;

// [SECTION] scene

struct Scene {
    Volume volume;
    SurfaceSite site{};
    MeshData field;
};

Scene buildScene(const std::string& volumeName) {
    Scene s;
    s.volume = openVolume(volumeName);
    try {
        s.site = defaultBurrSite(s.volume);
        s.field = makeSurgicalField(s.volume, s.site);
    } catch (const Error&) {
        // Not a skull: look at the top of the volume, no drape.
        s.site.position = glm::vec3(0, 0, s.volume.extentMm().z * 0.5f);
        s.site.normal = glm::vec3(0, 0, 1);
    }
    return s;
}

glm::vec3 anyPerpendicular(glm::vec3 n) {
    return glm::normalize(
        glm::cross(n, std::abs(n.z) < 0.9f ? glm::vec3(0, 0, 1) : glm::vec3(1, 0, 0)));
}

// The scripted burr hole: plunge at the site, widen in a spiral, then rest the drill to one side.
struct ScriptPose {
    glm::vec3 position;
    glm::vec3 axis;
    bool drilling;
    bool done;
};
ScriptPose burrholePose(const SurfaceSite& site, double t) {
    const glm::vec3 n = site.normal, e1 = anyPerpendicular(n), e2 = glm::cross(n, e1);
    const float depth = 2.0f;
    if (t < 1.0) {
        float d = -1.0f + float(t) * (depth + 1.0f);
        return {site.position - n * d, n, true, false};
    }
    if (t < 4.0) {
        float u = float((t - 1.0) / 3.0);
        float r = 6.0f * u, a = glm::two_pi<float>() * 3.0f * u;
        return {site.position - n * depth + (e1 * std::cos(a) + e2 * std::sin(a)) * r, n, true,
                false};
    }
    // Resting beside the hole, leaning away so the hole stays in view.
    return {site.position + e1 * 16.0f + n * 4.0f, glm::normalize(n + e1 * 0.7f), false, t > 4.3};
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

// The window's tool as the haptic loop's device: the UI thread sets the pose each frame, the
// 1 kHz loop reads it, extrapolates the force there and sends tool states at 100 Hz.
class WindowDevice : public Device {
public:
    struct Tool {
        ToolKind kind = ToolKind::Burr;
        float diameterMm = 5.0f;
        float speed = 0.0f;
        bool drilling = false;
    };
    std::string name() const override { return "window mouse"; }
    DeviceState read(double) override {
        std::lock_guard lock(m_mutex);
        return m_state;
    }
    void setForce(glm::vec3) override {} // a mouse pushes nothing back
    void set(const DeviceState& s, const Tool& t) {
        std::lock_guard lock(m_mutex);
        m_state = s;
        m_tool = t;
    }
    Tool tool() const {
        std::lock_guard lock(m_mutex);
        return m_tool;
    }

private:
    mutable std::mutex m_mutex;
    DeviceState m_state;
    Tool m_tool;
};

glm::mat4 toolMatrix(glm::vec3 position, glm::quat orientation) {
    return glm::translate(glm::mat4(1.0f), position) * glm::mat4_cast(orientation);
}

} // namespace

// [SECTION] frame loop

int runTrainerWindow(const TrainerOptions& o) {
    using Clock = std::chrono::steady_clock;
    const int viewSize = o.size;
    WindowConfig wc;
    wc.width = viewSize + kPanelWidth;
    wc.height = std::max(viewSize + kBottomHeight, 760);
    wc.title =
        std::string("Trephine - ") + (o.instructor ? "instructor" : "trainee") + " - " + o.address;
    wc.visible = o.visible;
    Window window(wc);
    Compositor comp;
    comp.resize(viewSize, viewSize);
    ToolMeshCache tools{&comp, {}};
    GpuMesh fieldMesh;

    net::ClientThreadConfig cc;
    cc.address = o.address;
    cc.client.name = o.name;
    cc.client.role = o.instructor ? net::Role::Instructor : net::Role::Trainee;
    cc.client.codec = net::parseCodec(o.codec);
    cc.client.view.width = cc.client.view.height = 1; // the real view needs the volume's name
    // The haptic loop sends the tool states; the client thread hands it each force model.
    WindowDevice device;
    net::ClientThread* clientPtr = nullptr;
    HapticLoopConfig hc;
    hc.rateHz = 1000.0;
    hc.sendRateHz = 100.0;
    HapticLoop haptics(device, hc, [&](const DeviceState& s, double) {
        WindowDevice::Tool t = device.tool();
        net::ToolState ts;
        ts.toolKind = uint8_t(t.kind);
        ts.diameterMm = t.diameterMm;
        ts.position = s.pose.position;
        ts.orientation = s.pose.orientation;
        ts.speed = t.drilling ? t.speed : 0.0f;
        ts.drilling = t.drilling;
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
    };
    net::ClientThread client(cc);
    clientPtr = &client;
    client.start();
    haptics.start();

    std::future<Scene> sceneFuture;
    std::optional<Scene> scene;
    std::string sceneError;
    Camera baseCamera; // the view before orbiting
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

    Dbi cpuDbi;               // mirror of the textures, for the cursor's depth lookups
    bool haveImage = false;   // the textures hold a full image of the current view
    uint32_t imageViewId = 0; // viewId of the image in the textures
    uint64_t hapticSeen = 0;
    glm::vec3 toolPos(0.0f);
    glm::quat toolRot(1, 0, 0, 0);
    bool toolValid = false;
    double nextSecond = 1.0, lastRectAt = 0.0, scriptStart = -1;
    uint64_t updatesAtLastSecond = 0;
    bool scriptDone = o.script.empty();
    int settledFrames = 0, frames = 0;
    int exitCode = 0;
    const auto t0 = Clock::now();
    auto seconds = [&] { return std::chrono::duration<double>(Clock::now() - t0).count(); };

    auto makeCamera = [&]() {
        glm::vec3 dir = glm::normalize(baseCamera.eye - baseCamera.target);
        glm::vec3 right = glm::normalize(glm::cross(baseCamera.up, dir));
        glm::vec3 upv = glm::cross(dir, right);
        dir = glm::rotate(dir, glm::radians(viewControls.yawDeg), upv);
        dir = glm::rotate(dir, glm::radians(viewControls.pitchDeg), right);
        return cameraLookingAt(baseCamera.target, dir, viewControls.distanceMm, baseCamera.fovYDeg,
                               {viewSize, viewSize}, scene->volume);
    };

    while (!window.shouldClose()) {
        const auto frameStart = Clock::now();
        const double now = seconds();
        auto snap = client.snapshot();

        // Volume-derived scene once the welcome names the volume.
        if (snap->welcome && !scene && !sceneFuture.valid() && sceneError.empty())
            sceneFuture = std::async(std::launch::async, buildScene, snap->welcome->volumeName);
        if (sceneFuture.valid() &&
            sceneFuture.wait_for(std::chrono::seconds(0)) == std::future_status::ready) {
            try {
                scene = sceneFuture.get();
                fieldMesh = comp.upload(scene->field);
                if (o.camera == "site")
                    baseCamera =
                        cameraLookingAt(scene->site.position, scene->site.normal, o.distanceMm,
                                        45.0f, {viewSize, viewSize}, scene->volume);
                else
                    baseCamera = cameraPreset(o.camera, scene->volume, {viewSize, viewSize});
                viewControls.distanceMm = glm::length(baseCamera.eye - baseCamera.target);
                wantedCamera = makeCamera();
                client.requestView(net::toViewSpec(wantedCamera));
            } catch (const std::exception& e) {
                sceneError = e.what();
            }
        }
        if (scene && viewControls.dirty) {
            viewControls.dirty = false;
            wantedCamera = makeCamera();
            client.requestView(net::toViewSpec(wantedCamera));
        }

        // Applied rectangles: only their pixels are uploaded.
        for (net::AppliedRect& r : client.drainRects()) {
            if (r.full) {
                if (r.pixels.width() != viewSize || r.pixels.height() != viewSize)
                    continue; // the placeholder view before ours
                comp.uploadFull(r.pixels);
                cpuDbi = std::move(r.pixels);
                haveImage = true;
                imageViewId = r.viewId;
            } else if (haveImage && r.viewId == imageViewId && cpuDbi.bounds().contains(r.rect)) {
                comp.uploadRect(r.rect, r.pixels);
                cpuDbi.apply(r.pixels, r.rect.x, r.rect.y);
            } else {
                continue;
            }
            lastRectAt = now;
            netHistory.addUpdate({now, r.latencyUs, r.bytes, r.rawBytes, r.full});
            boxHistory.add({now, r.rect, r.sequence, r.bytes, r.latencyUs, r.full});
        }
        netHistory.expire(now);
        const bool viewMatches = snap->view.width == viewSize && snap->view.height == viewSize;
        const Camera dbiCamera = net::toCamera(snap->view);

        // Tool: the script, or the mouse device on the bone under the cursor.
        ImGuiIO& io = ImGui::GetIO();
        if (scene && haveImage && o.script == "burrhole") {
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
        } else if (scene && haveImage && viewMatches) {
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
                    toolControls.pushMm += 0.25f;
                if (ImGui::IsKeyPressed(GLFW_KEY_UP))
                    toolControls.pushMm -= 0.25f;
            }
            const bool overView = io.MousePos.x >= 0 && io.MousePos.y >= 0 &&
                                  io.MousePos.x < float(viewSize) &&
                                  io.MousePos.y < float(viewSize) && !io.WantCaptureMouse;
            if (overView) {
                toolControls.pushMm =
                    std::clamp(toolControls.pushMm + io.MouseWheel * 0.25f, -5.0f, 10.0f);
                int px = int(io.MousePos.x), py = viewSize - 1 - int(io.MousePos.y);
                if (auto hit = pickSurface(cpuDbi, dbiCamera, px, py)) {
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
            device.set(ds, {kind, diameter, toolControls.speed, toolControls.drilling});
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
        forceHistory.extrapolated.clear();
        for (const HapticSample& h : haptics.samples())
            forceHistory.extrapolated.push_back({h.time, h.force});
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

        // Composite: pass 1 the DBI, pass 2 the anatomy and the tools, blitted top-left.
        window.beginFrame();
        const float viewTop = 0.0f;
        if (haveImage && viewMatches) {
            comp.begin(dbiCamera);
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
        if (haveImage && viewMatches) {
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
                      "client " + std::to_string(id) + (t.drilling ? " (drilling)" : ""));
            if (toolValid)
                label(toolPos, toolRot * glm::vec3(0, 0, 1), participantColor(0),
                      o.name + (toolControls.drilling ? " (drilling)" : ""));
            drawDirtyBoxOverlay(boxState, boxHistory, now, 0.0f, viewTop, viewSize);
        }
        {
            std::string status;
            if (snap->state == net::LinkState::Connecting)
                status = "Connecting to " + o.address + " (attempt " +
                         std::to_string(snap->attempts) + ")...";
            else if (snap->state == net::LinkState::Retrying)
                status = "Not connected: " + snap->closeReason + "\nRetrying...";
            else if (!sceneError.empty())
                status = "Cannot open the session's volume: " + sceneError;
            else if (!haveImage)
                status = "Waiting for the first image of the skull...";
            else if (snap->waitingForView)
                status = "Waiting for the new view...";
            if (!status.empty()) {
                ImVec2 sz = ImGui::CalcTextSize(status.c_str(), nullptr, false, viewSize - 40.0f);
                ImVec2 at((float(viewSize) - sz.x) * 0.5f,
                          haveImage ? 12.0f : viewTop + (float(viewSize) - sz.y) * 0.5f);
                fg->AddRectFilled(ImVec2(at.x - 10, at.y - 8),
                                  ImVec2(at.x + sz.x + 10, at.y + sz.y + 8),
                                  IM_COL32(20, 20, 24, 210), 6.0f);
                fg->AddText(nullptr, 0.0f, at, IM_COL32(255, 200, 90, 255), status.c_str(), nullptr,
                            viewSize - 40.0f);
            }
        }

        // Panels: right column and the strip under the view.
        const float right = float(viewSize), colW = float(kPanelWidth);
        const float H = float(window.height());
        ImGui::SetNextWindowPos(ImVec2(right, 0), ImGuiCond_FirstUseEver);
        ImGui::SetNextWindowSize(ImVec2(colW, 250), ImGuiCond_FirstUseEver);
        drawSessionPanel(*snap, toolControls, o.instructor ? "instructor" : "trainee", o.address,
                         o.name);
        ImGui::SetNextWindowPos(ImVec2(right, 250), ImGuiCond_FirstUseEver);
        ImGui::SetNextWindowSize(ImVec2(colW, 120), ImGuiCond_FirstUseEver);
        drawViewPanel(viewControls, snap->waitingForView || !haveImage,
                      haveImage ? describe(dbiCamera) : std::string("no image yet"));
        ImGui::SetNextWindowPos(ImVec2(right, 370), ImGuiCond_FirstUseEver);
        ImGui::SetNextWindowSize(ImVec2(colW, H - 370), ImGuiCond_FirstUseEver);
        drawNetworkPanel(*snap, netHistory, now);
        ImGui::SetNextWindowPos(ImVec2(0, float(viewSize)), ImGuiCond_FirstUseEver);
        ImGui::SetNextWindowSize(ImVec2(right * 0.5f, H - float(viewSize)), ImGuiCond_FirstUseEver);
        drawForcesPanel(forceHistory, hstats.achievedRateHz,
                        o.instructor ? &participantForces : nullptr);
        ImGui::SetNextWindowPos(ImVec2(right * 0.5f, float(viewSize)), ImGuiCond_FirstUseEver);
        ImGui::SetNextWindowSize(ImVec2(right * 0.5f, H - float(viewSize)), ImGuiCond_FirstUseEver);
        drawDirtyBoxPanel(boxState, boxHistory, now);

        // Screenshot / frame budget.
        ++frames;
        const bool settled = haveImage && viewMatches && scene && scriptDone &&
                             !snap->waitingForView && now - lastRectAt > 0.5;
        settledFrames = settled ? settledFrames + 1 : 0;
        Dbi capture;
        bool shoot = !o.screenshot.empty() && settledFrames >= std::max(o.frames, 1);
        const bool timedOut = !o.screenshot.empty() && now > o.timeoutS;
        window.endFrame(shoot || timedOut ? &capture : nullptr);
        if (shoot || timedOut) {
            writeScreenshot(o.screenshot, capture);
            if (timedOut) {
                std::fprintf(stderr,
                             "trephine: screenshot %s taken after %.0f s without a settled view "
                             "(%s)\n",
                             o.screenshot.c_str(), now, net::linkStateName(snap->state));
                exitCode = 1;
            } else {
                std::printf("screenshot %s (%dx%d) after %d frames\n", o.screenshot.c_str(),
                            capture.width(), capture.height(), frames);
            }
            break;
        }
        if (o.screenshot.empty() && o.frames > 0 && frames >= o.frames)
            break;
        std::this_thread::sleep_until(frameStart + std::chrono::milliseconds(10));
    }
    haptics.stop();
    client.stop();
    comp.destroy(fieldMesh);
    return exitCode;
}

} // namespace trephine::ui

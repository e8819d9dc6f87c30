// The trainee's client core, run by the window and by the headless trainee alike (one code path,
// two shells): the session client on its network thread, the 1 kHz haptic loop, the force the loop
// feels (the server's multi-rate models, or the local volume in the replicated-volume design) and
// the tool it drills with (a device the window moves, or a script).
#pragma once

#include "libsim/device.h"
#include "libsim/device_guard.h"
#include "libsim/force_model.h"
#include "libsim/haptics.h"
#include "net/client_model.h"
#include "net/client_thread.h"
#include "net/hand_links.h"
#include "net/protocol.h"

#include <atomic>
#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace trephine::net {

// Where the tool comes from: a device for its pose, and the tool held with it. Called on the
// haptic thread only.
class ToolSource {
public:
    virtual ~ToolSource() = default;
    virtual Device& device() = 0;
    // The tool at loop time `now` with the device at `pose`: kind, diameter, speed, drilling and
    // the pose (clientTimeUs is stamped by the core when it sends).
    virtual ToolState toolAt(const ToolPose& pose, double now) = 0;
    // The tool's velocity (mm/s), for the drilling resistance of a local force model.
    virtual glm::vec3 velocity(const ToolPose& pose, double now) = 0;
    // Where the user means the tool to be at `now`, for a simulated hand (ForceDevice::setIntent);
    // none where a real hand holds the device.
    virtual std::optional<ToolPose> intent(double) { return std::nullopt; }
    // The device's buttons as the loop read them (bit i: button i), before each tool state.
    virtual void noteButtons(uint32_t, double) {}
};

// One row of a trainee script: the tool state from time t (s) until the next row.
struct ScriptSample {
    double t = 0;
    ToolState tool;
};

// A script as a tool source: the device plays the rows' poses (e.g. a ScriptedDevice made from
// them); speed, drilling and tool hold from one row to the next, and drilling stops at `endS`.
class ScriptToolSource : public ToolSource {
public:
    ScriptToolSource(Device& device, std::vector<ScriptSample> script, double endS);
    Device& device() override { return m_device; }
    ToolState toolAt(const ToolPose& pose, double now) override;
    glm::vec3 velocity(const ToolPose& pose, double now) override;
    // The rows' poses, linear in position and slerped in orientation between rows.
    std::optional<ToolPose> intent(double now) override;
    // A device with buttons (a SpaceMouse headless) takes over from the rows: button 0 starts and
    // stops the drill, button 1 picks the next tool at its default size.
    void noteButtons(uint32_t buttons, double now) override;
    const ScriptSample& sampleAt(double t) const;
    double endS() const { return m_endS; }

private:
    Device& m_device;
    std::vector<ScriptSample> m_script; // not empty, sorted by t
    double m_endS;
    VelocityEstimate m_velocity;
    uint32_t m_buttons = 0;
    std::optional<bool> m_drilling; // set by button 0: the rows' drilling no longer counts
    int m_nextTools = 0;            // button 1 presses
};

// The assessment's warning felt on the device: a 60 Hz buzz back up the tool's shaft (its local
// +z, away from the tip), never toward the bone, while its own tool is in the danger zone (peak
// 0.3 N) or touching a structure (0.6 N); nothing when clear or in caution, which the view shows.
glm::vec3 zoneBuzz(Zone zone, double now, glm::vec3 axis);

// The haptic loop's force in either design, chosen per tick. DBI: the server's force models,
// extrapolated and blended (the multi-rate scheme). Local: the ForceModel on the client's own copy
// of the volume, read under ClientThread::withLocalVolume's shared lock; while no copy is held it
// falls back to the server's models. The blender runs in both, so a switch back blends from where
// it is. force() runs on the haptic thread only.
class TraineeForce : public ForceSource {
public:
    TraineeForce(ToolSource& tools, BlendConfig blend) : m_tools(tools), m_blender(blend) {}
    void setClient(const ClientThread* client) { m_client = client; } // before the loop runs
    // Any thread: the newest server model (one answering an older tool state is dropped).
    void setModel(const HapticModelData& m) { m_serverModel.offer(m, 0.0); }
    // Any thread: compute forces on the local volume.
    void setLocal(bool local) { m_local = local; }
    uint64_t localTicks() const { return m_localTicks.load(); }
    uint64_t serverTicks() const { return m_serverTicks.load(); }
    size_t toolsUsed() const { return m_toolsUsed.load(); } // shapes the local model was built for
    // Ticks that felt another participant's force, or the guide's pull (HandLinks).
    uint64_t feltTicks() const { return m_feltTicks.load(); }
    uint64_t guidedTicks() const { return m_guidedTicks.load(); }

    glm::vec3 force(const ToolPose& pose, double now) override;

private:
    // [Hand links] From the client's newest snapshot: the guide's target and the felt participant.
    void followLinks();
    glm::vec3 feltForce(const ToolPose& pose, double now);

    ToolSource& m_tools;
    const ClientThread* m_client = nullptr;
    ModelBlender m_blender;
    ForceModelCache m_models;
    NewestModel m_serverModel;
    std::atomic<bool> m_local{false};
    std::atomic<uint64_t> m_localTicks{0}, m_serverTicks{0};
    std::atomic<size_t> m_toolsUsed{0};
    // Hand links, haptic thread only: the snapshot they were read from.
    std::shared_ptr<const ClientSnapshot> m_linkSnap;
    std::optional<glm::vec3> m_guide;
    uint16_t m_felt = 0;
    uint32_t m_feltSequence = 0;
    Zone m_zone = Zone::Clear; // of the newest warning about its own tool
    VelocityEstimate m_guideVelocity;
    HandGuideConfig m_guideConfig;
    GuideRamp m_guideRamp;
    std::atomic<uint64_t> m_feltTicks{0}, m_guidedTicks{0};
};

// Silence from a connected server after which the device is no longer driven.
inline constexpr uint64_t kSilentLinkUs = 1'000'000;

struct TraineeCoreConfig {
    ClientThreadConfig client; // its onHapticModel is the core's
    HapticLoopConfig haptics;
    DeviceGuardConfig guard; // the device's safety: clamp and per-tick rate limit
};

// The session client thread plus, once a tool source is given, the haptic loop that sends its tool
// states and feels the force. connect() first (the tool may need what the session sends), then
// startHaptics(). The destructor stops both, the loop first (it sends through the client).
// The loop drives the device through a DeviceGuard: zero force while the link is not connected,
// and none at all once the loop has stopped.
class TraineeCore {
public:
    explicit TraineeCore(TraineeCoreConfig config);
    ~TraineeCore();
    TraineeCore(const TraineeCore&) = delete;
    TraineeCore& operator=(const TraineeCore&) = delete;

    void connect();
    // Starts the haptic loop on `tools` (once; `tools` must outlive the core). Forces are local
    // from the start when the client asked for the volume design.
    void startHaptics(ToolSource& tools);
    // Stops the loop and releases the device (zero force, never driven again); its figures stay
    // readable. The loop and force live until the core goes, as the client thread may still be
    // handing a model to them.
    void stopHaptics();
    // Stops the haptic loop, then disconnects and joins the client thread.
    void stop();

    ClientThread& client() { return *m_client; }
    const ClientThread& client() const { return *m_client; }
    bool hapticsRunning() const { return m_loop != nullptr; }
    // Local forces on or off (no-op before startHaptics).
    void setLocalForces(bool local);
    // The loop's figures and recent samples (zero / empty before startHaptics).
    HapticLoopStats hapticStats() const;
    std::vector<HapticSample> hapticSamples() const;
    const HapticLoopConfig& hapticConfig() const { return m_config.haptics; }
    uint64_t localForceTicks() const { return m_force ? m_force->localTicks() : 0; }
    uint64_t serverForceTicks() const { return m_force ? m_force->serverTicks() : 0; }
    size_t localForceTools() const { return m_force ? m_force->toolsUsed() : 0; }
    // [Hand links] ticks that felt another participant, and that the guide pulled.
    uint64_t feltTicks() const { return m_force ? m_force->feltTicks() : 0; }
    uint64_t guidedTicks() const { return m_force ? m_force->guidedTicks() : 0; }
    // The device guard's counts (read them once the loop has stopped) and the device's fault,
    // if it was cut off ("" if not, or not a force device).
    DeviceGuardStats deviceGuardStats() const {
        return m_guard ? m_guard->stats() : DeviceGuardStats{};
    }
    std::string deviceFault() const;
    // The haptic figures a ClientModel report takes from the core (both shells call this).
    ClientReportExtras reportExtras() const;

private:
    void onModel(const HapticModel& m);

    TraineeCoreConfig m_config;
    std::unique_ptr<ClientThread> m_client;
    // Set once by startHaptics before the loop runs; read by the client thread's model callback.
    std::atomic<bool> m_hapticsLive{false};
    std::unique_ptr<TraineeForce> m_force;
    std::unique_ptr<DeviceGuard> m_guard; // between the loop and the tool source's device
    std::unique_ptr<HapticLoop> m_loop;
    uint64_t m_loopStartUs = 0; // steadyNowUs() when the loop's clock started
};

// The trainee's picture without a window (the headless trainee, the demo): the DBI rebuilt from
// the client's applied updates as the window rebuilds its textures, and the client model they
// feed. Owned by one thread.
class HeadlessView {
public:
    explicit HeadlessView(int size) : m_size(size) {}
    // The newest snapshot and the updates applied since the last call, into the model.
    void take(ClientThread& client, uint64_t hapticTicks);
    // Takes snapshots until `pred` holds (true), the link fails or `seconds` pass (false).
    bool waitFor(ClientThread& client, double seconds, const std::function<bool()>& pred);

    bool connected() const { return m_snap && m_snap->state == LinkState::Connected; }
    bool hasPicture() const { return m_dbi.width() == m_size; }
    const Dbi& dbi() const { return m_dbi; } // empty until the view's first whole image
    // The newest snapshot (null before the first take).
    const std::shared_ptr<const ClientSnapshot>& snap() const { return m_snap; }
    ClientModel model;

private:
    int m_size;
    Dbi m_dbi;
    uint32_t m_viewId = 0;
    std::shared_ptr<const ClientSnapshot> m_snap;
    std::chrono::steady_clock::time_point m_t0 = std::chrono::steady_clock::now();
};

} // namespace trephine::net

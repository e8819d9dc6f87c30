// Multi-rate haptics on the client: extrapolate the server's force model at 1 kHz,
// F(p) = f(P_N) + grad f(P_N) (p - P_N); blend each new model in instead of jumping; fade a stale
// model out; clamp; record samples. HapticLoop runs that on its own thread (or step() by hand).
//
// [SECTION] model and extrapolation
// [SECTION] blender
// [SECTION] recorder
// [SECTION] force sources
// [SECTION] haptic loop
#pragma once

#include "libsim/device.h"
#include "libsim/force_model.h"
#include "libsim/stats.h"
#include "libsim/volume.h"

#include <atomic>
#include <chrono>
#include <cstdint>
#include <functional>
#include <glm/mat3x3.hpp>
#include <glm/vec3.hpp>
#include <memory>
#include <mutex>
#include <optional>
#include <thread>
#include <vector>

namespace trephine {

// [SECTION] model and extrapolation

// What the server computed for one tool state (net's HapticModel carries the same fields).
struct HapticModelData {
    glm::vec3 position{0.0f}; // P_N: the device position the model was computed at (mm)
    glm::vec3 force{0.0f};    // f(P_N) (N)
    glm::mat3 gradient{0.0f}; // grad f(P_N) (N/mm), column-major as glm
    bool contact = false;
    uint32_t toolSequence = 0; // the tool state it answers
};

// The affine force field a model (or a blend of two) defines; doubles so that blends of far-apart
// anchors lose nothing.
struct AffineForce {
    glm::dvec3 anchor{0.0}; // P_N
    glm::dvec3 force{0.0};  // at the anchor
    glm::dmat3 gradient{0.0};
    // The way the contact pushes: the model's own f(P_N) (for a blend, the same mix of its
    // fields' pushes). Not f at another field's anchor, which the extrapolation may have reversed.
    glm::dvec3 push{0.0};

    static AffineForce fromModel(const HapticModelData& m);
    glm::dvec3 at(glm::dvec3 p) const { return force + gradient * (p - anchor); }
};

// Equation 1 of the paper. Exactly m.force at p == m.position.
glm::vec3 extrapolate(const HapticModelData& m, glm::vec3 p);

// A contact only pushes: f less its component against `push` (the way the contact pushes), so
// Equation 1 extrapolated past the surface (the hand lifting off) does not pull the tool into the
// bone. Below kUnilateralFullN of push the removal is scaled down in proportion, so the result is
// continuous in both arguments (no direction at all: f unchanged).
// Small: a model taken just as the tool touches (f = 0.005 N, -6 N/mm) must still be cut, or
// lifting 1 mm pulls 3 N into the bone; the per-tick step bound holds however steep the ramp.
inline constexpr double kUnilateralFullN = 1e-4;
glm::dvec3 unilateral(glm::dvec3 f, glm::dvec3 push);

// The stiffest field a model may carry (Frobenius norm of its gradient, N/mm), about 170 times the
// force model's 6 N/mm; a steeper one is scaled down to it (ModelBlender::setModel).
inline constexpr double kMaxGradientNPerMm = 1000.0;

// Scales f to |f| <= maxN (keeps its direction).
glm::vec3 clampForce(glm::vec3 f, float maxN);

// [SECTION] blender

struct BlendConfig {
    // A new model replaces the old over this long (s); 0 measures it: the interval between the
    // last two models (about one update period), kept within [minBlendS, maxBlendS].
    double blendTimeS = 0.0;
    double minBlendS = 0.002;
    double maxBlendS = 0.1;
    // The most a model switch or a fade may change the output in one tick at a fixed position (N).
    double maxStepN = 0.25;
    double staleTimeoutS = 0.25; // no model for this long: fade the force out
    double fadeTimeS = 0.1;      // fading from full force to zero takes at least this long
    float maxForceN = kDefaultMaxForceN;
    // A contact only pushes (`unilateral`); false: the paper's plain Equation 1, which pulls a
    // tool lifted past the surface back in (kept to measure the difference).
    bool unilateral = true;
    // The blend lasts at least delay^2 / delayBlendScaleS (0: off), the delay being the blender's
    // own estimate (delayEstimate). Each model extrapolates over speed x delay, so successive
    // models disagree more the longer the delay; a short blend of them shook the hand at 300 ms
    // (docs/haptics.md). 1 s: 2.5 ms at 50 ms (no change), 40 ms at 200 ms, 90 ms at 300 ms.
    double delayBlendScaleS = 1.0;
};

// The haptic-rate side of multi-rate: owned by one thread, fed models with their arrival time.
// At a fixed device position the output never changes by more than maxStepN between two ticks on
// account of a new model or a fade (it changes freely as the device moves through the field).
class ModelBlender {
public:
    explicit ModelBlender(BlendConfig config = {}) : m_config(config) {}

    // A model with a non-finite field is ignored.
    void setModel(const HapticModelData& m, double now);
    // Takes the model at once, without a blend: only for a start from rest in a known state (a
    // study's warm start, tests). A live loop uses setModel.
    void resetTo(const HapticModelData& m, double now);
    // The force at device position p at time now (call once per tick, now non-decreasing).
    glm::vec3 update(glm::vec3 p, double now);

    bool hasModel() const { return m_hasModel; }
    // The round trip of the newest model whose P_N is a position this blender was updated at:
    // its arrival less that tick's time (s); 0 before the first. While the device has not moved
    // since that tick, the tick is ambiguous and the previous estimate stays.
    double delayEstimate() const { return m_delay; }
    bool stale() const { return m_fading; }
    double blendFraction() const { return m_alpha; } // 1: the newest model alone
    double lastModelTime() const { return m_lastModelTime; }
    const BlendConfig& config() const { return m_config; }
    void reset();

private:
    AffineForce current() const;
    void remember(glm::vec3 p, double now);
    void estimateDelay(glm::vec3 anchor, double now);

    // The positions of the last kHistory updates, for the delay estimate.
    static constexpr size_t kHistory = 1024;
    struct Tick {
        double time;
        glm::vec3 position;
    };
    std::vector<Tick> m_history;
    size_t m_historyNext = 0;
    double m_delay = 0.0;

    BlendConfig m_config;
    AffineForce m_from, m_to;
    double m_alpha = 1.0; // 0: m_from, 1: m_to
    double m_blendTime = 0.0;
    double m_lastTick = 0.0;
    double m_lastModelTime = 0.0;
    double m_prevModelTime = -1.0;
    bool m_hasModel = false;
    bool m_fading = false;
    bool m_ticked = false;
};

// [SECTION] recorder

struct HapticSample {
    double time = 0.0;          // s
    float forceN = 0.0f;        // |F| output
    glm::vec3 force{0.0f};      // output to the device
    glm::vec3 modelForce{0.0f}; // the newest server f(P_N)
    glm::vec3 position{0.0f};   // device position (the last read's when this tick's missed)
    bool stale = false;
    bool missed = false; // the device gave no pose this tick (late, cut off): zero force
};

// A ring of the most recent samples for plots; single thread.
class HapticRecorder {
public:
    explicit HapticRecorder(size_t capacity = 4096) : m_capacity(capacity) {}
    void add(const HapticSample& s);
    std::vector<HapticSample> samples() const; // oldest first
    size_t size() const { return m_ring.size(); }

private:
    size_t m_capacity;
    std::vector<HapticSample> m_ring;
    size_t m_next = 0;
};

// [SECTION] force sources

// Where the haptic loop's force comes from: the server's models (multi-rate) or a local volume.
class ForceSource {
public:
    virtual ~ForceSource() = default;
    virtual glm::vec3 force(const ToolPose& pose, double now) = 0;
};

// Local haptics (replicated-volume baseline): the force model on a volume the client holds. The
// volume must not change while force() runs (the caller serialises its updates with the loop).
class LocalForceSource : public ForceSource {
public:
    LocalForceSource(const Volume& volume, const ToolShape& shape, ForceModelConfig config = {})
        : m_volume(volume), m_model(shape, config) {}
    glm::vec3 force(const ToolPose& pose, double) override {
        return m_model.compute(m_volume, pose).force;
    }

private:
    const Volume& m_volume;
    ForceModel m_model;
};

// The newest server force model waiting for a haptic thread: offered from any thread, taken once
// a tick by the haptic thread. The haptic channel is unsequenced, so models may come reversed: one
// answering an older tool state than the one waiting, or than the last one taken, is dropped
// (sequence numbers wrap: compared by signed difference).
class NewestModel {
public:
    // `arrivedAt`: the arrival time handed back with it. False when dropped as older than the
    // model waiting (which stays).
    bool offer(const HapticModelData& model, double arrivedAt);
    struct Taken {
        std::optional<std::pair<HapticModelData, double>> model; // with its arrival time
        bool dropped = false; // one waited, older than the last taken
    };
    // Haptic thread: the model waiting, if any and newer than the last one taken.
    Taken take();

private:
    std::mutex m_mutex;
    std::optional<std::pair<HapticModelData, double>> m_pending;
    uint32_t m_lastSequence = 0; // of the last model taken (haptic thread only)
    bool m_any = false;
};

// [SECTION] haptic loop

struct HapticLoopConfig {
    double rateHz = 1000.0;
    double sendRateHz = 100.0; // tool states to the server, 20-1000 Hz
    BlendConfig blend;
    size_t recorderCapacity = 4096;
};

struct HapticLoopStats {
    uint64_t ticks = 0;
    uint64_t sent = 0;
    uint64_t models = 0;
    uint64_t modelsDropped = 0;  // out of order
    double achievedRateHz = 0.0; // over the run so far
    double latenessP50Ms = 0.0;  // how late each tick started after its scheduled time
    double latenessP99Ms = 0.0;
};

// The client's 1 kHz haptic loop: read the device, compute the force (multi-rate from the newest
// server model, or a local ForceSource), output it, record it, and send the tool state at the
// throttled rate through `send`. setModel is safe from any thread; the rest belongs to the owner.
class HapticLoop {
public:
    using SendToolState = std::function<void(const DeviceState& state, double now)>;

    HapticLoop(Device& device, HapticLoopConfig config, SendToolState send);
    ~HapticLoop();
    HapticLoop(const HapticLoop&) = delete;
    HapticLoop& operator=(const HapticLoop&) = delete;

    // Thread-safe: the network thread hands over each model as it arrives (now: arrival time).
    // A model answering an older tool state than one already applied or still pending (reordered
    // by the network) is dropped and counted.
    void setModel(const HapticModelData& model, double now);
    // Local mode: a non-null source replaces the server's models (the loop does not own it).
    // Call while the loop is stopped.
    void setForceSource(ForceSource* source) { m_source = source; }
    void setSendRate(double hz);

    // One tick at time now (seconds): what the thread does each millisecond. Returns the sample.
    HapticSample step(double now);

    // Runs step() at rateHz on a thread named "haptics" until stop(). Its clock (the `now` of
    // step, and of setModel's arrival times) counts from the first start(), across restarts.
    void start();
    void stop();
    bool running() const { return m_thread.joinable(); }

    HapticLoopStats stats() const;             // thread-safe
    std::vector<HapticSample> samples() const; // thread-safe copy of the recent samples

private:
    void run();

    Device& m_device;
    HapticLoopConfig m_config;
    SendToolState m_send;
    ForceSource* m_source = nullptr;
    ModelBlender m_blender;

    NewestModel m_models;
    glm::vec3 m_lastModelForce{0.0f};
    glm::vec3 m_lastPosition{0.0f}; // the last valid read's, for a missed tick's sample

    mutable std::mutex m_statsMutex;
    HapticRecorder m_recorder;
    SampleWindow m_lateness{8192};
    HapticLoopStats m_stats;
    double m_firstTick = -1.0, m_lastTick = 0.0;
    double m_nextSend = -1.0;
    std::atomic<double> m_sendRateHz;
    std::atomic<bool> m_stop{false};
    std::optional<std::chrono::steady_clock::time_point> m_clockStart; // the first start()
    std::thread m_thread;
};

} // namespace trephine

// The haptics study: a simulated hand holds a tool against bone while force models arrive at a
// given update rate and latency; multi-rate extrapolation is compared with a zero-order hold of
// f alone on force error, injected energy (passivity) and stability. Deterministic: no clocks.
#pragma once

#include "libsim/force_model.h"
#include "libsim/haptics.h"
#include "libsim/skull.h"
#include "libsim/volume.h"

#include <functional>
#include <memory>
#include <string>
#include <vector>

namespace trephine::study {

// Exact: the force model at the device position every tick, with no delay. It is the reference
// every case is judged against: the same hand and tremor on the display the network only
// approximates.
enum class HapticMethod { Multirate, ZeroOrderHold, Exact };
const char* hapticMethodName(HapticMethod m); // "multirate", "zoh", "exact"

// The hand: a mass on a spring-damper pulled towards a target inside the bone (it presses the
// tool in; the contact force holds it back). A slow slide along the surface and a small tremor
// keep the contact point moving.
struct HandModel {
    double massKg = 0.15;
    double stiffnessNPerMm = 1.0;
    double dampingNsPerMm = 0.005; // 5 N s/m: a relaxed grip
    double targetDepthMm = 2.0;    // below the surface, measured at the cutter's lowest point
    double startDepthMm = 0.0;     // at least this deep at the start (else: the equilibrium)
    double slideMmPerS = 5.0;      // target slides along the surface
    double tremorMm = 0.3;         // amplitude along the normal
    double tremorHz = 8.0;
};

// Where a hand works: the site's surface point and outward normal, the slide's direction, and the
// offset from the tool's reference point to the cutter's lowest point.
struct HandFrame {
    glm::dvec3 surface{0.0};
    glm::dvec3 normal{0.0, 0.0, 1.0};
    glm::dvec3 tangent{1.0, 0.0, 0.0};
    double tipOffsetMm = 0.0;

    double penetration(glm::dvec3 x) const { return glm::dot(surface - x, normal) + tipOffsetMm; }
    glm::dvec3 atDepth(double depthMm) const { return surface + normal * (tipOffsetMm - depthMm); }
};

// What the display pushes against. Any hand (this spring-damper one, a simulated force device)
// only has to report where the tool is and move under the force it is given.
class StudyHand {
public:
    virtual ~StudyHand() = default;
    virtual glm::dvec3 position() const = 0;
    // The tool over [t, t + dt] under the device force, held for the tick (the device's own
    // zero-order hold).
    virtual void advance(glm::dvec3 forceN, double t, double dt) = 0;
};

// HandModel integrated with semi-implicit Euler at `substeps` steps a tick, from rest at `start`.
class SpringHand : public StudyHand {
public:
    SpringHand(const HandModel& model, const HandFrame& frame, glm::dvec3 start, int substeps);
    glm::dvec3 position() const override { return m_x; }
    void advance(glm::dvec3 forceN, double t, double dt) override;

private:
    HandModel m_model;
    HandFrame m_frame;
    glm::dvec3 m_x, m_v{0.0};
    int m_substeps;
};

// Where HandModel's hand aims at time t: its target depth less the tremor, slid along the surface.
glm::dvec3 handTarget(const HandModel& model, const HandFrame& frame, double t);

// The simulated force device (plugins/sim_device) as the hand, through the device plugin ABI,
// called directly on simulated time: HandModel's mass, stiffness and damping are its arguments,
// its intent each tick is handTarget at the tick's middle, and it integrates the tick itself.
class PluginHand : public StudyHand {
public:
    // Throws trephine::Error (one line) when the plugin does not load.
    PluginHand(const std::string& path, const HandModel& model, const HandFrame& frame,
               glm::dvec3 start);
    ~PluginHand() override;
    PluginHand(const PluginHand&) = delete;
    PluginHand& operator=(const PluginHand&) = delete;
    glm::dvec3 position() const override { return m_x; }
    void advance(glm::dvec3 forceN, double t, double dt) override;

private:
    struct Loaded;
    std::unique_ptr<Loaded> m_plugin;
    HandModel m_model;
    HandFrame m_frame;
    glm::dvec3 m_x;
    bool m_started = false;
};
// The simulated force device built beside this program (../plugins/ from its folder); "" if none.
std::string builtSimDevicePath();

// Makes the hand of one run, at rest at `start`. Empty: a SpringHand of HapticsStudyConfig::hand.
using HandFactory =
    std::function<std::unique_ptr<StudyHand>(const HandFrame& frame, glm::dvec3 start)>;

struct HapticsStudyConfig {
    ToolShape shape = ToolShape::burr(2.0f);
    ForceModelConfig force;
    HandModel hand;
    HandFactory makeHand;
    BlendConfig blend;
    double durationS = 2.0;
    double hapticRateHz = 1000.0;
    int handSubsteps = 10; // hand integration steps per haptic tick
    // Ablation: multirate with the gradient dropped (blended f alone). Shows that the stability
    // comes from the extrapolation, not from the blending.
    bool multirateUsesGradient = true;
    // Stability limits, each against the Exact reference run (see docs/haptics.md).
    double maxOvershootMm = 1.0; // beyond the hand's target depth
    // Peak-to-peak along the normal of (depth - the reference's depth) over the last 0.25 s: the
    // motion the display adds to what the hand's own tremor makes.
    double maxExcessOscillationMm = 0.05;
    // Work of the display's error, (displayed - exact force) . dx, summed over the run.
    double maxEnergyInjectedJ = 0.001;
};

struct HapticsCase {
    HapticMethod method = HapticMethod::Multirate;
    double updateHz = 100.0;
    double latencyMs = 0.0; // from sampling P_N to the model's arrival (round trip)
};

struct HapticsCaseResult {
    HapticsCase c;
    double forceRmsErrorN = 0.0; // |displayed - true contact force| over the run
    double forcePeakErrorN = 0.0;
    double energyInjectedJ = 0.0; // integral of (displayed - true) . v dt; > 0: active
    bool stable = false;
    double maxPenetrationMm = 0.0;
    double finalOscillationMm = 0.0;     // peak-to-peak along the normal, last 0.25 s
    double earlyOscillationMm = 0.0;     // the same over [T/2, T/2 + 0.25 s]
    double referenceOscillationMm = 0.0; // finalOscillationMm of the Exact run
    double excessOscillationMm = 0.0;    // of depth - the Exact run's depth, last 0.25 s
    double meanForceN = 0.0;             // displayed, over the second half
    int modelsDelivered = 0;
};

// One run, judged against an Exact run of the same hand. `site` is a point on the bone surface and
// its outward normal.
HapticsCaseResult runHapticsCase(const Volume& volume, const SurfaceSite& site,
                                 const HapticsStudyConfig& config, const HapticsCase& c);

// Where a run's force models come from: the model answering the tool pose the client samples
// (its P_N). Called once for the warm start and at each update, in simulated-time order; the
// answer then reaches the hand `latencyMs` of simulated time later. The default computes the
// force model on the volume in process; a test passes one that asks a real SessionServer.
using HapticModelSource = std::function<HapticModelData(const ToolPose& pose)>;

// The same run with the models from `source` (toolSequence is set by the run; the gradient is
// dropped when !config.multirateUsesGradient). `volume` still gives the hand's start and the true
// contact force the errors are measured against, so it must hold what the source answers from.
HapticsCaseResult runHapticsCase(const Volume& volume, const SurfaceSite& site,
                                 const HapticsStudyConfig& config, const HapticsCase& c,
                                 const HapticModelSource& source);

// Exact first line of haptics.csv.
std::string hapticsCsvHeader();
std::string hapticsCsvRow(const HapticsCaseResult& r);

} // namespace trephine::study

// The haptics study: a simulated hand holds a tool against bone while force models arrive at a
// given update rate and latency; multi-rate extrapolation is compared with a zero-order hold of
// f alone on force error, injected energy (passivity) and stability. Deterministic: no clocks.
#pragma once

#include "libsim/force_model.h"
#include "libsim/haptics.h"
#include "libsim/skull.h"
#include "libsim/volume.h"

#include <functional>
#include <string>
#include <vector>

namespace trephine::study {

enum class HapticMethod { Multirate, ZeroOrderHold };
const char* hapticMethodName(HapticMethod m); // "multirate", "zoh"

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

struct HapticsStudyConfig {
    ToolShape shape = ToolShape::burr(2.0f);
    ForceModelConfig force;
    HandModel hand;
    BlendConfig blend;
    double durationS = 2.0;
    double hapticRateHz = 1000.0;
    int handSubsteps = 10; // hand integration steps per haptic tick
    // Ablation: multirate with the gradient dropped (blended f alone). Shows that the stability
    // comes from the extrapolation, not from the blending.
    bool multirateUsesGradient = true;
    // Stability limits (see docs/haptics.md).
    double maxOvershootMm = 1.0;        // beyond the hand's target depth
    double maxFinalOscillationMm = 0.2; // peak-to-peak along the normal over the last 0.25 s
    double maxEnergyInjectedJ = 0.005;
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
    double finalOscillationMm = 0.0; // peak-to-peak along the normal, last 0.25 s
    double earlyOscillationMm = 0.0; // the same over [T/2, T/2 + 0.25 s]
    double meanForceN = 0.0;         // displayed, over the second half
    int modelsDelivered = 0;
};

// One run. `site` is a point on the bone surface and its outward normal.
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

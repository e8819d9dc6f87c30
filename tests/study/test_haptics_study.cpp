// The haptics study in simulation (no network): multi-rate extrapolation against a zero-order hold
// of f alone, and the CSV it writes.
#include "study/haptics_study.h"

#include "libsim/skull.h"

#include <gtest/gtest.h>

#include <algorithm>

using namespace trephine;
using namespace trephine::study;

// The paper's claim, in simulation: at 20 Hz updates multi-rate extrapolation keeps the hand's
// contact stable; a zero-order hold of f alone in the same setting does not.
TEST(HapticsStudy, MultirateStableAt20HzWhereZeroOrderHoldIsNot) {
    Volume box = makeBox(48);
    SurfaceSite site = boxTopSite(box);
    HapticsStudyConfig config;
    config.durationS = 1.0;
    for (double latency : {0.0, 25.0}) {
        HapticsCaseResult mr =
            runHapticsCase(box, site, config, {HapticMethod::Multirate, 20.0, latency});
        HapticsCaseResult zoh =
            runHapticsCase(box, site, config, {HapticMethod::ZeroOrderHold, 20.0, latency});
        EXPECT_TRUE(mr.stable) << hapticsCsvRow(mr);
        EXPECT_LT(mr.energyInjectedJ, config.maxEnergyInjectedJ);
        EXPECT_LE(mr.finalOscillationMm, 1.5 * mr.earlyOscillationMm + 0.01); // not growing
        EXPECT_LT(mr.maxPenetrationMm, config.hand.targetDepthMm);
        EXPECT_FALSE(zoh.stable) << hapticsCsvRow(zoh);
        EXPECT_GT(zoh.forceRmsErrorN, 10.0 * mr.forceRmsErrorN);
        EXPECT_GT(zoh.energyInjectedJ, 10.0 * std::max(mr.energyInjectedJ, 1e-6));
    }
}

TEST(HapticsStudy, BlendingWithoutTheGradientIsNotEnough) {
    Volume box = makeBox(48);
    SurfaceSite site = boxTopSite(box);
    HapticsStudyConfig config;
    config.durationS = 1.0;
    config.multirateUsesGradient = false;
    HapticsCaseResult r = runHapticsCase(box, site, config, {HapticMethod::Multirate, 20.0, 0.0});
    EXPECT_FALSE(r.stable) << hapticsCsvRow(r);
}

TEST(HapticsStudy, CsvHeaderIsExact) {
    EXPECT_EQ(hapticsCsvHeader().rfind("method,update_hz,latency_ms,force_rms_error_n,"
                                       "force_peak_error_n,energy_injected_j,stable",
                                       0),
              0u);
    HapticsCaseResult r;
    r.c = {HapticMethod::ZeroOrderHold, 20.0, 50.0};
    EXPECT_EQ(hapticsCsvRow(r).rfind("zoh,20,50,", 0), 0u);
}

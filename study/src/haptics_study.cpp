#include "study/haptics_study.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <deque>
#include <numbers>

namespace trephine::study {

const char* hapticMethodName(HapticMethod m) {
    return m == HapticMethod::Multirate ? "multirate" : "zoh";
}

std::string hapticsCsvHeader() {
    return "method,update_hz,latency_ms,force_rms_error_n,force_peak_error_n,energy_injected_j,"
           "stable,max_penetration_mm,final_oscillation_mm,mean_force_n,models";
}

std::string hapticsCsvRow(const HapticsCaseResult& r) {
    return fmt::format("{},{:g},{:g},{:.6f},{:.6f},{:.9f},{},{:.4f},{:.4f},{:.4f},{}",
                       hapticMethodName(r.c.method), r.c.updateHz, r.c.latencyMs, r.forceRmsErrorN,
                       r.forcePeakErrorN, r.energyInjectedJ, r.stable ? 1 : 0, r.maxPenetrationMm,
                       r.finalOscillationMm, r.meanForceN, r.modelsDelivered);
}

namespace {

struct PendingModel {
    double arrival;
    HapticModelData model;
};

double peakToPeak(const std::vector<double>& v, size_t from, size_t to) {
    if (from >= to || to > v.size())
        return 0.0;
    auto [lo, hi] = std::minmax_element(v.begin() + long(from), v.begin() + long(to));
    return *hi - *lo;
}

} // namespace

HapticsCaseResult runHapticsCase(const Volume& volume, const SurfaceSite& site,
                                 const HapticsStudyConfig& cfg, const HapticsCase& c) {
    const ForceModel model(cfg.shape, cfg.force);
    return runHapticsCase(volume, site, cfg, c, [&](const ToolPose& pose) {
        ForceResult r = model.compute(volume, pose);
        HapticModelData m;
        m.position = pose.position;
        m.force = r.force;
        m.gradient = r.gradient;
        m.contact = r.contact;
        return m;
    });
}

HapticsCaseResult runHapticsCase(const Volume& volume, const SurfaceSite& site,
                                 const HapticsStudyConfig& cfg, const HapticsCase& c,
                                 const HapticModelSource& source) {
    HapticsCaseResult out;
    out.c = c;
    const ForceModel model(cfg.shape, cfg.force);
    auto ask = [&](const ToolPose& p, uint32_t sequence) {
        HapticModelData m = source(p);
        if (!cfg.multirateUsesGradient)
            m.gradient = glm::mat3(0.0f);
        m.toolSequence = sequence;
        return m;
    };
    const HandModel& hand = cfg.hand;
    const glm::dvec3 n = glm::normalize(glm::dvec3(site.normal));
    // A tangent for the slide.
    glm::dvec3 tangent =
        glm::cross(n, std::abs(n.x) < 0.9 ? glm::dvec3(1, 0, 0) : glm::dvec3(0, 1, 0));
    tangent = glm::normalize(tangent);
    // Reference point to lowest point of the cutter along -axis.
    const double tipOffset = cfg.shape.sphere() ? 0.5 * cfg.shape.diameterMm : 0.0;
    const glm::dvec3 surface(site.position);
    auto penetration = [&](glm::dvec3 x) { return glm::dot(surface - x, n) + tipOffset; };
    ToolPose pose = ToolPose::fromAxis(site.position, site.normal);

    const double dt = 1.0 / cfg.hapticRateHz;
    const int ticks = int(std::lround(cfg.durationS * cfg.hapticRateHz));
    const double h = dt / cfg.handSubsteps;
    const double updatePeriod = 1.0 / c.updateHz;
    const double latency = c.latencyMs * 1e-3;

    // Start at rest where the hand's push and the contact force balance: the user is already
    // holding the tool against the bone, and both methods start from the exact model there.
    auto atDepth = [&](double depth) { return surface + n * (tipOffset - depth); };
    auto normalForce = [&](double depth) {
        ToolPose p = pose;
        p.position = glm::vec3(atDepth(depth));
        return glm::dot(glm::dvec3(model.compute(volume, p).force), n);
    };
    double lo = 0.0, hi = hand.targetDepthMm;
    for (int it = 0; it < 40; ++it) {
        double mid = 0.5 * (lo + hi);
        (normalForce(mid) < hand.stiffnessNPerMm * (hand.targetDepthMm - mid) ? lo : hi) = mid;
    }
    glm::dvec3 x = atDepth(std::max(hand.startDepthMm, 0.5 * (lo + hi)));
    glm::dvec3 v(0.0);
    BlendConfig blend = cfg.blend;
    blend.maxForceN = cfg.force.maxForceN;
    ModelBlender blender(blend);
    pose.position = glm::vec3(x);
    const HapticModelData start = ask(pose, 0);
    blender.resetTo(start, 0.0);
    glm::vec3 held = start.force; // zero-order hold
    std::deque<PendingModel> inFlight;
    double nextSend = updatePeriod;

    double sumSq = 0.0, injectedNmm = 0.0, meanForce = 0.0;
    int meanCount = 0;
    std::vector<double> depthTrace;
    depthTrace.reserve(size_t(ticks));
    for (int i = 0; i < ticks; ++i) {
        const double t = i * dt;
        pose.position = glm::vec3(x);
        // The server samples P_N when the tool state is sent; its answer arrives `latency` later.
        if (t + 1e-12 >= nextSend) {
            inFlight.push_back({t + latency, ask(pose, uint32_t(i))});
            nextSend += updatePeriod;
        }
        while (!inFlight.empty() && inFlight.front().arrival <= t + 1e-12) {
            blender.setModel(inFlight.front().model, t);
            held = inFlight.front().model.force;
            inFlight.pop_front();
            out.modelsDelivered++;
        }
        glm::dvec3 displayed = c.method == HapticMethod::Multirate
                                   ? glm::dvec3(blender.update(pose.position, t))
                                   : glm::dvec3(clampForce(held, cfg.force.maxForceN));
        const glm::dvec3 truth(model.compute(volume, pose).force);
        const double err = glm::length(displayed - truth);
        sumSq += err * err;
        out.forcePeakErrorN = std::max(out.forcePeakErrorN, err);
        if (i >= ticks / 2) {
            meanForce += glm::length(displayed);
            ++meanCount;
        }

        // The hand over one tick, the device force held (the device's own zero-order hold).
        const glm::dvec3 x0 = x;
        for (int s = 0; s < cfg.handSubsteps; ++s) {
            const double ts = t + s * h;
            const double tremor =
                hand.tremorMm * std::sin(2.0 * std::numbers::pi * hand.tremorHz * ts);
            const glm::dvec3 target = surface + n * (tipOffset - hand.targetDepthMm + tremor) +
                                      tangent * (hand.slideMmPerS * ts);
            const glm::dvec3 fHand = hand.stiffnessNPerMm * (target - x) - hand.dampingNsPerMm * v;
            const glm::dvec3 acc = (fHand + displayed) / hand.massKg * 1000.0; // mm/s^2
            v += acc * h;
            x += v * h;
        }
        injectedNmm += glm::dot(displayed - truth, x - x0);
        const double depth = penetration(x);
        out.maxPenetrationMm = std::max(out.maxPenetrationMm, depth);
        depthTrace.push_back(depth);
    }
    out.forceRmsErrorN = std::sqrt(sumSq / std::max(1, ticks));
    out.energyInjectedJ = injectedNmm * 1e-3;
    out.meanForceN = meanCount ? meanForce / meanCount : 0.0;
    const size_t window = size_t(std::lround(0.25 * cfg.hapticRateHz));
    const size_t half = depthTrace.size() / 2;
    out.finalOscillationMm = peakToPeak(
        depthTrace, depthTrace.size() - std::min(window, depthTrace.size()), depthTrace.size());
    out.earlyOscillationMm =
        peakToPeak(depthTrace, half, std::min(half + window, depthTrace.size()));
    const bool bounded = out.maxPenetrationMm <= hand.targetDepthMm + cfg.maxOvershootMm;
    const bool notGrowing = out.finalOscillationMm <= cfg.maxFinalOscillationMm;
    const bool passive = out.energyInjectedJ <= cfg.maxEnergyInjectedJ;
    out.stable = bounded && notGrowing && passive && std::isfinite(out.forceRmsErrorN);
    return out;
}

} // namespace trephine::study

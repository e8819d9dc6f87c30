#include "study/haptics_study.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <deque>
#include <numbers>

namespace trephine::study {

const char* hapticMethodName(HapticMethod m) {
    switch (m) {
    case HapticMethod::Multirate:
        return "multirate";
    case HapticMethod::ZeroOrderHold:
        return "zoh";
    case HapticMethod::Exact:
        break;
    }
    return "exact";
}

std::string hapticsCsvHeader() {
    return "method,update_hz,latency_ms,force_rms_error_n,force_peak_error_n,energy_injected_j,"
           "stable,max_penetration_mm,final_oscillation_mm,mean_force_n,models,"
           "reference_oscillation_mm,excess_oscillation_mm";
}

std::string hapticsCsvRow(const HapticsCaseResult& r) {
    return fmt::format("{},{:g},{:g},{:.6f},{:.6f},{:.9f},{},{:.4f},{:.4f},{:.4f},{},{:.4f},{:.4f}",
                       hapticMethodName(r.c.method), r.c.updateHz, r.c.latencyMs, r.forceRmsErrorN,
                       r.forcePeakErrorN, r.energyInjectedJ, r.stable ? 1 : 0, r.maxPenetrationMm,
                       r.finalOscillationMm, r.meanForceN, r.modelsDelivered,
                       r.referenceOscillationMm, r.excessOscillationMm);
}

SpringHand::SpringHand(const HandModel& model, const HandFrame& frame, glm::dvec3 start,
                       int substeps)
    : m_model(model), m_frame(frame), m_x(start), m_substeps(std::max(1, substeps)) {}

glm::dvec3 handTarget(const HandModel& model, const HandFrame& frame, double t) {
    const double tremor = model.tremorMm * std::sin(2.0 * std::numbers::pi * model.tremorHz * t);
    return frame.atDepth(model.targetDepthMm - tremor) + frame.tangent * (model.slideMmPerS * t);
}

void SpringHand::advance(glm::dvec3 forceN, double t, double dt) {
    const double h = dt / m_substeps;
    for (int s = 0; s < m_substeps; ++s) {
        const glm::dvec3 target = handTarget(m_model, m_frame, t + s * h);
        const glm::dvec3 fHand =
            m_model.stiffnessNPerMm * (target - m_x) - m_model.dampingNsPerMm * m_v;
        m_v += (fHand + forceN) / m_model.massKg * 1000.0 * h; // mm/s^2
        m_x += m_v * h;
    }
}

namespace {

struct PendingModel {
    double arrival;
    HapticModelData model;
    bool ofThisRun = true; // false: sent before the run started
};

double peakToPeak(const std::vector<double>& v, size_t from, size_t to) {
    if (from >= to || to > v.size())
        return 0.0;
    auto [lo, hi] = std::minmax_element(v.begin() + long(from), v.begin() + long(to));
    return *hi - *lo;
}

// What the display adds to the hand's motion, as an oscillation: this run's depth less the
// reference's, less that difference's centred running mean over one tremor period. A slow offset
// from a force error (a stale model on a sliding contact) is the force error's, not an oscillation.
std::vector<double> oscillation(const std::vector<double>& depth,
                                const std::vector<double>& reference,
                                const HapticsStudyConfig& cfg) {
    const size_t n = std::min(depth.size(), reference.size());
    const double periodS = cfg.hand.tremorHz > 0.0 ? 1.0 / cfg.hand.tremorHz : 0.125;
    const size_t half = size_t(std::lround(0.5 * periodS * cfg.hapticRateHz));
    std::vector<double> sum(n + 1, 0.0); // prefix sums of the difference
    for (size_t i = 0; i < n; ++i)
        sum[i + 1] = sum[i] + depth[i] - reference[i];
    std::vector<double> out(n);
    for (size_t i = 0; i < n; ++i) {
        const size_t a = i > half ? i - half : 0, b = std::min(n, i + half + 1);
        out[i] = depth[i] - reference[i] - (sum[b] - sum[a]) / double(b - a);
    }
    return out;
}

HandFrame handFrame(const SurfaceSite& site, const ToolShape& shape) {
    HandFrame f;
    f.surface = glm::dvec3(site.position);
    f.normal = glm::normalize(glm::dvec3(site.normal));
    const glm::dvec3 n = f.normal;
    f.tangent = glm::normalize(
        glm::cross(n, std::abs(n.x) < 0.9 ? glm::dvec3(1, 0, 0) : glm::dvec3(0, 1, 0)));
    f.tipOffsetMm = shape.sphere() ? 0.5 * shape.diameterMm : 0.0;
    return f;
}

// At rest where the hand's push and the contact force balance: the user is already holding the
// tool against the bone, and every method starts from the exact model there.
glm::dvec3 restingPosition(const Volume& volume, const HandFrame& frame, const HandModel& hand,
                           const ForceModel& model, const ToolPose& pose) {
    auto normalForce = [&](double depth) {
        ToolPose p = pose;
        p.position = glm::vec3(frame.atDepth(depth));
        return glm::dot(glm::dvec3(model.compute(volume, p).force), frame.normal);
    };
    double lo = 0.0, hi = hand.targetDepthMm;
    for (int it = 0; it < 40; ++it) {
        const double mid = 0.5 * (lo + hi);
        (normalForce(mid) < hand.stiffnessNPerMm * (hand.targetDepthMm - mid) ? lo : hi) = mid;
    }
    return frame.atDepth(std::max(hand.startDepthMm, 0.5 * (lo + hi)));
}

// The device's force each tick by one method: the models the client has received (sampled every
// update period, each arriving `latency` later), or the exact force.
class Display {
public:
    Display(const HapticsStudyConfig& cfg, const HapticsCase& c,
            std::function<HapticModelData(const ToolPose&, uint32_t)> ask,
            const HapticModelData& start)
        : m_c(c), m_ask(std::move(ask)), m_maxForceN(cfg.force.maxForceN),
          m_period(1.0 / c.updateHz), m_latency(c.latencyMs * 1e-3), m_nextSend(m_period),
          m_blender(blendConfig(cfg)), m_held(start.force) {
        m_blender.resetTo(start, 0.0);
        // The hand has rested there before the run: the answers to the tool states sent over the
        // last round trip are still on their way (without them a round trip over the blender's
        // stale timeout faded the force out at the start).
        for (double sent = -std::floor(m_latency / m_period) * m_period; sent <= 0.0;
             sent += m_period)
            if (sent + m_latency > 1e-12)
                m_inFlight.push_back({sent + m_latency, start, false});
    }

    glm::dvec3 tick(int i, double t, const ToolPose& pose, glm::dvec3 exact) {
        if (m_c.method == HapticMethod::Exact)
            return exact;
        // The server samples P_N when the tool state is sent; its answer arrives `latency` later.
        if (t + 1e-12 >= m_nextSend) {
            m_inFlight.push_back({t + m_latency, m_ask(pose, uint32_t(i))});
            m_nextSend += m_period;
        }
        while (!m_inFlight.empty() && m_inFlight.front().arrival <= t + 1e-12) {
            m_blender.setModel(m_inFlight.front().model, t);
            m_held = m_inFlight.front().model.force;
            m_delivered += m_inFlight.front().ofThisRun;
            m_inFlight.pop_front();
        }
        return m_c.method == HapticMethod::Multirate
                   ? glm::dvec3(m_blender.update(pose.position, t))
                   : glm::dvec3(clampForce(m_held, m_maxForceN));
    }
    int delivered() const { return m_delivered; }

private:
    static BlendConfig blendConfig(const HapticsStudyConfig& cfg) {
        BlendConfig b = cfg.blend;
        b.maxForceN = cfg.force.maxForceN;
        return b;
    }

    HapticsCase m_c;
    std::function<HapticModelData(const ToolPose&, uint32_t)> m_ask;
    float m_maxForceN;
    double m_period, m_latency, m_nextSend;
    ModelBlender m_blender;
    glm::vec3 m_held; // zero-order hold
    std::deque<PendingModel> m_inFlight;
    int m_delivered = 0;
};

// One run's record, before it is judged.
struct Run {
    HapticsCaseResult result;  // all but the verdict and the reference's figures
    std::vector<double> depth; // penetration after each tick
};

Run simulate(const Volume& volume, const SurfaceSite& site, const HapticsStudyConfig& cfg,
             const HapticsCase& c, const HapticModelSource& source) {
    Run run;
    HapticsCaseResult& out = run.result;
    out.c = c;
    const ForceModel model(cfg.shape, cfg.force);
    auto ask = [&](const ToolPose& p, uint32_t sequence) {
        HapticModelData m = source(p);
        if (!cfg.multirateUsesGradient)
            m.gradient = glm::mat3(0.0f);
        m.toolSequence = sequence;
        return m;
    };
    const HandFrame frame = handFrame(site, cfg.shape);
    ToolPose pose = ToolPose::fromAxis(site.position, site.normal);
    const glm::dvec3 start = restingPosition(volume, frame, cfg.hand, model, pose);
    std::unique_ptr<StudyHand> hand =
        cfg.makeHand ? cfg.makeHand(frame, start)
                     : std::make_unique<SpringHand>(cfg.hand, frame, start, cfg.handSubsteps);
    pose.position = glm::vec3(start);
    // The exact reference asks no source: it may run where the source is a server.
    Display display(cfg, c, ask,
                    c.method == HapticMethod::Exact ? HapticModelData{} : ask(pose, 0));

    const double dt = 1.0 / cfg.hapticRateHz;
    const int ticks = int(std::lround(cfg.durationS * cfg.hapticRateHz));
    double sumSq = 0.0, injectedNmm = 0.0, meanForce = 0.0;
    int meanCount = 0;
    run.depth.reserve(size_t(ticks));
    for (int i = 0; i < ticks; ++i) {
        const double t = i * dt;
        const glm::dvec3 x0 = hand->position();
        pose.position = glm::vec3(x0);
        const glm::dvec3 truth(model.compute(volume, pose).force);
        const glm::dvec3 displayed = display.tick(i, t, pose, truth);
        const double err = glm::length(displayed - truth);
        sumSq += err * err;
        out.forcePeakErrorN = std::max(out.forcePeakErrorN, err);
        if (i >= ticks / 2) {
            meanForce += glm::length(displayed);
            ++meanCount;
        }
        hand->advance(displayed, t, dt);
        injectedNmm += glm::dot(displayed - truth, hand->position() - x0);
        const double depth = frame.penetration(hand->position());
        out.maxPenetrationMm = std::max(out.maxPenetrationMm, depth);
        run.depth.push_back(depth);
    }
    out.forceRmsErrorN = std::sqrt(sumSq / std::max(1, ticks));
    out.energyInjectedJ = injectedNmm * 1e-3;
    out.meanForceN = meanCount ? meanForce / meanCount : 0.0;
    out.modelsDelivered = display.delivered();
    return run;
}

// Fills the oscillation figures and the verdict of `run` against the Exact run `reference`.
HapticsCaseResult judge(const Run& run, const Run& reference, const HapticsStudyConfig& cfg) {
    HapticsCaseResult out = run.result;
    const std::vector<double>& d = run.depth;
    const size_t window = std::min(size_t(std::lround(0.25 * cfg.hapticRateHz)), d.size());
    const size_t half = d.size() / 2;
    out.finalOscillationMm = peakToPeak(d, d.size() - window, d.size());
    out.earlyOscillationMm = peakToPeak(d, half, std::min(half + window, d.size()));
    const std::vector<double>& r = reference.depth;
    out.referenceOscillationMm = peakToPeak(r, r.size() - std::min(window, r.size()), r.size());
    const std::vector<double> added = oscillation(d, r, cfg); // same length: same ticks
    out.excessOscillationMm = peakToPeak(added, added.size() - window, added.size());
    const bool bounded = out.maxPenetrationMm <= cfg.hand.targetDepthMm + cfg.maxOvershootMm;
    const bool calm = out.excessOscillationMm <= cfg.maxExcessOscillationMm;
    const bool passive = out.energyInjectedJ <= cfg.maxEnergyInjectedJ;
    out.stable = bounded && calm && passive && std::isfinite(out.forceRmsErrorN);
    return out;
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
    const Run run = simulate(volume, site, cfg, c, source);
    if (c.method == HapticMethod::Exact)
        return judge(run, run, cfg);
    return judge(run, simulate(volume, site, cfg, {HapticMethod::Exact, c.updateHz, 0.0}, source),
                 cfg);
}

} // namespace trephine::study

#include "libsim/haptics.h"

#include <algorithm>
#include <cassert>
#include <chrono>
#include <cmath>
#include <pthread.h>

namespace trephine {

// [SECTION] model and extrapolation

AffineForce AffineForce::fromModel(const HapticModelData& m) {
    return {glm::dvec3(m.position), glm::dvec3(m.force), glm::dmat3(m.gradient),
            glm::dvec3(m.force)};
}

glm::vec3 extrapolate(const HapticModelData& m, glm::vec3 p) {
    return m.force + m.gradient * (p - m.position);
}

glm::dvec3 unilateral(glm::dvec3 f, glm::dvec3 push) {
    const double strength = glm::length(push);
    if (!(strength > 0.0))
        return f;
    const glm::dvec3 u = push / strength;
    const double along = glm::dot(f, u);
    if (along >= 0.0)
        return f;
    return f - std::min(1.0, strength / kUnilateralFullN) * along * u;
}

glm::vec3 clampForce(glm::vec3 f, float maxN) {
    float mag = glm::length(f);
    if (!(mag <= maxN)) // also catches NaN: a NaN force never reaches a device
        return std::isfinite(mag) && mag > 0.0f ? f * (maxN / mag) : glm::vec3(0.0f);
    return f;
}

// [SECTION] blender

namespace {

bool allFinite(glm::vec3 v) {
    return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z);
}

} // namespace

void ModelBlender::reset() {
    *this = ModelBlender(m_config);
}

AffineForce ModelBlender::current() const {
    // A convex mix of two affine fields is affine; anchor it at the newer one.
    AffineForce out;
    out.anchor = m_to.anchor;
    out.force = (1.0 - m_alpha) * m_from.at(m_to.anchor) + m_alpha * m_to.force;
    out.gradient = (1.0 - m_alpha) * m_from.gradient + m_alpha * m_to.gradient;
    out.push = (1.0 - m_alpha) * m_from.push + m_alpha * m_to.push;
    return out;
}

void ModelBlender::setModel(const HapticModelData& m, double now) {
    // One NaN in the mix would stay in every later blend (0 * NaN is NaN) and clampForce would
    // zero the output for good: ignore such a model, and fade out if no good one follows.
    if (!allFinite(m.position) || !allFinite(m.force) || !allFinite(m.gradient[0]) ||
        !allFinite(m.gradient[1]) || !allFinite(m.gradient[2]))
        return;
    AffineForce next = AffineForce::fromModel(m);
    // A gradient beyond any contact's stiffness (a bug upstream, a hostile server) is scaled down
    // to kMaxGradientNPerMm: a 1e37 N/mm field held the device at the force limit, since no
    // bounded step can blend out of it in doubles.
    double norm = 0.0;
    for (int c = 0; c < 3; ++c)
        norm += glm::dot(next.gradient[c], next.gradient[c]);
    norm = std::sqrt(norm);
    if (norm > kMaxGradientNPerMm)
        next.gradient *= kMaxGradientNPerMm / norm;
    if (m_hasModel) {
        m_from = current();
    } else {
        m_from = AffineForce{next.anchor, glm::dvec3(0.0), glm::dmat3(0.0), glm::dvec3(0.0)};
    }
    m_to = next;
    m_alpha = 0.0;
    estimateDelay(m.position, now);
    if (m_config.blendTimeS > 0.0) {
        m_blendTime = m_config.blendTimeS;
    } else {
        const double interval = m_hasModel ? now - m_lastModelTime : 0.0;
        const double forDelay =
            m_config.delayBlendScaleS > 0.0 ? m_delay * m_delay / m_config.delayBlendScaleS : 0.0;
        m_blendTime =
            std::clamp(std::max(interval, forDelay), m_config.minBlendS, m_config.maxBlendS);
    }
    m_prevModelTime = m_lastModelTime;
    m_lastModelTime = now;
    m_hasModel = true;
    m_fading = false;
}

void ModelBlender::resetTo(const HapticModelData& m, double now) {
    setModel(m, now);
    m_alpha = 1.0;
}

void ModelBlender::remember(glm::vec3 p, double now) {
    if (m_history.size() < kHistory) {
        m_history.push_back({now, p});
    } else {
        m_history[m_historyNext] = {now, p};
        m_historyNext = (m_historyNext + 1) % kHistory;
    }
}

void ModelBlender::estimateDelay(glm::vec3 anchor, double now) {
    // The server computes at the position the tool state carried, which is the device position
    // of the tick that sent it, bit for bit: the newest tick there is when it was sent.
    const size_t n = m_history.size();
    for (size_t back = 1; back <= n; ++back) {
        const Tick& tick = m_history[(m_historyNext + n - back) % n];
        if (tick.position != anchor)
            continue;
        if (back > 1) // else the device has stayed there: the sending tick is ambiguous
            m_delay = std::max(0.0, now - tick.time);
        return;
    }
}

glm::vec3 ModelBlender::update(glm::vec3 p, double now) {
    const double dt = m_ticked ? std::max(0.0, now - m_lastTick) : 0.0;
    m_lastTick = now;
    m_ticked = true;
    remember(p, now);
    if (!m_hasModel)
        return glm::vec3(0.0f);
    // A position that is not a number gives no force and leaves the blend where it is: the step
    // shortening below met a NaN distance, and std::min(1, NaN) finished the blend in one tick.
    if (!allFinite(p))
        return glm::vec3(0.0f);
    const glm::dvec3 pd(p);
    if (!m_fading && now - m_lastModelTime > m_config.staleTimeoutS) {
        // Fading is a blend towards the zero field.
        m_from = current();
        m_to = AffineForce{m_from.anchor, glm::dvec3(0.0), glm::dmat3(0.0), m_from.push};
        m_alpha = 0.0;
        m_blendTime = m_config.fadeTimeS;
        m_fading = true;
    }
    const glm::dvec3 fromF = m_from.at(pd), toF = m_to.at(pd);
    // The mix at alpha a, made unilateral (`unilateral`) against the same mix of the pushes: at a
    // new model nothing changes (its `from` is the mix of the moment, push included).
    auto mixAt = [&](double a) {
        const glm::dvec3 f = (1.0 - a) * fromF + a * toF;
        return m_config.unilateral ? unilateral(f, (1.0 - a) * m_from.push + a * m_to.push) : f;
    };
    // The output at alpha a: clamped to maxForceN in doubles (a huge but finite field, 1e37 N/mm,
    // overflowed a float to infinity, which clampForce takes for a NaN and zeroes).
    const double maxN = m_config.maxForceN;
    auto outAt = [&](double a) {
        const glm::dvec3 f = mixAt(a);
        const double mag = glm::length(f);
        return mag > maxN ? f * (maxN / mag) : f;
    };
    if (m_alpha < 1.0 && dt > 0.0) {
        // The step the blend time allows, shortened until the output (as the device feels it,
        // clamped) moves at most maxStepN. Bounded by the unclamped fields, a blend away from a
        // huge field would stall (its step would be maxStepN / 1e37).
        double step = m_blendTime > 0.0 ? dt / m_blendTime : 1.0;
        const glm::dvec3 now0 = outAt(m_alpha);
        for (int i = 0; i < 60; ++i) {
            const double moved = glm::length(outAt(std::min(1.0, m_alpha + step)) - now0);
            if (moved <= m_config.maxStepN)
                break;
            step *= 0.9 * m_config.maxStepN / moved;
        }
        m_alpha = std::min(1.0, m_alpha + step);
    }
    return clampForce(glm::vec3(outAt(m_alpha)), m_config.maxForceN);
}

// [SECTION] recorder

void HapticRecorder::add(const HapticSample& s) {
    if (m_capacity == 0)
        return;
    if (m_ring.size() < m_capacity) {
        m_ring.push_back(s);
    } else {
        m_ring[m_next] = s;
        m_next = (m_next + 1) % m_capacity;
    }
}

std::vector<HapticSample> HapticRecorder::samples() const {
    std::vector<HapticSample> out;
    out.reserve(m_ring.size());
    for (size_t i = 0; i < m_ring.size(); ++i)
        out.push_back(m_ring[(m_next + i) % m_ring.size()]);
    return out;
}

// [SECTION] haptic loop

HapticLoop::HapticLoop(Device& device, HapticLoopConfig config, SendToolState send)
    : m_device(device), m_config(config), m_send(std::move(send)), m_blender(config.blend),
      m_recorder(config.recorderCapacity), m_sendRateHz(config.sendRateHz) {
    assert(config.rateHz > 0.0 && "HapticLoopConfig::rateHz must be positive");
    setSendRate(config.sendRateHz);
}

HapticLoop::~HapticLoop() {
    stop();
}

void HapticLoop::setSendRate(double hz) {
    // std::clamp lets NaN through, and one NaN period would make every later send time NaN, so
    // no tool state would be sent again.
    m_sendRateHz = std::isnan(hz) ? 20.0 : std::clamp(hz, 20.0, 1000.0);
}

bool NewestModel::offer(const HapticModelData& model, double arrivedAt) {
    std::lock_guard lock(m_mutex);
    // Two models within one tick may come reversed: the one answering the older tool state must
    // not replace the newer one still waiting.
    if (m_pending && int32_t(model.toolSequence - m_pending->first.toolSequence) < 0)
        return false;
    m_pending = std::make_pair(model, arrivedAt);
    return true;
}

NewestModel::Taken NewestModel::take() {
    Taken t;
    {
        std::lock_guard lock(m_mutex);
        t.model.swap(m_pending);
    }
    if (t.model && m_any && int32_t(t.model->first.toolSequence - m_lastSequence) < 0) {
        t.model.reset();
        t.dropped = true;
    }
    if (t.model) {
        m_lastSequence = t.model->first.toolSequence;
        m_any = true;
    }
    return t;
}

void HapticLoop::setModel(const HapticModelData& model, double now) {
    if (!m_models.offer(model, now)) {
        std::lock_guard statsLock(m_statsMutex);
        m_stats.modelsDropped++;
    }
}

HapticSample HapticLoop::step(double now) {
    const NewestModel::Taken taken = m_models.take();
    const auto& pending = taken.model;
    const bool dropped = taken.dropped;
    bool gotModel = false;
    if (pending) {
        m_blender.setModel(pending->first, pending->second);
        m_lastModelForce = pending->first.force;
        gotModel = true;
    }

    const DeviceState state = m_device.read(now);
    glm::vec3 force(0.0f);
    if (state.valid) {
        if (m_source)
            force = clampForce(m_source->force(state.pose, now), m_config.blend.maxForceN);
        else
            force = m_blender.update(state.pose.position, now);
    }
    m_device.setForce(force);

    bool sent = false;
    const double period = 1.0 / m_sendRateHz.load();
    if (m_nextSend < 0.0)
        m_nextSend = now;
    if (state.valid && now + 1e-9 >= m_nextSend) {
        if (m_send)
            m_send(state, now);
        sent = true;
        m_nextSend += period;
        if (m_nextSend <= now)
            m_nextSend = now + period;
    }

    HapticSample s;
    s.time = now;
    s.force = force;
    s.forceN = glm::length(force);
    s.modelForce = m_lastModelForce;
    if (state.valid)
        m_lastPosition = state.pose.position;
    s.position = m_lastPosition; // a missed read's pose is no place the hand went
    s.missed = !state.valid;
    s.stale = m_blender.stale();
    std::lock_guard lock(m_statsMutex);
    m_recorder.add(s);
    if (m_firstTick < 0.0)
        m_firstTick = now;
    m_lastTick = now;
    m_stats.ticks++;
    m_stats.sent += sent;
    m_stats.models += gotModel;
    m_stats.modelsDropped += dropped;
    return s;
}

void HapticLoop::start() {
    if (m_thread.joinable())
        return;
    m_stop = false;
    m_thread = std::thread([this] { run(); });
}

void HapticLoop::stop() {
    m_stop = true;
    if (m_thread.joinable())
        m_thread.join();
}

void HapticLoop::run() {
    pthread_setname_np(pthread_self(), "haptics");
    using Clock = std::chrono::steady_clock;
    // One timeline across stop() and start(): a clock restarting from 0 sent no tool state and
    // froze the blend until it passed the times the throttle and the blender held from before.
    if (!m_clockStart)
        m_clockStart = Clock::now();
    const auto t0 = *m_clockStart;
    const auto period = std::chrono::duration_cast<Clock::duration>(
        std::chrono::duration<double>(1.0 / m_config.rateHz));
    auto next = Clock::now();
    while (!m_stop.load(std::memory_order_relaxed)) {
        std::this_thread::sleep_until(next);
        const auto actual = Clock::now();
        const double late = std::chrono::duration<double, std::milli>(actual - next).count();
        {
            std::lock_guard lock(m_statsMutex);
            m_lateness.add(late);
        }
        step(std::chrono::duration<double>(actual - t0).count());
        next += period;
        // After a long stall (a suspended VM), resume the schedule rather than burst to catch up.
        if (actual - next > 20 * period)
            next = actual + period;
    }
    m_device.setForce(glm::vec3(0.0f));
}

HapticLoopStats HapticLoop::stats() const {
    std::lock_guard lock(m_statsMutex);
    HapticLoopStats s = m_stats;
    if (s.ticks > 1 && m_lastTick > m_firstTick)
        s.achievedRateHz = double(s.ticks - 1) / (m_lastTick - m_firstTick);
    s.latenessP50Ms = m_lateness.percentile(50.0);
    s.latenessP99Ms = m_lateness.percentile(99.0);
    return s;
}

std::vector<HapticSample> HapticLoop::samples() const {
    std::lock_guard lock(m_statsMutex);
    return m_recorder.samples();
}

} // namespace trephine

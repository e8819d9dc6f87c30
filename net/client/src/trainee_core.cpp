#include "net/trainee_core.h"

#include "libsim/error.h"
#include "libsim/tool_catalogue.h"
#include "net/net_stats.h"
#include "net/tool_model.h"

#include <algorithm>
#include <cassert>
#include <cmath>
#include <glm/gtc/quaternion.hpp>
#include <numbers>
#include <thread>

namespace trephine::net {

// [SECTION] script

ScriptToolSource::ScriptToolSource(Device& device, std::vector<ScriptSample> script, double endS)
    : m_device(device), m_script(std::move(script)), m_endS(endS) {
    assert(!m_script.empty() && "ScriptToolSource: a script needs at least one row");
}

const ScriptSample& ScriptToolSource::sampleAt(double t) const {
    auto it = std::upper_bound(m_script.begin(), m_script.end(), t,
                               [](double v, const ScriptSample& s) { return v < s.t; });
    return it == m_script.begin() ? m_script.front() : *std::prev(it);
}

void ScriptToolSource::noteButtons(uint32_t buttons, double now) {
    const uint32_t pressed = buttons & ~m_buttons;
    m_buttons = buttons;
    if (pressed & 1u)
        m_drilling = !toolAt(ToolPose{}, now).drilling;
    if (pressed & 2u)
        ++m_nextTools;
}

ToolState ScriptToolSource::toolAt(const ToolPose& pose, double now) {
    ToolState t = sampleAt(now).tool;
    if (m_nextTools) {
        const ToolType& next = toolType(ToolKind((t.toolKind + m_nextTools) % kToolKindCount));
        t.toolKind = uint8_t(next.kind);
        t.diameterMm = next.defaultDiameterMm;
    }
    if (m_drilling) {
        t.drilling = *m_drilling;
        t.speed = *m_drilling ? 1.0f : 0.0f;
    }
    if (now >= m_endS) {
        t.speed = 0.0f; // the script is over: no more drilling
        t.drilling = false;
    }
    t.position = pose.position;
    t.orientation = pose.orientation;
    return t;
}

glm::vec3 ScriptToolSource::velocity(const ToolPose& pose, double now) {
    return m_velocity.update(pose.position, now);
}

std::optional<ToolPose> ScriptToolSource::intent(double now) {
    auto next = std::upper_bound(m_script.begin(), m_script.end(), now,
                                 [](double v, const ScriptSample& s) { return v < s.t; });
    const ToolState& b = (next == m_script.end() ? m_script.back() : *next).tool;
    const ToolState& a = (next == m_script.begin() ? m_script.front() : *std::prev(next)).tool;
    const double ta = next == m_script.begin() ? now : std::prev(next)->t;
    const double tb = next == m_script.end() ? ta : next->t;
    const float u = tb > ta ? float(std::clamp((now - ta) / (tb - ta), 0.0, 1.0)) : 0.0f;
    return ToolPose{glm::mix(a.position, b.position, u),
                    glm::slerp(a.orientation, b.orientation, u)};
}

// [SECTION] force

glm::vec3 TraineeForce::force(const ToolPose& pose, double now) {
    followLinks();
    glm::vec3 f = feltForce(pose, now) +
                  zoneBuzz(m_zone, now, pose.orientation * glm::vec3(0.0f, 0.0f, 1.0f));
    if (m_guide || m_guideRamp.pulling()) {
        f += m_guideRamp.force(m_guide, pose.position, m_guideVelocity.update(pose.position, now),
                               now, m_guideConfig);
        m_guidedTicks.fetch_add(1, std::memory_order_relaxed);
    }
    return f;
}

// The force of the bone: another participant's when this instructor feels one, else the local
// model (volume design) or the server's models extrapolated (multi-rate).
glm::vec3 TraineeForce::feltForce(const ToolPose& pose, double now) {
    const NewestModel::Taken taken = m_serverModel.take();
    if (m_felt) {
        // Its newest relayed model, as its own force: the gradient is about its tool, not ours.
        auto relayed = m_linkSnap->relayedModels.find(m_felt);
        if (relayed != m_linkSnap->relayedModels.end() &&
            relayed->second.toolSequence != m_feltSequence) {
            m_feltSequence = relayed->second.toolSequence;
            HapticModelData d = toModelData(relayed->second);
            d.gradient = glm::mat3(0.0f);
            m_blender.setModel(d, now);
        }
        m_feltTicks.fetch_add(1, std::memory_order_relaxed);
        return m_blender.update(pose.position, now);
    }
    if (taken.model)
        m_blender.setModel(taken.model->first, now);
    const glm::vec3 extrapolated = m_blender.update(pose.position, now);
    if (m_local.load(std::memory_order_relaxed) && m_client) {
        const ToolState t = m_tools.toolAt(pose, now);
        glm::vec3 f(0.0f);
        try {
            const ForceModel& model = m_models.get(shapeOf(t));
            m_toolsUsed.store(m_models.size(), std::memory_order_relaxed);
            const float speed = t.drilling ? t.speed : 0.0f;
            const glm::vec3 velocity = m_tools.velocity(pose, now);
            if (m_client->withLocalVolume(
                    [&](const Volume& v) { f = model.compute(v, pose, speed, velocity).force; })) {
                m_localTicks.fetch_add(1, std::memory_order_relaxed);
                return f;
            }
        } catch (const Error&) {
            // A shape the factories refuse: no local model; the server's is all there is.
        }
    }
    m_serverTicks.fetch_add(1, std::memory_order_relaxed);
    return extrapolated;
}

glm::vec3 zoneBuzz(Zone zone, double now, glm::vec3 axis) {
    const float amplitude = zone == Zone::Violation ? 0.6f : zone == Zone::Danger ? 0.3f : 0.0f;
    if (amplitude == 0.0f)
        return glm::vec3(0.0f);
    // One-sided, back up the shaft: a buzz never pushes the tool toward the structure.
    const float wave = 0.5f + 0.5f * float(std::sin(2.0 * std::numbers::pi * 60.0 * now));
    return axis * (amplitude * wave);
}

// A new snapshot (at most 100 a second) may change the links; the same one changes nothing.
void TraineeForce::followLinks() {
    if (!m_client)
        return;
    std::shared_ptr<const ClientSnapshot> snap = m_client->snapshot();
    if (snap == m_linkSnap)
        return;
    m_linkSnap = std::move(snap);
    m_guide = guideTarget(*m_linkSnap);
    const uint16_t self = m_linkSnap->welcome ? m_linkSnap->welcome->clientId : 0;
    const auto warning = m_linkSnap->warnings.find(self);
    m_zone = warning == m_linkSnap->warnings.end() ? Zone::Clear : warning->second.zone;
    const uint16_t felt = feltParticipant(*m_linkSnap);
    if (felt != m_felt)
        m_feltSequence = 0; // a new participant's models: take its newest, whatever its number
    m_felt = felt;
}

// [SECTION] core

TraineeCore::TraineeCore(TraineeCoreConfig config) : m_config(std::move(config)) {
    m_config.client.onHapticModel = [this](const HapticModel& m) { onModel(m); };
    m_client = std::make_unique<ClientThread>(m_config.client);
}

TraineeCore::~TraineeCore() {
    stop();
}

void TraineeCore::connect() {
    m_client->start();
}

void TraineeCore::startHaptics(ToolSource& tools) {
    assert(!m_loop && "TraineeCore::startHaptics: the loop runs once");
    m_force = std::make_unique<TraineeForce>(tools, m_config.haptics.blend);
    m_force->setClient(m_client.get());
    m_force->setLocal(m_config.client.client.sync == Sync::Volume);
    m_guard = std::make_unique<DeviceGuard>(tools.device(), m_config.guard);
    // Never driven while the link is down, or silent (a server gone without a goodbye, which ENet
    // notices only after 5-30 s): the guide, the buzz and the forces it would feel are stale. The
    // client pings every 250 ms, so a second of silence is four answers missed.
    m_guard->setGate([this] {
        const std::shared_ptr<const ClientSnapshot> s = m_client->snapshot();
        const ClientConfig& cc = m_config.client.client;
        const uint64_t now = cc.clock ? cc.clock() : steadyNowUs();
        return s->state == LinkState::Connected && now - s->lastHeardUs < kSilentLinkUs;
    });
    m_guard->setIntentSource([&tools](double now) { return tools.intent(now); });
    m_loop = std::make_unique<HapticLoop>(*m_guard, m_config.haptics,
                                          [this, &tools](const DeviceState& s, double now) {
                                              tools.noteButtons(s.buttons, now);
                                              ToolState t = tools.toolAt(s.pose, now);
                                              // The device sample: the server's step and velocity
                                              // follow the loop's sampling, and the force round
                                              // trip starts here, not when the client thread sends
                                              // it.
                                              t.clientTimeUs = steadyNowUs();
                                              m_client->sendToolState(t);
                                          });
    m_loop->setForceSource(m_force.get());
    m_loopStartUs = steadyNowUs();
    m_loop->start();
    m_hapticsLive.store(true, std::memory_order_release);
}

void TraineeCore::onModel(const HapticModel& m) {
    if (!m_hapticsLive.load(std::memory_order_acquire))
        return;
    const HapticModelData d = toModelData(m);
    // The loop's clock counts from its start (within microseconds of m_loopStartUs).
    m_loop->setModel(d, double(int64_t(steadyNowUs()) - int64_t(m_loopStartUs)) * 1e-6);
    m_force->setModel(d);
}

void TraineeCore::stopHaptics() {
    if (m_loop)
        m_loop->stop();
    if (m_guard && !m_guard->released())
        m_guard->release(); // the session is over for the device: zero, and never driven again
}

std::string TraineeCore::deviceFault() const {
    const auto* f = m_guard ? dynamic_cast<const ForceDevice*>(&m_guard->inner()) : nullptr;
    return f ? f->fault() : std::string();
}

void TraineeCore::stop() {
    stopHaptics();
    m_client->stop();
}

void TraineeCore::setLocalForces(bool local) {
    if (m_force)
        m_force->setLocal(local);
}

HapticLoopStats TraineeCore::hapticStats() const {
    return m_loop ? m_loop->stats() : HapticLoopStats{};
}

std::vector<HapticSample> TraineeCore::hapticSamples() const {
    return m_loop ? m_loop->samples() : std::vector<HapticSample>{};
}

ClientReportExtras TraineeCore::reportExtras() const {
    ClientReportExtras x;
    x.toolRateHz = m_config.haptics.sendRateHz;
    x.hapticRateHz = m_config.haptics.rateHz;
    x.haptics = hapticStats();
    x.localForceTicks = localForceTicks();
    x.serverForceTicks = serverForceTicks();
    return x;
}

// [SECTION] headless view

void HeadlessView::take(ClientThread& client, uint64_t hapticTicks) {
    const double now =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - m_t0).count();
    m_snap = client.snapshot();
    model.addSnapshot(m_snap, now);
    for (AppliedRect& r : client.drainRects()) {
        const std::optional<HeldPicture> held =
            hasPicture() ? std::optional(HeldPicture{m_viewId, {m_size, m_size}}) : std::nullopt;
        switch (picturePart(r, {m_size, m_size}, held)) {
        case PicturePart::Whole:
            m_dbi = r.pixels;
            m_viewId = r.viewId;
            break;
        case PicturePart::Rect:
            m_dbi.apply(r.pixels, r.rect.x, r.rect.y);
            break;
        case PicturePart::None:
            continue;
        }
        model.addRect(r, now);
        if (!r.full) // no display: on screen when applied
            model.addDrawn(designOf(m_snap->sync), r.latencyUs, r.appliedUs, r.appliedUs, r.bytes,
                           r.rawBytes);
    }
    model.tickComparison(now, designOf(m_snap->sync), hasPicture(), hapticTicks);
}

bool HeadlessView::waitFor(ClientThread& client, double seconds,
                           const std::function<bool()>& pred) {
    const uint64_t deadline = steadyNowUs() + uint64_t(seconds * 1e6);
    while (steadyNowUs() < deadline) {
        take(client, 0);
        if (pred())
            return true;
        if (m_snap->state == LinkState::Retrying)
            return false;
        std::this_thread::sleep_for(std::chrono::milliseconds(2));
    }
    return pred();
}

} // namespace trephine::net

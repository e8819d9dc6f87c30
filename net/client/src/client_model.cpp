#include "net/client_model.h"

#include "net/enet_host.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <glm/geometric.hpp>

namespace trephine::net {

namespace {
void pushCapped(std::vector<float>& v, float x, size_t n) {
    v.push_back(x);
    if (v.size() > n)
        v.erase(v.begin(), v.begin() + ptrdiff_t(v.size() - n));
}
} // namespace

// [SECTION] histories

void NetworkHistory::addUpdate(const Update& u) {
    updates.push_back(u);
    expire(u.t);
}

void NetworkHistory::addSecond(double imageBytesPerS, double toolBytesPerS, double hapticBytesPerS,
                               double updatesInS, double rttUs) {
    pushCapped(imageKbitPerS, float(imageBytesPerS * 8e-3), seriesLength);
    pushCapped(toolKbitPerS, float(toolBytesPerS * 8e-3), seriesLength);
    pushCapped(hapticKbitPerS, float(hapticBytesPerS * 8e-3), seriesLength);
    pushCapped(updatesPerS, float(updatesInS), seriesLength);
    pushCapped(rttMs, float(std::max(0.0, rttUs) * 1e-3), seriesLength);
}

void NetworkHistory::expire(double now) {
    while (!updates.empty() && updates.front().t < now - windowS)
        updates.pop_front();
}

double NetworkHistory::updateRate(double now) const {
    return double(std::count_if(updates.begin(), updates.end(),
                                [&](const Update& u) { return u.t > now - 1.0 && u.t <= now; }));
}

double NetworkHistory::compressionRatio() const {
    double raw = 0, wire = 0;
    for (const Update& u : updates) {
        raw += u.rawBytes;
        wire += u.bytes;
    }
    return wire > 0 ? raw / wire : 1.0;
}

std::vector<float> NetworkHistory::latencyHistogram(int buckets, double maxUs) const {
    std::vector<float> h(size_t(std::max(buckets, 1)), 0.0f);
    for (const Update& u : updates) {
        if (u.latencyUs < 0)
            continue;
        int b = int(u.latencyUs / maxUs * double(h.size()));
        h[size_t(std::clamp(b, 0, int(h.size()) - 1))] += 1.0f;
    }
    return h;
}

double NetworkHistory::latencyPercentile(double p) const {
    std::vector<double> v;
    for (const Update& u : updates)
        if (u.latencyUs >= 0)
            v.push_back(u.latencyUs);
    return v.empty() ? -1.0 : percentile(v, p);
}

std::string NetworkHistory::latencyCaption(double maxUs) const {
    auto ms = [](double us) {
        if (us < 0.0)
            return std::string("-");
        char b[32];
        std::snprintf(b, sizeof b, "%.1f ms", us * 1e-3);
        return std::string(b);
    };
    char range[48];
    std::snprintf(range, sizeof range, " (0-%.0f ms)", maxUs * 1e-3);
    return "delivery p50 " + ms(latencyPercentile(50)) + " p99 " + ms(latencyPercentile(99)) +
           range;
}

void ForceHistory::addServer(double t, glm::vec3 f) {
    server.push_back({t, f});
    expire(t);
}

void ForceHistory::addExtrapolated(double t, glm::vec3 f) {
    extrapolated.push_back({t, f});
    expire(t);
}

void ForceHistory::expire(double now) {
    for (auto* q : {&server, &extrapolated})
        while (!q->empty() && q->front().t < now - windowS)
            q->pop_front();
}

double ForceHistory::serverRate() const {
    if (server.size() < 2)
        return 0.0;
    double span = server.back().t - server.front().t;
    return span > 0 ? double(server.size() - 1) / span : 0.0;
}

std::vector<float> ForceHistory::series(const std::deque<Sample>& s, int component) {
    std::vector<float> out;
    out.reserve(s.size());
    for (const Sample& x : s)
        out.push_back(component >= 3 ? glm::length(x.f) : x.f[component]);
    return out;
}

std::vector<float> ForceHistory::resample(const std::deque<Sample>& s, int component, double t0,
                                          double t1, int n) {
    std::vector<float> out;
    if (s.empty() || n <= 0)
        return out;
    out.reserve(size_t(n));
    auto value = [&](const Sample& x) {
        return component >= 3 ? glm::length(x.f) : x.f[component];
    };
    size_t next = 0; // the first sample after the current time
    for (int i = 0; i < n; ++i) {
        const double t = n > 1 ? t0 + (t1 - t0) * double(i) / double(n - 1) : t1;
        while (next < s.size() && s[next].t <= t)
            ++next;
        out.push_back(value(s[next == 0 ? 0 : next - 1]));
    }
    return out;
}

float ForceHistory::scaleN() const {
    float m = 0.0f;
    for (const auto* q : {&server, &extrapolated})
        for (const Sample& x : *q)
            m = std::max(m, glm::length(x.f));
    float scale = 0.5f;
    for (float decade = 1.0f; scale < m; decade *= 10.0f)
        for (float step : {1.0f, 2.0f, 5.0f})
            if (scale < m)
                scale = std::max(scale, step * decade);
    return scale;
}

int ParticipantForces::update(double now, const std::map<uint16_t, HapticModel>& models) {
    // The client drops the model of whoever left the session (or of everyone, on a reconnect):
    // their plot goes with it at once, not 5 s later under a bare "client N", and their sequence
    // too, so that an id given to someone new starts afresh.
    std::erase_if(byClient, [&](const auto& e) { return !models.count(e.first); });
    std::erase_if(lastSequence, [&](const auto& e) { return !models.count(e.first); });
    int added = 0;
    for (const auto& [id, m] : models) {
        auto seen = lastSequence.find(id);
        if (seen != lastSequence.end() && int32_t(m.toolSequence - seen->second) <= 0)
            continue;
        lastSequence[id] = m.toolSequence;
        ForceHistory& h = byClient[id];
        h.windowS = windowS;
        h.addServer(now, m.force);
        ++added;
    }
    expire(now);
    return added;
}

void ParticipantForces::expire(double now) {
    for (auto it = byClient.begin(); it != byClient.end();) {
        it->second.expire(now);
        // lastSequence stays: the same old model must not bring the participant back.
        if (it->second.server.empty())
            it = byClient.erase(it);
        else
            ++it;
    }
}

void DirtyBoxHistory::add(const Box& b) {
    // A full update replaces the whole picture (a new view, a switch of design): the rectangles
    // before it belong to a picture no longer shown.
    if (b.full)
        boxes.clear();
    boxes.push_back(b);
    while (boxes.size() > keep)
        boxes.pop_front();
}

float DirtyBoxHistory::alpha(const Box& b, double now) const {
    double age = now - b.t;
    if (age < 0)
        return 1.0f;
    return float(std::clamp(1.0 - age / fadeS, 0.0, 1.0));
}

std::vector<DirtyBoxHistory::Box> DirtyBoxHistory::visible(double now) const {
    std::vector<Box> out;
    for (const Box& b : boxes)
        if (alpha(b, now) > 0.0f)
            out.push_back(b);
    return out;
}

std::vector<DirtyBoxHistory::Box> DirtyBoxHistory::overlay(double now, size_t n) const {
    std::vector<Box> out;
    for (auto it = boxes.rbegin(); it != boxes.rend() && out.size() < n; ++it)
        if (!it->full && alpha(*it, now) > 0.0f)
            out.push_back(*it);
    std::reverse(out.begin(), out.end());
    return out;
}

const char* syncDesignName(SyncDesign d) {
    return d == SyncDesign::Dbi ? "DBI (server renders)" : "Volume (local copy)";
}

void ComparisonHistory::record(SyncDesign design, double now, const ComparisonFigures& f) {
    Series& s = designs[int(design)];
    // A second without updates keeps the last measured bytes and latencies, for the table and
    // the plots alike (plotted as 0 they read "0.0 ms" beside the table's 23 ms).
    const ComparisonFigures before = s.last;
    s.last = f;
    if (f.bytesPerUpdate < 0 && s.points > 0) {
        s.last.bytesPerUpdate = before.bytesPerUpdate;
        s.last.rawBytesPerUpdate = before.rawBytesPerUpdate;
    }
    if (f.latencyP50Ms < 0 && s.points > 0) {
        s.last.latencyP50Ms = before.latencyP50Ms;
        s.last.latencyP99Ms = before.latencyP99Ms;
    }
    pushCapped(s.updatesPerS, float(f.updatesPerS), seriesLength);
    pushCapped(s.bytesPerUpdate, float(std::max(0.0, s.last.bytesPerUpdate)), seriesLength);
    pushCapped(s.rawBytesPerUpdate, float(std::max(0.0, s.last.rawBytesPerUpdate)), seriesLength);
    pushCapped(s.latencyP50Ms, float(std::max(0.0, s.last.latencyP50Ms)), seriesLength);
    pushCapped(s.latencyP99Ms, float(std::max(0.0, s.last.latencyP99Ms)), seriesLength);
    pushCapped(s.frameMs, float(f.frameMs), seriesLength);
    pushCapped(s.hapticHz, float(f.hapticHz), seriesLength);
    s.lastT = now;
    ++s.points;
    active = design;
}

double ComparisonHistory::ageS(SyncDesign d, double now) const {
    return measured(d) ? std::max(0.0, now - series(d).lastT) : -1.0;
}

double ComparisonHistory::ratio(double ComparisonFigures::*figure) const {
    if (!measured(SyncDesign::Dbi) || !measured(SyncDesign::Volume))
        return 0.0;
    double v = series(SyncDesign::Volume).last.*figure;
    return v > 0 ? series(SyncDesign::Dbi).last.*figure / v : 0.0;
}

SyncDesign designOf(Sync s) {
    return s == Sync::Volume ? SyncDesign::Volume : SyncDesign::Dbi;
}
Sync syncOf(SyncDesign d) {
    return d == SyncDesign::Volume ? Sync::Volume : Sync::Dbi;
}

// [SECTION] model

void ClientModel::addSnapshot(const std::shared_ptr<const ClientSnapshot>& snap, double now) {
    m_snap = snap;
    if (snap->state == LinkState::Connected)
        m_session = snap;
    if (snap->hapticModel && snap->hapticModels != m_hapticSeen) {
        m_hapticSeen = snap->hapticModels;
        forces.addServer(now, snap->hapticModel->force);
    }
    forces.expire(now);
    participants.update(now, snap->relayedModels);
    network.expire(now);
    if (m_nextSecond < 0)
        m_nextSecond = now + 1.0;
    if (now >= m_nextSecond) {
        const auto& rt = snap->rates;
        const uint64_t u = snap->updatesApplied;
        network.addSecond(
            imageBytesInPerS(rt), rt[size_t(Channel::ToolState)].bytesOutPerS,
            rt[size_t(Channel::Haptic)].bytesInPerS,
            double(u >= m_updatesAtLastSecond ? u - m_updatesAtLastSecond : u), snap->rttUs);
        m_updatesAtLastSecond = u;
        m_nextSecond += 1.0;
        if (m_nextSecond <= now)
            m_nextSecond = now + 1.0;
    }
}

void ClientModel::addRect(const AppliedRect& r, double now) {
    network.addUpdate({now, r.latencyUs, r.bytes, r.rawBytes, r.full});
    boxes.add({now, r.rect, r.sequence, r.bytes, r.latencyUs, r.full});
    ++updates;
    if (r.full) {
        ++fullUpdates;
        return;
    }
    updateBytes.add(r.bytes);
    updateRawBytes.add(r.rawBytes);
    if (r.latencyUs >= 0)
        updateLatencyUs.add(r.latencyUs);
}

void ClientModel::addVolumeBox(const AppliedVolumeBox& b, const PixelRect& screen, double now) {
    network.addUpdate({now, b.latencyUs, b.bytes, b.rawBytes, b.full});
    if (!screen.empty())
        boxes.add({now, screen, b.sequence, b.bytes, b.latencyUs, b.full});
    ++updates;
    if (b.full) {
        ++fullUpdates;
        return;
    }
    updateBytes.add(b.bytes);
    updateRawBytes.add(b.rawBytes);
    if (b.latencyUs >= 0)
        updateLatencyUs.add(b.latencyUs);
}

void ClientModel::setHapticTicks(const std::vector<HapticSample>& ticks, double now) {
    forces.extrapolated.clear();
    const double shift = ticks.empty() ? 0.0 : now - ticks.back().time;
    for (const HapticSample& h : ticks)
        forces.extrapolated.push_back({h.time + shift, h.force});
}

void ClientModel::addDrawn(SyncDesign design, double latencyUs, uint64_t appliedUs,
                           uint64_t drawnUs, uint32_t bytes, uint32_t rawBytes) {
    LiveSecond& l = m_live[int(design)];
    ++l.updates;
    l.bytes += bytes;
    l.rawBytes += rawBytes;
    if (latencyUs >= 0 && drawnUs >= appliedUs)
        l.latencyMs.push_back((latencyUs + double(drawnUs - appliedUs)) * 1e-3);
}

void ClientModel::addFrame(SyncDesign design, double frameMs) {
    m_frameMs[int(design)].push_back(frameMs);
    m_framed = true;
}

void ClientModel::tickComparison(double now, SyncDesign picture, bool record,
                                 uint64_t hapticTicks) {
    if (m_lastSecondAt < 0) {
        m_lastSecondAt = now;
        m_ticksAtLastSecond = hapticTicks;
        return;
    }
    if (now - m_lastSecondAt < 1.0)
        return;
    const double hz = hapticTicks >= m_ticksAtLastSecond
                          ? double(hapticTicks - m_ticksAtLastSecond) / (now - m_lastSecondAt)
                          : 0.0;
    const std::vector<double>& fm = m_frameMs[int(picture)];
    // A shell that draws frames records a second only when one was drawn in its design.
    if (record && m_snap && (!m_framed || !fm.empty())) {
        const ModeFigures& m = m_snap->modes[size_t(syncOf(picture))];
        const LiveSecond& l = m_live[int(picture)];
        ComparisonFigures f;
        f.updatesPerS = m.updateRatePerS;
        f.bytesPerUpdate = l.updates ? l.bytes / l.updates : -1.0;
        f.rawBytesPerUpdate = l.updates ? l.rawBytes / l.updates : -1.0;
        f.latencyP50Ms = l.latencyMs.empty() ? -1.0 : percentile(l.latencyMs, 50.0);
        f.latencyP99Ms = l.latencyMs.empty() ? -1.0 : percentile(l.latencyMs, 99.0);
        f.frameMs = fm.empty() ? 0.0 : percentile(fm, 50.0);
        f.hapticHz = hz;
        comparison.record(picture, now, f);
    }
    for (auto& v : m_frameMs)
        v.clear();
    m_live = {};
    m_ticksAtLastSecond = hapticTicks;
    m_lastSecondAt = now;
}

// [SECTION] report

nlohmann::ordered_json windowJson(const SampleWindow& w) {
    const bool any = w.size() > 0;
    return {{"count", w.totalCount()},
            {"mean", any ? w.mean() : -1.0},
            {"min", any ? w.min() : -1.0},
            {"p50", any ? w.percentile(50) : -1.0},
            {"p99", any ? w.percentile(99) : -1.0},
            {"max", any ? w.max() : -1.0}};
}

namespace {

nlohmann::ordered_json modeJson(const ModeFigures& m) {
    return {{"updates", m.updatesApplied},
            {"mean_bytes", m.meanBytes},
            {"mean_raw_bytes", m.meanRawBytes},
            {"latency_p50_us", m.latencyP50Us},
            {"latency_p99_us", m.latencyP99Us},
            {"erode_p50_us", m.erodeP50Us},
            {"server_render_p50_us", m.serverRenderP50Us},
            {"encode_p50_us", m.encodeP50Us},
            {"transmit_p50_us", m.transmitP50Us},
            {"client_apply_p50_us", m.applyP50Us},
            {"client_render_p50_us", m.clientRenderP50Us}};
}

nlohmann::ordered_json comparisonJson(const ComparisonHistory& c) {
    nlohmann::ordered_json out = nlohmann::ordered_json::object();
    for (SyncDesign d : {SyncDesign::Dbi, SyncDesign::Volume}) {
        if (!c.measured(d))
            continue;
        const ComparisonFigures& f = c.series(d).last;
        out[d == SyncDesign::Dbi ? "dbi" : "volume"] = {
            {"seconds", c.series(d).points},
            {"updates_per_s", f.updatesPerS},
            {"bytes_per_update", f.bytesPerUpdate},
            {"raw_bytes_per_update", f.rawBytesPerUpdate},
            {"latency_p50_ms", f.latencyP50Ms},
            {"latency_p99_ms", f.latencyP99Ms},
            {"frame_ms", f.frameMs},
            {"haptic_hz", f.hapticHz}};
    }
    return out;
}

} // namespace

nlohmann::ordered_json ClientModel::report(const ClientReportExtras& x) const {
    nlohmann::ordered_json j = x.session.is_object() ? x.session : nlohmann::ordered_json::object();
    const ClientSnapshot empty;
    const ClientSnapshot& s = m_session ? *m_session : empty;
    j["duration_s"] = x.durationS;
    j["updates_applied"] = s.updatesApplied;
    j["full_updates"] = s.fullUpdates;
    j["updates_rejected"] = s.updatesRejected;
    j["updates_shown"] = updates; // the updates this shell took from its client (the same, drained)
    j["tool_states_sent"] = s.toolStatesSent;
    j["relays_received"] = s.relaysReceived;
    j["malformed_dropped"] = s.malformed;
    j["packet_loss"] = s.packetLoss;
    j["packets_lost"] = s.packetsLost;
    j["rtt_p50_us"] = s.rttP50Us;
    j["update_latency_p50_us"] = s.latencyP50Us;
    j["update_latency_p99_us"] = s.latencyP99Us;
    j["update_mean_bytes"] = s.meanBytes;
    j["update_mean_raw_bytes"] = s.meanRawBytes;
    j["update_bytes"] = windowJson(updateBytes);
    j["update_raw_bytes"] = windowJson(updateRawBytes);
    j["update_latency_us"] = windowJson(updateLatencyUs);
    j["compression_ratio"] =
        updateBytes.totalSum() > 0 ? updateRawBytes.totalSum() / updateBytes.totalSum() : 1.0;
    j["modes"] = {{"dbi", modeJson(s.modes[size_t(Sync::Dbi)])},
                  {"volume", modeJson(s.modes[size_t(Sync::Volume)])}};
    nlohmann::ordered_json channels = nlohmann::ordered_json::object();
    for (size_t c = 0; c < size_t(Channel::Count); ++c) {
        double in = 0, out = 0;
        for (const auto& second : s.rateHistory) {
            in += second[c].bytesInPerS;
            out += second[c].bytesOutPerS;
        }
        const double n = s.rateHistory.empty() ? 1.0 : double(s.rateHistory.size());
        channels[channelName(Channel(c))] = {{"bytes_in_per_s", in / n},
                                             {"bytes_out_per_s", out / n}};
    }
    j["channels"] = channels;
    const HapticLoopStats& h = x.haptics;
    j["haptics"] = {{"tool_rate_hz", x.toolRateHz},
                    {"rate_hz", x.hapticRateHz},
                    {"achieved_rate_hz", h.achievedRateHz},
                    {"lateness_p50_ms", h.latenessP50Ms},
                    {"lateness_p99_ms", h.latenessP99Ms},
                    {"ticks", h.ticks},
                    {"models_received", s.hapticModels},
                    {"models_applied", h.models},
                    {"models_dropped", h.modelsDropped},
                    {"force_round_trip_p50_us", s.hapticRoundTripP50Us},
                    {"force_round_trip_p99_us", s.hapticRoundTripP99Us},
                    {"local_force_ticks", x.localForceTicks},
                    {"server_force_ticks", x.serverForceTicks},
                    {"server_force_samples_per_s", forces.serverRate()}};
    j["comparison"] = comparisonJson(comparison);
    j["dirty_boxes"] = boxes.boxes.size();
    return j;
}

} // namespace trephine::net

#include "ui/panel_data.h"
#include "ui/panels.h"

#include "libsim/stats.h"

#include <algorithm>
#include <cstdio>
#include <glm/geometric.hpp>

namespace trephine::ui {

namespace {
void pushCapped(std::vector<float>& v, float x, size_t n) {
    v.push_back(x);
    if (v.size() > n)
        v.erase(v.begin(), v.begin() + ptrdiff_t(v.size() - n));
}
} // namespace

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

std::optional<uint16_t>
ScriptedTakeOver::due(int attempt, const std::map<uint16_t, net::ParticipantInfo>& participants) {
    if (who.empty() || sentOnAttempt == attempt)
        return std::nullopt;
    for (const auto& [id, p] : participants)
        if (p.role == net::Role::Trainee && (p.name == who || std::to_string(id) == who)) {
            sentOnAttempt = attempt;
            return id;
        }
    return std::nullopt;
}

std::string defaultMarkLabel(const std::vector<net::AnnotationInfo>& marks) {
    for (size_t n = marks.size() + 1;; ++n) {
        const std::string label = "mark " + std::to_string(n);
        if (std::none_of(marks.begin(), marks.end(),
                         [&](const net::AnnotationInfo& m) { return m.label == label; }))
            return label;
    }
}

void MarkUndo::removing(const std::vector<net::AnnotationInfo>& shown, uint32_t id) {
    auto it = std::find_if(shown.begin(), shown.end(),
                           [&](const net::AnnotationInfo& m) { return m.id == id; });
    if (it != shown.end())
        m_taken = {*it};
}

void MarkUndo::clearing(const std::vector<net::AnnotationInfo>& shown) {
    if (!shown.empty())
        m_taken = shown;
}

std::vector<net::Annotate> MarkUndo::undo() {
    std::vector<net::Annotate> adds;
    for (const net::AnnotationInfo& m : m_taken) {
        net::Annotate a;
        a.op = net::Annotate::Op::Add;
        a.position = m.position;
        a.label = m.label;
        adds.push_back(std::move(a));
    }
    m_taken.clear();
    return adds;
}

std::vector<net::Annotate> markRequests(MarkControls& controls, MarkUndo& undo,
                                        const net::ClientSnapshot& snap,
                                        const std::optional<glm::vec3>& pointerPick) {
    std::vector<net::Annotate> out;
    if (snap.welcome && snap.state == net::LinkState::Connected) {
        if (controls.addAtPointer && pointerPick) {
            net::Annotate a;
            a.op = net::Annotate::Op::Add;
            a.position = *pointerPick;
            a.label = controls.label[0] ? std::string(controls.label)
                                        : defaultMarkLabel(snap.annotations);
            out.push_back(std::move(a));
        }
        if (controls.clearAll) {
            undo.clearing(snap.annotations);
            net::Annotate a;
            a.op = net::Annotate::Op::Clear;
            out.push_back(std::move(a));
        }
        if (controls.removeId) {
            undo.removing(snap.annotations, controls.removeId);
            net::Annotate a;
            a.op = net::Annotate::Op::Remove;
            a.id = controls.removeId;
            out.push_back(std::move(a));
        }
        if (controls.undo)
            for (net::Annotate& a : undo.undo())
                out.push_back(std::move(a));
    }
    controls.addAtPointer = controls.clearAll = controls.undo = false;
    controls.removeId = 0;
    controls.undoable = undo.pending();
    return out;
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
    return "latency p50 " + ms(latencyPercentile(50)) + " p99 " + ms(latencyPercentile(99)) + range;
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

int ParticipantForces::update(double now, const std::map<uint16_t, net::HapticModel>& models) {
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

} // namespace trephine::ui

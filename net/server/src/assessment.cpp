#include "net/assessment.h"

#include "libsim/error.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <limits>

namespace trephine::net {

const char* zoneName(Zone z) {
    switch (z) {
    case Zone::Clear:
        return "clear";
    case Zone::Caution:
        return "caution";
    case Zone::Danger:
        return "danger";
    case Zone::Violation:
        return "violation";
    }
    return "?";
}

void AssessmentConfig::validate() const {
    if (!(dangerMm > 0.0f && dangerMm < cautionMm && cautionMm < clampMm &&
          clampMm <= DistanceField::kMaxClampMm))
        throw Error(fmt::format("assessment: the zones need 0 < danger ({} mm) < caution ({} mm) "
                                "< {} mm",
                                dangerMm, cautionMm, clampMm));
}

// [SECTION] strokes

void StrokeCounter::start(glm::vec3 p) {
    ++m_strokes;
    m_points.assign(1, p);
    m_last = p;
    m_cos[0] = m_cos[1] = -1.0f;
    m_index = m_lastCut = 0;
}

void StrokeCounter::add(glm::vec3 p) {
    // Resample every kStepMm along the straight move from the last sample.
    glm::vec3 d = p - m_last;
    float len = glm::length(d);
    while (len >= kStepMm) {
        m_last += d / len * kStepMm;
        m_points.push_back(m_last);
        if (m_points.size() > size_t(2 * kK + 1))
            m_points.pop_front();
        ++m_index;
        if (m_points.size() == size_t(2 * kK + 1)) {
            const glm::vec3 mid = m_points[kK];
            const glm::vec3 a = m_points.front() - mid, b = m_points.back() - mid;
            const float c = glm::dot(a, b) / std::max(1e-6f, glm::length(a) * glm::length(b));
            // The previous sample's k-cosine is a local maximum above the threshold: a cut.
            const int64_t candidate = m_index - kK - 1;
            if (m_cos[1] > kCosine && m_cos[1] >= m_cos[0] && m_cos[1] > c &&
                candidate - m_lastCut >= kK) {
                ++m_strokes;
                m_lastCut = candidate;
            }
            m_cos[0] = m_cos[1];
            m_cos[1] = c;
        }
        d = p - m_last;
        len = glm::length(d);
    }
}

// [SECTION] assessment

double Assessment::sinceJoin(const Person& p, uint64_t now) {
    return now > p.joinedUs ? double(now - p.joinedUs) * 1e-6 : 0.0;
}

Assessment::Assessment(const Volume& volume, const AssessmentConfig& config, ReportBook& book,
                       ThreadPool* pool)
    : m_config(config), m_book(book), m_spacing(volume.spacing()) {
    m_config.validate();
    m_fields = StructureFields(volume, m_config.clampMm, pool);
    AssessmentSummary summary;
    for (size_t i = 0; i < m_fields.size(); ++i)
        summary.structures.push_back(m_fields.structure(i).name);
    summary.cautionMm = m_config.cautionMm;
    summary.dangerMm = m_config.dangerMm;
    summary.clampMm = m_config.clampMm;
    summary.fieldBuildMs = m_fields.buildMs();
    summary.fieldBytes = m_fields.bytes();
    m_book.record([&](ServerReport& r) { r.assessment = std::move(summary); });
}

double Assessment::voxelMm3() const {
    return double(m_spacing.x) * double(m_spacing.y) * double(m_spacing.z);
}

Zone Assessment::grade(float closestMm, bool contact) const {
    if (contact || closestMm <= 0.0f)
        return Zone::Violation;
    if (closestMm <= m_config.dangerMm)
        return Zone::Danger;
    if (closestMm <= m_config.cautionMm)
        return Zone::Caution;
    return Zone::Clear;
}

void Assessment::approach(const ToolShape& shape, const ToolPose& pose,
                          std::vector<float>& out) const {
    out.resize(m_fields.size());
    for (size_t i = 0; i < m_fields.size(); ++i)
        out[i] = m_fields.closestApproach(i, shape, pose);
}

void Assessment::join(uint16_t id, const std::string& name, Role role, uint64_t now) {
    Person p;
    p.name = name;
    p.role = role;
    p.joinedUs = now;
    p.structures.resize(m_fields.size());
    for (StructureState& s : p.structures)
        s.closestMm = s.distanceMm = m_config.clampMm;
    m_people[id] = std::move(p);
}

void Assessment::leave(uint16_t id, uint64_t now) {
    auto it = m_people.find(id);
    if (it == m_people.end() || !it->second.present)
        return;
    it->second.present = false;
    it->second.leftUs = now;
    record(now);
}

void Assessment::finish(uint64_t now) {
    for (auto& [id, p] : m_people)
        if (p.present) {
            p.present = false;
            p.leftUs = now;
        }
    record(now);
}

std::vector<uint16_t> Assessment::recipients(uint16_t owner) const {
    std::vector<uint16_t> to;
    for (const auto& [id, p] : m_people)
        if (p.present && (id == owner || p.role == Role::Instructor))
            to.push_back(id);
    return to;
}

void Assessment::post(std::vector<uint16_t> to, std::vector<uint8_t> bytes) {
    if (to.empty() || bytes.empty())
        return;
    std::lock_guard lock(m_noticeMutex);
    m_notices.push_back({std::move(to), std::move(bytes)});
}

std::vector<Assessment::Notice> Assessment::takeNotices() {
    std::lock_guard lock(m_noticeMutex);
    return std::exchange(m_notices, {});
}

void Assessment::warn(uint16_t id, Person& p, Zone previous, uint32_t sequence, uint64_t now) {
    SafetyWarning w;
    w.clientId = id;
    w.toolSequence = sequence;
    w.zone = p.zone;
    w.previous = previous;
    w.structure = p.zoneStructure >= 0 ? m_fields.structure(size_t(p.zoneStructure)).name : "";
    w.distanceMm = p.zoneDistance;
    w.serverTimeUs = now;
    post(recipients(id), encodeMessage(w));
    p.refreshedUs = now;
}

void Assessment::apply(const AppliedTool& a, uint64_t now) {
    auto it = m_people.find(a.client);
    if (it == m_people.end() || !it->second.present)
        return;
    Person& p = it->second;
    approach(a.shape, a.pose, m_scratch);
    // The zone: a structure touched (by the drill, or by the cutter's closest approach) is a
    // violation; otherwise the nearest structure's approach grades it.
    Zone zone = Zone::Clear;
    int nearest = -1;
    float nearestMm = std::numeric_limits<float>::max();
    for (size_t i = 0; i < m_fields.size(); ++i) {
        const CriticalStructure& cs = m_fields.structure(i);
        bool drillContact = false;
        for (int m = 0; m < kMaterialCount; ++m)
            drillContact = drillContact || (cs.has(Material(m)) && a.contactBy[size_t(m)] > 0);
        const float d = m_scratch[i];
        StructureState& s = p.structures[i];
        const bool contact = drillContact || d <= 0.0f;
        s.contacts += contact && !s.inContact;
        s.inContact = contact;
        s.closestMm = std::min(s.closestMm, d);
        s.distanceMm = d;
        const Zone z = grade(d, contact);
        if (z > zone || (z == zone && d < nearestMm)) {
            zone = z;
            nearest = int(i);
            nearestMm = d;
        }
    }
    const Zone previous = p.zone;
    p.zone = zone;
    p.zoneStructure = nearest;
    p.zoneDistance = nearest >= 0 ? nearestMm : m_config.clampMm;
    if (zone != previous) {
        p.warnings += zone > previous;
        warn(a.client, p, previous, a.sequence, a.arrivedUs);
        p.timeline.warnings.push_back({sinceJoin(p, now), zone, previous,
                                       nearest >= 0 ? m_fields.structure(size_t(nearest)).name : "",
                                       p.zoneDistance});
    } else if (zone != Zone::Clear && a.arrivedUs - p.refreshedUs >= m_config.refreshIntervalUs) {
        warn(a.client, p, previous, a.sequence, a.arrivedUs);
    }

    // Time, force, removal, path and strokes.
    const double dt = double(a.dt);
    p.zoneS[size_t(zone)] += dt;
    p.toolS[a.shape.describe()] += dt;
    if (a.forceN >= 0.0f) {
        p.maxForceN = std::max(p.maxForceN, double(a.forceN));
        p.lastForceN = a.forceN;
        if (a.drilling) {
            p.drillForceSum += a.forceN;
            ++p.drillForceCount;
        }
    }
    for (int m = 0; m < kMaterialCount; ++m)
        p.removed[size_t(m)] += a.removedBy[size_t(m)];
    const bool sameTool = p.shape.kind == a.shape.kind && p.shape.diameterMm == a.shape.diameterMm;
    if (a.drilling) {
        p.drillingS += dt;
        const float move = glm::length(a.pose.position - p.lastPos);
        if (p.drilling && sameTool && move <= m_config.maxSweepMm) {
            p.pathMm += move;
            p.strokes.add(a.pose.position);
        } else {
            p.strokes.start(a.pose.position);
        }
    }
    p.drilling = a.drilling;
    p.shape = a.shape;
    p.lastPos = a.pose.position;
    sample(p, sinceJoin(p, now), m_scratch);
}

void Assessment::sample(Person& p, double t, const std::vector<float>& dist) {
    if (p.sampleS >= 0.0 && t - p.sampleS < m_config.timelineIntervalS)
        return;
    p.sampleS = t;
    int64_t removed = 0;
    for (int64_t n : p.removed)
        removed += n;
    p.timeline.samples.push_back({t, dist, p.lastForceN, double(removed) * voxelMm3(), p.zone});
    // Bounded: past this many, every other sample goes (the plot keeps its shape).
    constexpr size_t kMaxSamples = 100000;
    if (p.timeline.samples.size() >= kMaxSamples) {
        std::vector<TimelineSample>& s = p.timeline.samples;
        size_t j = 0;
        for (size_t i = 0; i < s.size(); i += 2)
            s[j++] = std::move(s[i]);
        s.resize(j);
    }
}

void Assessment::tick(uint64_t now) {
    if (m_snapshotSent && now - m_snapshotUs < m_config.snapshotIntervalUs)
        return;
    m_snapshotSent = true;
    m_snapshotUs = now;
    AssessmentSnapshot all;
    all.serverTimeUs = now;
    for (const auto& [id, p] : m_people)
        if (p.present)
            all.list.push_back(figuresOf(id, p, now));
    if (all.list.empty())
        return;
    const std::vector<uint8_t> everyone = encodeMessage(all);
    std::vector<uint16_t> instructors;
    for (const ParticipantFigures& f : all.list) {
        const Person& p = m_people.at(f.clientId);
        if (p.role == Role::Instructor) {
            instructors.push_back(f.clientId);
            continue;
        }
        AssessmentSnapshot own;
        own.serverTimeUs = now;
        own.list.push_back(f);
        post({f.clientId}, encodeMessage(own));
    }
    post(std::move(instructors), everyone);
    record(now);
}

void Assessment::record(uint64_t now) {
    std::map<uint16_t, ParticipantMetrics> m = metrics(now);
    m_book.record([&](ServerReport& r) { r.participants = std::move(m); });
}

ParticipantMetrics Assessment::metricsOf(const Person& p, uint64_t now) const {
    ParticipantMetrics m;
    m.name = p.name;
    m.role = p.role;
    m.sessionS = sinceJoin(p, p.present ? now : p.leftUs);
    m.drillingS = p.drillingS;
    for (int i = 0; i < kMaterialCount; ++i)
        if (p.removed[size_t(i)] > 0) {
            const std::string name(materialName(Material(i)));
            m.removedVoxels[name] = p.removed[size_t(i)];
            m.removedMm3[name] = double(p.removed[size_t(i)]) * voxelMm3();
        }
    for (size_t i = 0; i < m_fields.size(); ++i)
        m.structures[m_fields.structure(i).name] = {p.structures[i].contacts,
                                                    double(p.structures[i].closestMm)};
    m.zoneS = p.zoneS;
    m.warnings = p.warnings;
    m.maxForceN = p.maxForceN;
    m.meanForceN = p.drillForceCount ? p.drillForceSum / double(p.drillForceCount) : 0.0;
    m.pathLengthMm = p.pathMm;
    m.meanSpeedMmS = p.drillingS > 0.0 ? p.pathMm / p.drillingS : 0.0;
    m.strokes = p.strokes.strokes();
    m.toolS = p.toolS;
    m.zone = p.zone;
    return m;
}

ParticipantFigures Assessment::figuresOf(uint16_t id, const Person& p, uint64_t now) const {
    const ParticipantMetrics m = metricsOf(p, now);
    ParticipantFigures f;
    f.clientId = id;
    f.zone = p.zone;
    f.sessionS = float(m.sessionS);
    f.drillingS = float(m.drillingS);
    f.maxForceN = float(m.maxForceN);
    f.meanForceN = float(m.meanForceN);
    f.pathLengthMm = float(m.pathLengthMm);
    f.meanSpeedMmS = float(m.meanSpeedMmS);
    f.strokes = uint32_t(m.strokes);
    f.warnings = uint32_t(m.warnings);
    for (int z = 0; z < kZoneCount; ++z)
        f.zoneS[size_t(z)] = float(m.zoneS[size_t(z)]);
    for (int i = 0; i < kMaterialCount; ++i)
        if (p.removed[size_t(i)] > 0)
            f.removed.push_back({uint8_t(i), float(double(p.removed[size_t(i)]) * voxelMm3())});
    for (size_t i = 0; i < m_fields.size() && i < kMaxStructures; ++i)
        f.structures.push_back({m_fields.structure(i).name.substr(0, kMaxStructureName),
                                p.structures[i].closestMm, p.structures[i].distanceMm,
                                uint32_t(p.structures[i].contacts)});
    for (const auto& [tool, s] : p.toolS)
        if (f.tools.size() < kMaxToolKinds)
            f.tools.push_back({tool.substr(0, kMaxStructureName), float(s)});
    return f;
}

std::map<uint16_t, ParticipantMetrics> Assessment::metrics(uint64_t now) const {
    std::map<uint16_t, ParticipantMetrics> out;
    for (const auto& [id, p] : m_people)
        out[id] = metricsOf(p, now);
    return out;
}

std::map<uint16_t, Timeline> Assessment::timelines() const {
    std::map<uint16_t, Timeline> out;
    for (const auto& [id, p] : m_people)
        out[id] = p.timeline;
    return out;
}

} // namespace trephine::net

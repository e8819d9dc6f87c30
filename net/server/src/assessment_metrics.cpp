#include "net/assessment_metrics.h"

namespace trephine::net {

using Json = nlohmann::ordered_json;

Json toJson(const AssessmentSummary& a) {
    return {{"structures", a.structures},       {"caution_mm", a.cautionMm},
            {"danger_mm", a.dangerMm},          {"field_clamp_mm", a.clampMm},
            {"field_build_ms", a.fieldBuildMs}, {"field_bytes", a.fieldBytes}};
}

Json toJson(const std::map<uint16_t, ParticipantMetrics>& participants) {
    Json list = Json::array();
    for (const auto& [id, m] : participants) {
        Json contacts = Json::object(), closest = Json::object();
        for (const auto& [name, s] : m.structures) {
            contacts[name] = s.contacts;
            closest[name] = s.closestMm;
        }
        Json zones = Json::object();
        for (int z = 0; z < kZoneCount; ++z)
            zones[zoneName(Zone(z))] = m.zoneS[size_t(z)];
        list.push_back({{"id", id},
                        {"name", m.name},
                        {"role", m.role == Role::Instructor ? "instructor" : "trainee"},
                        {"metrics",
                         {{"session_time_s", m.sessionS},
                          {"drilling_time_s", m.drillingS},
                          {"bone_removed_mm3", m.removedMm3},
                          {"bone_removed_voxels", m.removedVoxels},
                          {"contacts", contacts},
                          {"closest_mm", closest},
                          {"zone_time_s", zones},
                          {"warnings", m.warnings},
                          {"max_force_n", m.maxForceN},
                          {"mean_force_n", m.meanForceN},
                          {"path_length_mm", m.pathLengthMm},
                          {"mean_speed_mm_s", m.meanSpeedMmS},
                          {"strokes", m.strokes},
                          {"tool_time_s", m.toolS},
                          {"zone", zoneName(m.zone)}}}});
    }
    return list;
}

} // namespace trephine::net

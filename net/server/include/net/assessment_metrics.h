// One participant's assessment metrics as plain data: what the server's report holds
// (ServerReport::participants) and the debrief reads. net/assessment.h computes them from the tool
// states the simulation applies; docs/assessment.md defines each figure.
#pragma once

#include "net/assessment_protocol.h"
#include "net/protocol.h"

#include <nlohmann/json.hpp>

#include <array>
#include <cstdint>
#include <map>
#include <string>
#include <vector>

namespace trephine::net {

struct StructureMetrics {
    uint64_t contacts = 0; // episodes: runs of applied states touching it
    double closestMm = 0;  // the least closest approach (the field's clamp when never nearer)
};

struct ParticipantMetrics {
    std::string name;
    Role role = Role::Trainee;
    double sessionS = 0;  // server time from its join to its leave (or now)
    double drillingS = 0; // applied drilling time (the steps the simulation drilled)
    // Voxels eroded to zero by its cuts, by the material they were (only bone erodes), and their
    // volume: voxels x the voxel's volume.
    std::map<std::string, int64_t> removedVoxels;
    std::map<std::string, double> removedMm3;
    std::map<std::string, StructureMetrics> structures; // every critical structure present
    std::array<double, kZoneCount> zoneS{};             // applied time in each zone
    uint64_t warnings = 0;                              // zone entries (Caution and worse)
    double maxForceN = 0, meanForceN = 0;               // mean over drilling states
    double pathLengthMm = 0, meanSpeedMmS = 0;          // while drilling
    uint64_t strokes = 0;
    std::map<std::string, double> toolS; // applied time per tool and size ("burr 4 mm")
    Zone zone = Zone::Clear;             // the zone of its newest applied state
};

// The session's assessment settings and the cost of its distance fields.
struct AssessmentSummary {
    std::vector<std::string> structures;
    float cautionMm = 0, dangerMm = 0, clampMm = 0;
    double fieldBuildMs = 0;
    uint64_t fieldBytes = 0;
};

// The report's `assessment` object and `participants` list (docs/assessment.md).
nlohmann::ordered_json toJson(const AssessmentSummary& a);
nlohmann::ordered_json toJson(const std::map<uint16_t, ParticipantMetrics>& participants);

} // namespace trephine::net

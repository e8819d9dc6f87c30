// The assessment's two messages: SafetyWarning (a cutter's zone near a critical structure) and
// AssessmentSnapshot (each participant's live metrics). docs/protocol.md and docs/assessment.md
// describe them; the server makes them in net/assessment.h.
#pragma once

#include "net/protocol.h"

#include <array>
#include <cstdint>
#include <string>
#include <vector>

namespace trephine::net {

// How near a cutter is to a critical structure: beyond the caution distance (Clear), within it
// (Caution), within the danger distance (Danger), touching it (Violation).
enum class Zone : uint8_t { Clear = 0, Caution = 1, Danger = 2, Violation = 3 };
inline constexpr int kZoneCount = 4;
const char* zoneName(Zone z);

inline constexpr size_t kMaxStructureName = 32;
inline constexpr uint16_t kMaxStructures = 32;
inline constexpr uint16_t kMaxToolKinds = 64;

// Server -> the tool's owner and every instructor (Channel::Control, reliable), never to another
// trainee: the owner's zone changed (entered or left), or, while not Clear, its distance now (at
// most every AssessmentConfig::refreshIntervalUs, `zone == previous`).
struct SafetyWarning {
    static constexpr MessageType kType = MessageType::SafetyWarning;
    uint16_t clientId = 0; // whose tool
    Zone zone = Zone::Clear;
    Zone previous = Zone::Clear;
    std::string structure;     // the structure nearest the cutter (the one touched, in a violation)
    float distanceMm = 0;      // the cutter's closest approach to it (<= 0: touching)
    uint32_t toolSequence = 0; // the tool state that put it there
    uint64_t serverTimeUs = 0;

    template <typename S>
    bool serialize(S& s) {
        return s.ranged(clientId, uint16_t(1), uint16_t(UINT16_MAX)) &&
               s.ranged(zone, Zone::Clear, Zone::Violation) &&
               s.ranged(previous, Zone::Clear, Zone::Violation) &&
               s.string(structure, kMaxStructureName) && serializeFinite(s, distanceMm) &&
               s.integer(toolSequence) && s.integer(serverTimeUs);
    }
};

// One structure's figures for a participant.
struct StructureFigures {
    std::string name;
    float closestMm = 0;  // the least closest approach so far (the clamp when never nearer)
    float distanceMm = 0; // the current one
    uint32_t contacts = 0;

    template <typename S>
    bool serialize(S& s) {
        return s.string(name, kMaxStructureName) && serializeFinite(s, closestMm) &&
               serializeFinite(s, distanceMm) && s.integer(contacts);
    }
};

// Bone removed of one material (mm^3).
struct MaterialFigure {
    uint8_t material = 0;
    float mm3 = 0;

    template <typename S>
    bool serialize(S& s) {
        return s.ranged(material, uint8_t(0), uint8_t(kMaterialCount - 1)) &&
               serializeFinite(s, mm3);
    }
};

// Time with one tool (its describe(), e.g. "burr 4 mm").
struct ToolFigure {
    std::string tool;
    float seconds = 0;

    template <typename S>
    bool serialize(S& s) {
        return s.string(tool, kMaxStructureName) && serializeFinite(s, seconds);
    }
};

// One participant's metrics, as the server computes them from what it applies.
struct ParticipantFigures {
    uint16_t clientId = 0;
    Zone zone = Zone::Clear;
    float sessionS = 0, drillingS = 0;
    float maxForceN = 0, meanForceN = 0;      // mean while drilling
    float pathLengthMm = 0, meanSpeedMmS = 0; // while drilling
    uint32_t strokes = 0, warnings = 0;
    std::array<float, kZoneCount> zoneS{}; // time in each zone, by Zone
    std::vector<MaterialFigure> removed;
    std::vector<StructureFigures> structures;
    std::vector<ToolFigure> tools;

    template <typename S>
    bool serialize(S& s) {
        if (!(s.ranged(clientId, uint16_t(1), uint16_t(UINT16_MAX)) &&
              s.ranged(zone, Zone::Clear, Zone::Violation) && serializeFinite(s, sessionS) &&
              serializeFinite(s, drillingS) && serializeFinite(s, maxForceN) &&
              serializeFinite(s, meanForceN) && serializeFinite(s, pathLengthMm) &&
              serializeFinite(s, meanSpeedMmS) && s.integer(strokes) && s.integer(warnings)))
            return false;
        for (float& z : zoneS)
            if (!serializeFinite(s, z))
                return false;
        return list(s, removed, uint16_t(kMaterialCount)) && list(s, structures, kMaxStructures) &&
               list(s, tools, kMaxToolKinds);
    }

private:
    template <typename S, typename T>
    static bool list(S& s, std::vector<T>& v, uint16_t max) {
        uint16_t n = uint16_t(std::min<size_t>(v.size(), max));
        if (!s.ranged(n, uint16_t(0), max))
            return false;
        if constexpr (S::kReading)
            v.assign(n, T{});
        for (uint16_t i = 0; i < n; ++i)
            if (!v[i].serialize(s))
                return false;
        return true;
    }
};

// Server -> client (Channel::Control, reliable), at most every
// AssessmentConfig::snapshotIntervalUs: a trainee gets its own figures, an instructor everyone's,
// in increasing client id.
struct AssessmentSnapshot {
    static constexpr MessageType kType = MessageType::AssessmentSnapshot;
    uint64_t serverTimeUs = 0;
    std::vector<ParticipantFigures> list;

    template <typename S>
    bool serialize(S& s) {
        return s.integer(serverTimeUs) &&
               serializeIdList(s, list, kMaxParticipants,
                               [](const ParticipantFigures& p) { return p.clientId; });
    }
};

} // namespace trephine::net

// The session's assessment: for every tool state the simulation applies, the cutter's closest
// approach to each critical structure (libsim/distance_field.h), graded into zones; warnings to
// the tool's owner and every instructor when its zone changes; and each participant's metrics,
// computed from what the server applied (so no client can fake them), sent live as snapshots and
// kept for the report and the debrief. Pumped by the simulation step with the time passed in;
// the network thread takes its messages. docs/assessment.md defines the zones and metrics.
#pragma once

#include "libsim/distance_field.h"
#include "libsim/drill.h"
#include "libsim/thread_pool.h"
#include "libsim/tool.h"
#include "libsim/volume.h"
#include "net/assessment_metrics.h"
#include "net/assessment_protocol.h"
#include "net/server_report.h"

#include <array>
#include <cstdint>
#include <deque>
#include <map>
#include <mutex>
#include <string>
#include <vector>

namespace trephine::net {

struct AssessmentConfig {
    float cautionMm = 3.0f; // a closest approach within this is Caution
    float dangerMm = 1.0f;  // ... within this, Danger; touching is a Violation
    // The fields' clamp: distances beyond it read as it (it must exceed cautionMm).
    float clampMm = DistanceField::kDefaultClampMm;
    float maxSweepMm = 10.0f; // a drilling move longer than this is a jump (not path length)
    uint64_t snapshotIntervalUs = 500000; // AssessmentSnapshot at 2 Hz
    uint64_t refreshIntervalUs = 100000;  // a warning's distance again, while not Clear
    double timelineIntervalS = 0.05;      // debrief samples at most this often
    // Throws trephine::Error unless 0 < dangerMm < cautionMm < clampMm <= 255.
    void validate() const;
};

// What one applied tool state did: the simulation fills it in.
struct AppliedTool {
    uint16_t client = 0;
    ToolShape shape;
    ToolPose pose;
    bool drilling = false; // drilling and spinning (a paused drill is not)
    float dt = 0.0f;       // the step the simulation took for it (s)
    float forceN = -1.0f;  // the haptic answer's force magnitude (< 0: none was computed)
    uint32_t sequence = 0;
    uint64_t arrivedUs = 0;
    std::array<int64_t, kMaterialCount> removedBy{}; // DrillResult::removedBy over the sweep
    std::array<int64_t, kMaterialCount> contactBy{}; // DrillResult::contactBy over the sweep
};

// The debrief's record of one participant: samples over its session time and its warnings.
struct TimelineSample {
    double t = 0;                  // s since it joined
    std::vector<float> distanceMm; // closest approach per structure (StructureFields order)
    float forceN = 0;
    double removedMm3 = 0; // all bone removed so far
    Zone zone = Zone::Clear;
};
struct WarningMark {
    double t = 0;
    Zone zone = Zone::Clear, previous = Zone::Clear;
    std::string structure;
    float distanceMm = 0;
};
struct Timeline {
    std::vector<TimelineSample> samples;
    std::vector<WarningMark> warnings;
};

// k-cosine stroke segmentation of a drilling path (as FIVRS's skill-analysis scripts): the path
// is resampled every kStepMm; a sample whose k-cosine (the cosine between the chords to the
// samples k before and k after it) is a local maximum above kCosine, at least k samples after the
// last cut, ends a stroke. Each drilling run starts one.
class StrokeCounter {
public:
    static constexpr float kStepMm = 0.5f;
    static constexpr int kK = 4;           // 2 mm chords
    static constexpr float kCosine = 0.0f; // a turn sharper than 90 degrees
    void start(glm::vec3 p);               // the drill goes down: a new stroke
    void add(glm::vec3 p);                 // the drilling cutter moved to p
    uint64_t strokes() const { return m_strokes; }

private:
    std::deque<glm::vec3> m_points; // the last 2k + 1 resampled points
    glm::vec3 m_last{0.0f};
    float m_cos[2] = {-1.0f, -1.0f};    // k-cosines of the two samples before the newest known
    int64_t m_index = 0, m_lastCut = 0; // samples since the run started; the newest cut
    uint64_t m_strokes = 0;
};

class Assessment {
public:
    // Builds the structures' distance fields (on `pool`'s threads when given).
    Assessment(const Volume& volume, const AssessmentConfig& config, ReportBook& book,
               ThreadPool* pool = nullptr);

    void join(uint16_t id, const std::string& name, Role role, uint64_t now);
    void leave(uint16_t id, uint64_t now);
    // Grades an applied tool state, sends a warning on a zone change, and adds to the metrics.
    void apply(const AppliedTool& a, uint64_t now);
    // Time passes: the snapshot, when due, goes to everyone present and into the report.
    void tick(uint64_t now);
    // Everyone still present leaves at `now` (the server stops); the report gets the final figures.
    void finish(uint64_t now);

    // [Any thread] The messages to send, in order: whom to and the encoded bytes.
    struct Notice {
        std::vector<uint16_t> to;
        std::vector<uint8_t> bytes;
    };
    std::vector<Notice> takeNotices();

    // Every participant that ever joined, by client id, with session times up to `now`.
    std::map<uint16_t, ParticipantMetrics> metrics(uint64_t now) const;
    std::map<uint16_t, Timeline> timelines() const;
    const StructureFields& fields() const { return m_fields; }
    const AssessmentConfig& config() const { return m_config; }
    // The zone of a closest approach (contact: the drill touched the structure).
    Zone grade(float closestMm, bool contact) const;
    // The closest approach of a cutter to every structure (mm), into `out` (fields() order).
    void approach(const ToolShape& shape, const ToolPose& pose, std::vector<float>& out) const;

private:
    struct StructureState {
        uint64_t contacts = 0;
        float closestMm = 0;
        float distanceMm = 0;
        bool inContact = false;
    };
    struct Person {
        std::string name;
        Role role = Role::Trainee;
        uint64_t joinedUs = 0, leftUs = 0;
        bool present = true;
        double drillingS = 0;
        std::array<int64_t, kMaterialCount> removed{};
        std::vector<StructureState> structures;
        std::array<double, kZoneCount> zoneS{};
        uint64_t warnings = 0;
        double maxForceN = 0, drillForceSum = 0;
        uint64_t drillForceCount = 0;
        double pathMm = 0;
        Zone zone = Zone::Clear;
        int zoneStructure = -1;
        float zoneDistance = 0;
        uint64_t refreshedUs = 0;
        std::map<std::string, double> toolS;
        bool drilling = false; // its previous applied state drilled, with the same tool
        ToolShape shape;
        glm::vec3 lastPos{0.0f};
        StrokeCounter strokes;
        Timeline timeline;
        double sampleS = -1.0; // when the newest timeline sample was taken
        float lastForceN = 0;
    };

    void warn(uint16_t id, Person& p, Zone previous, uint32_t sequence, uint64_t now);
    std::vector<uint16_t> recipients(uint16_t owner) const;
    ParticipantMetrics metricsOf(const Person& p, uint64_t now) const;
    ParticipantFigures figuresOf(uint16_t id, const Person& p, uint64_t now) const;
    void record(uint64_t now);
    void sample(Person& p, double t, const std::vector<float>& dist);
    void post(std::vector<uint16_t> to, std::vector<uint8_t> bytes);
    double voxelMm3() const;
    static double sinceJoin(const Person& p, uint64_t now);

    AssessmentConfig m_config;
    ReportBook& m_book;
    StructureFields m_fields;
    glm::vec3 m_spacing{1.0f};
    std::map<uint16_t, Person> m_people;
    uint64_t m_snapshotUs = 0;
    bool m_snapshotSent = false;
    std::vector<float> m_scratch;

    mutable std::mutex m_noticeMutex;
    std::vector<Notice> m_notices;
};

} // namespace trephine::net

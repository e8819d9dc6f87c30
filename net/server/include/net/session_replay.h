// Replays a session log (net/session_log.h) through the simulation step the server ran
// (net/sim_step.h), so the volume comes out bit for bit as the server held it, and folds the
// policy's records into who was in the session, their marks and take-overs, and recomputes each
// participant's assessment metrics with the step's own Assessment (`replay --report`).
// `trephine replay` and `trephine server --resume` use it; trajectoriesOf exports each
// participant's tool path.
#pragma once

#include "libsim/camera.h"
#include "libsim/dbi.h"
#include "libsim/volume.h"
#include "net/server_config.h"
#include "net/server_report.h"
#include "net/session_log.h"

#include <functional>
#include <map>
#include <memory>
#include <set>
#include <span>
#include <string>
#include <vector>

namespace trephine::net {

class SessionReplay {
public:
    // One participant as the log has it; `ordinal` counts hellos from 1, so a client id the
    // server gave again after a resume is still another person.
    struct Participant {
        uint16_t client = 0;
        uint32_t ordinal = 0;
        Role role = Role::Trainee;
        std::string name;
        Sync sync = Sync::Dbi;
        uint16_t takenOverBy = 0;
    };

    // `start` is logStartVolume(header, ...).
    SessionReplay(const LogHeader& header, Volume start, int renderThreads = 1);
    ~SessionReplay();

    // Applies the next record (records in the log's order).
    void apply(const LogRecord& r);
    void applyAll(std::span<const LogRecord> records) {
        for (const LogRecord& r : records)
            apply(r);
    }

    const Volume& volume() const;
    // A full render of the volume now (what a converged client at that view holds).
    Dbi render(const Camera& camera);
    // Participants listed now (said hello, not left), by client id.
    const std::map<uint16_t, Participant>& participants() const { return m_participants; }
    const std::map<uint32_t, AnnotationInfo>& marks() const { return m_marks; }
    // The marks as a server resuming here starts with them (ServerConfig::marks).
    std::vector<AnnotationInfo> marksList() const;
    uint64_t toolStatesApplied() const {
        return m_book.counter(&ServerCounters::toolStatesApplied);
    }
    uint64_t recordsApplied() const { return m_applied; }

    // The assessment as the live server's report has it (docs/assessment.md): "assessment" (the
    // zones and structures; field_build_ms and field_bytes are this replay's own) and
    // "participants", every participant's metrics recomputed from the recorded tool states at
    // the recorded times, by the ids their server gave them. A log resumed N times lists each
    // server's participants in turn; those still present at the log's end (a killed server's)
    // are measured up to its last record.
    nlohmann::ordered_json assessmentJson();

private:
    // The participants (by client id) of the server that wrote the log since its last Resume.
    std::map<uint16_t, ParticipantMetrics> stretchMetrics();
    void simulate(const LogRecord& r);
    void join(const JoinEvent& e, uint64_t timeUs);
    void leave(uint16_t client);
    void policy(const Event& e);
    void resume(uint64_t timeUs);

    ReportBook m_book;
    // The server's own simulation step (net/sim_step.h), which only drills here, and its outbox.
    struct Simulation;
    std::unique_ptr<Simulation> m_sim;
    std::map<uint16_t, Participant> m_participants;
    std::set<uint16_t> m_joined; // clients the simulation holds (joined, not left)
    std::map<uint32_t, AnnotationInfo> m_marks;
    uint32_t m_hellos = 0;
    uint64_t m_applied = 0;
    uint64_t m_lastUs = 0;            // the newest record's time since the last Resume
    std::set<uint16_t> m_stretch;     // clients that joined since the last Resume
    nlohmann::ordered_json m_earlier; // the participants of the servers before it
};

// `trephine replay FILE --report R.json`: the log's name, format, records and torn tail (if any),
// then the assessment sections (SessionReplay::assessmentJson) of `replay`, which has applied
// all of `log`'s records.
std::string replayReportText(SessionReplay& replay, const LogContents& log,
                             const std::string& name);

// [SECTION] resuming

// A server's start from the log at `path` (`trephine server --resume`): the volume its server
// held, and in `config` the scene, marks, volume name and drilling settings it had, with a
// recorder appending to the log that has written the Resume record. A damaged log is first kept
// aside whole and replaced by its intact records (repairSessionLog). `open` regenerates a volume
// from its spec. Throws Error (one line) on a log it cannot use.
struct Resumed {
    Volume volume;
    std::string stopped;   // the log's damage, a line a stretch (empty: none)
    std::string keptAside; // where the damaged log was kept whole ("": it was whole)
    size_t records = 0;
    uint64_t toolStates = 0;
};
Resumed resumeSession(const std::string& path, ServerConfig& config,
                      const std::function<Volume(const std::string&)>& open, uint64_t unixNowUs);

// [SECTION] trajectories

// One participant's tool path: the tool states the simulation applied (newer sequences only),
// as a trainee script (docs/scripts.md) replays them.
struct Trajectory {
    uint32_t ordinal = 0;
    uint16_t client = 0;
    Role role = Role::Trainee;
    std::string name;
    std::vector<ToolState> states;
};
std::vector<Trajectory> trajectoriesOf(std::span<const LogRecord> records);
// The CSV of docs/scripts.md: time_s from the first state's client time, speed 0 where the
// drill did not cut.
std::string trajectoryCsv(const Trajectory& t);
// A file name for it: NN-NAME-ROLE.csv (NAME kept to letters, digits, '-' and '_').
std::string trajectoryFileName(const Trajectory& t);

} // namespace trephine::net

#include "net/session_replay.h"

#include "libsim/error.h"
#include "libsim/tool_catalogue.h"
#include "net/net_stats.h"
#include "net/outbox.h"
#include "net/scene.h"
#include "net/sim_step.h"

#include <fmt/format.h>

#include <cctype>

namespace trephine::net {

namespace {

uint64_t noClock() {
    return 0; // stage timings mean nothing in a replay
}

// The simulation settings of the server that wrote the log: drilling and the assessment's zones.
StepConfig replayStepConfig(const LogHeader& header, int renderThreads) {
    StepConfig c{.maxStepS = header.maxStepS,
                 .maxSweepMm = header.maxSweepMm,
                 .renderThreads = std::max(1, renderThreads),
                 .publish = false};
    c.assessment.cautionMm = header.cautionMm;
    c.assessment.dangerMm = header.dangerMm;
    c.assessment.clampMm = header.clampMm;
    return c;
}

} // namespace

struct SessionReplay::Simulation {
    Outbox outbox;
    SimulationStep step;
    Simulation(ReportBook& book, const LogHeader& header, Volume start, int renderThreads)
        : outbox(0, book, noClock),
          step(std::move(start), replayStepConfig(header, renderThreads), outbox, book, noClock) {}
};

SessionReplay::SessionReplay(const LogHeader& header, Volume start, int renderThreads)
    : m_sim(std::make_unique<Simulation>(m_book, header, std::move(start), renderThreads)),
      m_earlier(nlohmann::ordered_json::array()) {
    // A server numbers its starting marks 1..n, author 0 (SessionPolicy's constructor).
    uint32_t id = 1;
    for (const AnnotationInfo& m : header.marks) {
        m_marks[id] = {id, 0, m.position, m.label};
        ++id;
    }
}

SessionReplay::~SessionReplay() = default;

const Volume& SessionReplay::volume() const {
    return m_sim->step.volume();
}

Dbi SessionReplay::render(const Camera& camera) {
    return m_sim->step.render(camera);
}

void SessionReplay::apply(const LogRecord& r) {
    ++m_applied;
    if (!r.is<ResumeEvent>())
        m_lastUs = std::max(m_lastUs, r.timeUs);
    std::visit(Handlers{
                   [&](const JoinEvent& e) { join(e, r.timeUs); },
                   [&](const LeaveEvent& e) {
                       leave(e.client);
                       simulate(r);
                   },
                   [&](const SyncEvent& e) {
                       if (auto p = m_participants.find(e.client); p != m_participants.end())
                           p->second.sync = e.sync;
                       simulate(r);
                   },
                   [&](const ResumeEvent&) { resume(r.timeUs); },
                   [&](const auto&) {
                       if (isSimulation(r.event))
                           simulate(r);
                       else
                           policy(r.event);
                   },
               },
               r.event);
}

void SessionReplay::simulate(const LogRecord& r) {
    m_sim->step.step({&r, 1}, r.timeUs);
}

void SessionReplay::join(const JoinEvent& e, uint64_t timeUs) {
    m_joined.insert(e.client);
    m_stretch.insert(e.client);
    // The assessment lists it by its hello's name and role, as the policy's Join does.
    LogRecord named{timeUs, e};
    if (auto p = m_participants.find(e.client); p != m_participants.end()) {
        named.as<JoinEvent>()->name = p->second.name;
        named.as<JoinEvent>()->role = p->second.role;
    }
    simulate(named);
}

void SessionReplay::leave(uint16_t client) {
    m_joined.erase(client);
    m_participants.erase(client);
    // The policy hands back whatever a leaving client held or was held by.
    for (auto& [id, p] : m_participants)
        if (p.takenOverBy == client)
            p.takenOverBy = 0;
}

// Who is in the session, their marks and take-overs.
void SessionReplay::policy(const Event& e) {
    auto release = [&](uint16_t client) {
        for (auto& [id, p] : m_participants)
            if (p.takenOverBy == client)
                p.takenOverBy = 0;
    };
    std::visit(Handlers{
                   [&](const HelloEvent& h) {
                       m_participants[h.client] = {h.client, ++m_hellos, h.role,
                                                   h.name,   Sync::Dbi,  0};
                   },
                   [&](const MarkEvent& m) {
                       if (m.op == Annotate::Op::Add)
                           m_marks[m.mark.id] = m.mark;
                       else if (m.op == Annotate::Op::Remove)
                           m_marks.erase(m.mark.id);
                       else
                           m_marks.clear();
                   },
                   [&](const HoldEvent& h) {
                       release(h.client);
                       if (auto p = m_participants.find(h.trainee); p != m_participants.end())
                           p->second.takenOverBy = h.client;
                   },
                   [&](const ReleaseEvent& rel) {
                       release(rel.client);
                       if (auto p = m_participants.find(rel.client); p != m_participants.end())
                           p->second.takenOverBy = 0;
                   },
                   [](const auto&) {},
               },
               e);
}

// The killed server's clients are gone: the simulation forgets them as it would their leaves,
// and the resumed server numbers the marks afresh. They left at the killed server's last record,
// on its clock (the Resume's is the new server's).
void SessionReplay::resume(uint64_t timeUs) {
    for (uint16_t id : std::set<uint16_t>(m_joined))
        simulate({m_lastUs, LeaveEvent{id}});
    m_joined.clear();
    for (nlohmann::ordered_json& p : toJson(stretchMetrics()))
        m_earlier.push_back(std::move(p));
    m_stretch.clear();
    m_lastUs = timeUs;
    m_participants.clear();
    const std::vector<AnnotationInfo> kept = marksList();
    m_marks.clear();
    for (const AnnotationInfo& m : kept)
        m_marks[m.id] = m;
}

std::vector<AnnotationInfo> SessionReplay::marksList() const {
    std::vector<AnnotationInfo> list;
    uint32_t id = 1;
    for (const auto& [old, m] : m_marks)
        list.push_back({id++, 0, m.position, m.label});
    return list;
}

// [SECTION] the assessment

std::map<uint16_t, ParticipantMetrics> SessionReplay::stretchMetrics() {
    std::map<uint16_t, ParticipantMetrics> all = m_sim->step.assessment().metrics(m_lastUs);
    std::erase_if(all, [&](const auto& p) { return !m_stretch.count(p.first); });
    return all;
}

nlohmann::ordered_json SessionReplay::assessmentJson() {
    nlohmann::ordered_json participants = m_earlier;
    for (nlohmann::ordered_json& p : toJson(stretchMetrics()))
        participants.push_back(std::move(p));
    const AssessmentSummary summary =
        m_book.read([](const ServerReport& r) { return r.assessment; });
    nlohmann::ordered_json j = nlohmann::ordered_json::object();
    j["assessment"] = toJson(summary);
    j["participants"] = std::move(participants);
    return j;
}

std::string replayReportText(SessionReplay& replay, const LogContents& log,
                             const std::string& name) {
    nlohmann::ordered_json j = nlohmann::ordered_json::object();
    j["log"] = name;
    j["log_format"] = log.version;
    j["records"] = log.records.size();
    j["stopped"] = log.stopped; // empty: the log was read to its end
    j.update(replay.assessmentJson());
    return jsonText(j);
}

// [SECTION] resuming

Resumed resumeSession(const std::string& path, ServerConfig& config,
                      const std::function<Volume(const std::string&)>& open, uint64_t unixNowUs) {
    LogContents log = readSessionLog(path);
    SessionReplay replay(log.header, logStartVolume(log.header, open), config.renderThreads);
    replay.applyAll(log.records);
    Scene scene;
    if (!decodeScene(log.header.scene, scene))
        throw Error("--resume " + path + ": the scene in its header does not read");
    config.scene = std::make_shared<const Scene>(std::move(scene));
    config.marks = replay.marksList();
    config.volumeName = log.header.volumeName;
    config.maxStepS = log.header.maxStepS;
    config.maxSweepMm = log.header.maxSweepMm;
    config.cautionMm = log.header.cautionMm;
    config.dangerMm = log.header.dangerMm;
    // Only now that the log is known to be usable: a damaged one is kept aside whole, and its
    // intact records become the log appended to.
    const std::string keptAside = repairSessionLog(path, log);
    config.recorder = SessionRecorder::append(path, log.intactBytes, log.version);
    const LogRecord resumed{steadyNowUs(), ResumeEvent{unixNowUs}};
    if (!config.recorder->write({&resumed, 1}))
        throw Error("--resume " + path + ": " + config.recorder->error());
    return {replay.volume(), log.stopped, keptAside, log.records.size(),
            replay.toolStatesApplied()};
}

// [SECTION] trajectories

std::vector<Trajectory> trajectoriesOf(std::span<const LogRecord> records) {
    std::vector<Trajectory> out;
    std::map<uint16_t, size_t> current; // client id -> its trajectory now
    std::map<uint16_t, uint32_t> lastSequence;
    for (const LogRecord& r : records) {
        std::visit(Handlers{
                       [&](const HelloEvent& h) {
                           Trajectory t;
                           t.ordinal = uint32_t(out.size() + 1);
                           t.client = h.client;
                           t.role = h.role;
                           t.name = h.name;
                           current[h.client] = out.size();
                           lastSequence.erase(h.client);
                           out.push_back(std::move(t));
                       },
                       [&](const LeaveEvent& l) { current.erase(l.client); },
                       [&](const ResumeEvent&) { current.clear(); },
                       [&](const ToolEvent& e) {
                           auto it = current.find(e.client);
                           if (it == current.end())
                               return;
                           // As the simulation applies them: an older sequence arriving late is
                           // dropped.
                           auto last = lastSequence.find(e.client);
                           if (last != lastSequence.end() &&
                               int32_t(e.tool.sequence - last->second) <= 0)
                               return;
                           lastSequence[e.client] = e.tool.sequence;
                           out[it->second].states.push_back(e.tool);
                       },
                       [](const auto&) {},
                   },
                   r.event);
    }
    std::erase_if(out, [](const Trajectory& t) { return t.states.empty(); });
    return out;
}

std::string trajectoryCsv(const Trajectory& t) {
    // The header first: a script's header is its first line (comments may follow).
    std::string csv = "time_s,x,y,z,qw,qx,qy,qz,speed,tool\n";
    csv += fmt::format("# {} ({}, client {}): {} tool states\n", t.name,
                       t.role == Role::Instructor ? "instructor" : "trainee", t.client,
                       t.states.size());
    const uint64_t t0 = t.states.empty() ? 0 : t.states.front().clientTimeUs;
    uint64_t last = t0;
    for (const ToolState& s : t.states) {
        // A script's times must not decrease; a client's clock does not either.
        last = std::max(last, s.clientTimeUs);
        const double time = double(last - t0) * 1e-6;
        const char* kind = toolType(ToolKind(s.toolKind)).name; // in range: the log decoded
        csv +=
            fmt::format("{:.6f},{},{},{},{},{},{},{},{},{}:{}\n", time, s.position.x, s.position.y,
                        s.position.z, s.orientation.w, s.orientation.x, s.orientation.y,
                        s.orientation.z, s.drilling ? s.speed : 0.0f, kind, s.diameterMm);
    }
    return csv;
}

std::string trajectoryFileName(const Trajectory& t) {
    std::string name;
    for (char c : t.name)
        name += std::isalnum(static_cast<unsigned char>(c)) || c == '-' || c == '_' ? c : '_';
    if (name.empty())
        name = "client" + std::to_string(t.client);
    return fmt::format("{:02}-{}-{}.csv", t.ordinal, name,
                       t.role == Role::Instructor ? "instructor" : "trainee");
}

} // namespace trephine::net

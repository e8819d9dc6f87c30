#include "net/replay_feed.h"

#include "libsim/distance_field.h"
#include "libsim/error.h"
#include "net/scene.h"
#include "net/session_policy.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

namespace trephine::net {

std::vector<uint64_t> sessionTimesUs(std::span<const LogRecord> records) {
    std::vector<uint64_t> times;
    times.reserve(records.size());
    uint64_t offset = 0, start = 0, last = 0;
    bool open = false;
    for (const LogRecord& r : records) {
        if (!open || r.is<ResumeEvent>()) {
            offset += open ? last - start : 0;
            start = last = r.timeUs;
            open = true;
        }
        // A Tool record carries its arrival time, which may precede records written before it.
        last = std::max(last, r.timeUs);
        times.push_back(offset + (last - start));
    }
    return times;
}

ReplayPlayer::ReplayPlayer(std::vector<LogRecord> records, double speed, bool playing,
                           uint64_t nowUs)
    : m_records(std::move(records)), m_times(sessionTimesUs(m_records)), m_speed(1.0),
      m_playing(playing), m_anchorNowUs(nowUs) {
    setSpeed(speed, nowUs);
}

uint64_t ReplayPlayer::positionUs(uint64_t nowUs) const {
    if (!m_playing || nowUs <= m_anchorNowUs)
        return m_anchorPosUs;
    const double pos = double(m_anchorPosUs) + double(nowUs - m_anchorNowUs) * m_speed;
    return pos >= double(durationUs()) ? durationUs() : uint64_t(pos);
}

void ReplayPlayer::anchor(uint64_t nowUs) {
    m_anchorPosUs = positionUs(nowUs);
    m_anchorNowUs = nowUs;
}

ReplayPlayer::Due ReplayPlayer::advance(uint64_t nowUs) {
    Due due;
    const uint64_t pos = positionUs(nowUs);
    if (m_rewind) {
        due.rewind = true;
        m_rewind = false;
        m_next = 0;
    }
    while (m_next < m_records.size() && m_times[m_next] <= pos)
        due.records.push_back(m_records[m_next++]);
    if (m_playing && pos >= durationUs()) {
        anchor(nowUs);
        m_playing = false;
    }
    return due;
}

void ReplayPlayer::play(uint64_t nowUs) {
    if (m_playing)
        return;
    if (positionUs(nowUs) >= durationUs() && done())
        seek(0, nowUs); // at the end, as a video player does: again from the start
    m_anchorNowUs = nowUs;
    m_playing = true;
}

void ReplayPlayer::pause(uint64_t nowUs) {
    anchor(nowUs);
    m_playing = false;
}

void ReplayPlayer::seek(uint64_t positionUs, uint64_t nowUs) {
    positionUs = std::min(positionUs, durationUs());
    // Something already applied lies past the new position: only a rebuild takes it back.
    if (m_next > 0 && m_times[m_next - 1] > positionUs)
        m_rewind = true;
    m_anchorPosUs = positionUs;
    m_anchorNowUs = nowUs;
    ++m_seeks;
}

void ReplayPlayer::setSpeed(double speed, uint64_t nowUs) {
    if (!(speed >= double(kMinReplaySpeed) && speed <= double(kMaxReplaySpeed)))
        throw Error(fmt::format("replay: the speed must be within {:g} and {:g}",
                                double(kMinReplaySpeed), double(kMaxReplaySpeed)));
    anchor(nowUs);
    m_speed = speed;
}

bool ReplayPlayer::control(const ReplayControl& c, uint64_t nowUs) {
    switch (c.op) {
    case ReplayControl::Op::Play:
        play(nowUs);
        return true;
    case ReplayControl::Op::Pause:
        pause(nowUs);
        return true;
    case ReplayControl::Op::Seek:
        seek(c.positionUs, nowUs);
        return true;
    case ReplayControl::Op::Speed:
        if (!(c.speed >= kMinReplaySpeed && c.speed <= kMaxReplaySpeed))
            return false;
        setSpeed(double(c.speed), nowUs);
        return true;
    }
    return false;
}

ReplayState ReplayPlayer::state(uint64_t nowUs) const {
    return {positionUs(nowUs), durationUs(), float(m_speed), m_playing, m_seeks};
}

LogHeader makeLogHeader(const Volume& volume, const ServerConfig& config,
                        const std::string& volumeSpec, bool embed, uint64_t startUnixUs) {
    LogHeader h = logHeaderOf(volume, volumeSpec, embed, startUnixUs);
    h.volumeName = config.volumeName;
    h.maxStepS = config.maxStepS;
    h.maxSweepMm = config.maxSweepMm;
    h.cautionMm = config.cautionMm;
    h.dangerMm = config.dangerMm;
    h.clampMm = DistanceField::kDefaultClampMm; // the server's (AssessmentConfig's default)
    // The scene the server serves: the one given, or the one it builds from the volume.
    Scene scene = config.scene ? *config.scene : buildScene(volume);
    h.scene = encodeMessage(scene);
    // Numbered as the server numbers its starting marks.
    uint32_t id = 1;
    for (const AnnotationInfo& m : config.marks)
        h.marks.push_back({id++, 0, m.position, m.label});
    return h;
}

ServerConfig replayServerConfig(const LogHeader& header, ServerConfig c) {
    Scene scene;
    if (!decodeScene(header.scene, scene))
        throw Error("replay: the scene in the log's header does not read");
    c.scene = std::make_shared<const Scene>(std::move(scene));
    c.marks = header.marks;
    c.volumeName = header.volumeName;
    c.maxStepS = header.maxStepS;
    c.maxSweepMm = header.maxSweepMm;
    c.cautionMm = header.cautionMm;
    c.dangerMm = header.dangerMm;
    c.recorder = nullptr;
    c.replay = true;
    return c;
}

// [SECTION] the policy's side

void SessionPolicy::replayed(std::span<const LogRecord> records, uint64_t now, PolicyOutput& out) {
    std::map<uint16_t, ToolState> tools; // each participant's newest of the batch
    for (const LogRecord& r : records)
        replayOne(r, now, out, tools);
    const std::vector<uint16_t> watchers = participants();
    if (watchers.empty())
        return;
    for (auto& [id, tool] : tools)
        if (m_replayed.count(id)) {
            ToolRelay relay{id, tool};
            out.messages.push_back({watchers, Channel::ToolState, encodeMessage(relay)});
        }
}

// Every recorded participant leaves the simulation and the roster, its take-overs handed back.
void SessionPolicy::replayedLeave(PolicyOutput& out) {
    for (uint16_t joined : m_replayJoined)
        out.events.push_back({0, LeaveEvent{joined}});
    m_replayJoined.clear();
    for (const auto& [gone, p] : m_replayed)
        releaseTakeOvers(gone);
    m_replayed.clear();
    m_roster.mark(true);
}

void SessionPolicy::rewindReplay(PolicyOutput& out) {
    replayedLeave(out);
    // The log's marks go (its starting ones come back under their ids); the watchers' stay.
    std::erase_if(m_marks, [](const auto& m) {
        return m.second.author == 0 || (m.second.author & 0x8000u) != 0;
    });
    m_replayMarks.clear();
    uint32_t id = 1;
    for (const AnnotationInfo& m : m_config.marks) {
        m_marks[id] = {id, 0, m.position, m.label};
        m_replayMarks[id] = id;
        ++id;
    }
    m_marksOut.mark(true);
}

void SessionPolicy::replayState(ReplayState state, PolicyOutput& out) {
    m_replayState = encodeMessage(state);
    const std::vector<uint16_t> watchers = participants();
    if (!watchers.empty())
        out.messages.push_back({watchers, Channel::Control, m_replayState});
}

void SessionPolicy::replayOne(const LogRecord& r, uint64_t now, PolicyOutput& out,
                              std::map<uint16_t, ToolState>& tools) {
    const uint16_t id = replayedId(clientOf(r.event));
    // What the simulation applies goes to it as the recorded participant's, arriving now.
    auto simulate = [&](auto e) {
        if constexpr (requires { e.client; })
            e.client = id;
        out.events.push_back({now, std::move(e)});
    };
    std::visit(Handlers{
                   [&](JoinEvent e) {
                       // Nobody receives its pictures: a DBI (not the whole volume a volume
                       // client is sent) keeps the simulation's work for it small.
                       e.sync = Sync::Dbi;
                       if (auto p = m_replayed.find(id); p != m_replayed.end()) {
                           e.name = p->second.name; // the assessment names it
                           e.role = p->second.role;
                       }
                       simulate(std::move(e));
                       m_replayJoined.insert(id);
                   },
                   [&](const SyncEvent& e) {
                       if (auto p = m_replayed.find(id); p != m_replayed.end()) {
                           p->second.sync = e.sync;
                           m_roster.mark();
                       }
                   },
                   [&](const ToolEvent& e) {
                       simulate(e);
                       tools[id] = e.tool;
                   },
                   [&](const LeaveEvent& e) {
                       simulate(e);
                       tools.erase(id);
                       m_replayJoined.erase(id);
                       if (m_replayed.erase(id))
                           m_roster.mark(true);
                       if (releaseTakeOvers(id))
                           m_roster.mark();
                   },
                   [&](const HelloEvent& e) {
                       m_replayed[id] = {e.role, e.name, Sync::Dbi};
                       m_roster.mark(true);
                   },
                   [&](const MarkEvent& e) { replayMark(e); },
                   [&](const HoldEvent& e) {
                       releaseTakeOvers(id);
                       m_takenOver[replayedId(e.trainee)] = id;
                       m_roster.mark();
                   },
                   [&](const ReleaseEvent&) {
                       releaseTakeOvers(id);
                       m_roster.mark();
                   },
                   [&](const ResumeEvent&) { replayResume(out); },
                   [&](const auto& e) { simulate(e); }, // a view, a cut, voxels
               },
               r.event);
}

void SessionPolicy::replayMark(const MarkEvent& e) {
    if (e.op == Annotate::Op::Add) {
        if (m_marks.size() >= kMaxAnnotations || m_nextMarkId == 0)
            return;
        const uint32_t mark = m_nextMarkId++;
        m_marks[mark] = {mark, replayedId(e.mark.author), e.mark.position, e.mark.label};
        m_replayMarks[e.mark.id] = mark;
    } else if (e.op == Annotate::Op::Remove) {
        if (auto m = m_replayMarks.find(e.mark.id); m != m_replayMarks.end()) {
            m_marks.erase(m->second);
            m_replayMarks.erase(m);
        }
    } else {
        m_marks.clear();
        m_replayMarks.clear();
    }
    m_marksOut.mark();
}

// The recorded server was killed: its clients were gone, and the resumed one numbered the marks
// left 1..n in the order of their ids.
void SessionPolicy::replayResume(PolicyOutput& out) {
    replayedLeave(out);
    std::map<uint32_t, uint32_t> renumbered;
    uint32_t recorded = 1;
    for (const auto& [old, mark] : m_replayMarks)
        if (m_marks.count(mark))
            renumbered[recorded++] = mark;
    m_replayMarks = std::move(renumbered);
}

} // namespace trephine::net

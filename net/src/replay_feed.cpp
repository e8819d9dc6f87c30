#include "net/replay_feed.h"

#include "libsim/error.h"
#include "net/scene.h"
#include "net/session_policy.h"

#include <algorithm>
#include <cmath>

namespace trephine::net {

std::vector<uint64_t> sessionTimesUs(std::span<const LogRecord> records) {
    std::vector<uint64_t> times;
    times.reserve(records.size());
    uint64_t offset = 0, start = 0, last = 0;
    bool open = false;
    for (const LogRecord& r : records) {
        if (!open || r.kind == LogRecord::Kind::Resume) {
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

ReplayFeed::ReplayFeed(std::vector<LogRecord> records, double speed)
    : m_records(std::move(records)), m_times(sessionTimesUs(m_records)), m_speed(speed) {
    if (!(speed > 0.0) || !std::isfinite(speed))
        throw Error("replay: the speed must be a positive number");
}

std::vector<LogRecord> ReplayFeed::due(uint64_t elapsedUs) {
    const double sessionUs = double(elapsedUs) * m_speed;
    std::vector<LogRecord> out;
    while (m_next < m_records.size() && double(m_times[m_next]) <= sessionUs)
        out.push_back(m_records[m_next++]);
    return out;
}

uint64_t ReplayFeed::durationUs() const {
    return m_times.empty() ? 0 : uint64_t(std::ceil(double(m_times.back()) / m_speed));
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
    return c;
}

// [SECTION] the policy's side

void SessionPolicy::replayed(const LogRecord& r, uint64_t now, PolicyOutput& out) {
    const uint16_t id = replayedId(r.client);
    auto event = [&](uint16_t client) {
        SimEvent ev = simEventOf(r);
        ev.client = client;
        ev.arrivedUs = now;
        return ev;
    };
    switch (r.kind) {
    case LogRecord::Kind::Join: {
        // Nobody receives its pictures: a DBI (not the whole volume a volume client is sent)
        // keeps the simulation's work for it small.
        SimEvent ev = event(id);
        ev.sync = Sync::Dbi;
        out.events.push_back(std::move(ev));
        m_replayJoined.insert(id);
        break;
    }
    case LogRecord::Kind::View:
        out.events.push_back(event(id));
        break;
    case LogRecord::Kind::Sync:
        if (auto p = m_replayed.find(id); p != m_replayed.end()) {
            p->second.sync = r.sync;
            m_roster.mark();
        }
        break;
    case LogRecord::Kind::Tool: {
        out.events.push_back(event(id));
        const std::vector<uint16_t> watchers = participants();
        if (!watchers.empty()) {
            ToolRelay relay{id, r.tool};
            out.messages.push_back({watchers, Channel::ToolState, encodeMessage(relay)});
        }
        break;
    }
    case LogRecord::Kind::Leave:
        out.events.push_back(event(id));
        m_replayJoined.erase(id);
        if (m_replayed.erase(id))
            m_roster.mark(true);
        if (releaseTakeOvers(id))
            m_roster.mark();
        break;
    case LogRecord::Kind::Cut:
    case LogRecord::Kind::Voxels:
        out.events.push_back(event(0));
        break;
    case LogRecord::Kind::Hello:
        m_replayed[id] = {r.role, r.name, Sync::Dbi};
        m_roster.mark(true);
        break;
    case LogRecord::Kind::Mark:
        if (r.op == Annotate::Op::Add) {
            if (m_marks.size() >= kMaxAnnotations || m_nextMarkId == 0)
                break;
            const uint32_t mark = m_nextMarkId++;
            m_marks[mark] = {mark, replayedId(r.mark.author), r.mark.position, r.mark.label};
            m_replayMarks[r.mark.id] = mark;
        } else if (r.op == Annotate::Op::Remove) {
            if (auto m = m_replayMarks.find(r.mark.id); m != m_replayMarks.end()) {
                m_marks.erase(m->second);
                m_replayMarks.erase(m);
            }
        } else {
            m_marks.clear();
            m_replayMarks.clear();
        }
        m_marksOut.mark();
        break;
    case LogRecord::Kind::Hold:
        releaseTakeOvers(id);
        m_takenOver[replayedId(r.trainee)] = id;
        m_roster.mark();
        break;
    case LogRecord::Kind::Release:
        releaseTakeOvers(id);
        m_roster.mark();
        break;
    case LogRecord::Kind::Resume: {
        // The recorded server was killed: its clients were gone, and the resumed one numbered
        // the marks left 1..n in the order of their ids.
        for (uint16_t joined : m_replayJoined)
            out.events.push_back(SimEvent::of(SimEvent::Kind::Leave, joined));
        m_replayJoined.clear();
        for (const auto& [gone, p] : m_replayed)
            releaseTakeOvers(gone);
        m_replayed.clear();
        std::map<uint32_t, uint32_t> renumbered;
        uint32_t recorded = 1;
        for (const auto& [old, mark] : m_replayMarks)
            if (m_marks.count(mark))
                renumbered[recorded++] = mark;
        m_replayMarks = std::move(renumbered);
        m_roster.mark(true);
        break;
    }
    }
}

} // namespace trephine::net

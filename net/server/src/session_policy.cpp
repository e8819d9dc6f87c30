#include "net/session_policy.h"

#include "libsim/error.h"
#include "net/messages.h"
#include "net/tool_model.h"
#include "net/view.h"

#include <algorithm>

namespace trephine::net {

SessionPolicy::SessionPolicy(const ServerConfig& config, glm::ivec3 dims, glm::vec3 spacing,
                             ReportBook& book, ForceFn force)
    : m_config(config), m_dims(dims), m_spacing(spacing), m_book(book), m_force(std::move(force)) {
    if (!m_config.scene || m_config.scene->dims != dims)
        throw Error("server: the scene given is not one of this volume");
    Scene scene = *m_config.scene; // serialize is one function for write and read: not const
    m_sceneMessage = encodeMessage(scene);
    if (m_sceneMessage.empty())
        throw Error("server: the scene does not fit one message");
    for (const AnnotationInfo& m : m_config.marks) {
        const uint32_t id = m_nextMarkId++;
        m_marks[id] = {id, 0, m.position, m.label};
        m_replayMarks[id] = id; // a replayed log numbers its starting marks the same
    }
}

// [SECTION] connections

uint16_t SessionPolicy::connect(uint32_t connectData, uint64_t now, PolicyOutput& out) {
    if (connectData != kProtocolVersion) {
        out.disconnects.push_back({0, uint32_t(RefuseReason::Version) | (kProtocolVersion << 8)});
        return 0;
    }
    // Places are the admitted peers'; connections still to be admitted have slots of their own.
    if (admittedCount() >= m_config.maxClients) {
        m_book.count(&ServerCounters::refusedFull);
        out.disconnects.push_back({0, uint32_t(RefuseReason::ServerFull)});
        return 0;
    }
    if (m_peers.size() - admittedCount() >= m_config.admission.waitingSlots) {
        m_book.record([](ServerReport& r) { ++r.availability.refusedBusy; });
        out.disconnects.push_back({0, uint32_t(RefuseReason::Busy)});
        return 0;
    }
    // After 65535 joins the ids wrap: skip any still held (peers <= maxClients, so one is free
    // within maxClients + 1 tries).
    uint16_t id = 0;
    do {
        id = m_nextId++;
        if (m_nextId == 0)
            m_nextId = 1;
    } while (m_peers.count(id) || m_replayed.count(id));
    Peer& joined = m_peers[id];
    joined.connectedUs = joined.heardUs = now;
    walkBy(now + helloTimeoutUs() + 1);
    joined.viewPixels = RateBudget(m_config.viewPixelsPerS, 2.0 * double(m_config.maxViewPixels));
    m_book.record([&](ServerReport& r) {
        // A fresh report: after the ids wrap, one may still hold a left peer's figures.
        r.peers[id] = PeerReport{};
        r.peers[id].connectedUs = now;
        r.counters.clients = m_peers.size();
    });
    return id;
}

void SessionPolicy::disconnect(uint16_t id, uint64_t now, PolicyOutput& out) {
    auto gone = m_peers.find(id);
    if (gone == m_peers.end())
        return;
    const bool listed = gone->second.hello && !gone->second.kicked;
    m_peers.erase(gone);
    countSwitches(); // it left: nothing to switch
    releaseTakeOvers(id);
    m_handLinks.erase(id);
    m_follow.leave(id);
    out.events.push_back({0, LeaveEvent{id}});
    m_book.record([&](ServerReport& r) {
        PeerReport& p = r.peers[id];
        if (p.disconnectedUs == 0)
            p.disconnectedUs = now;
        r.counters.clients = m_peers.size();
    });
    if (listed)
        m_roster.mark(true);
}

void SessionPolicy::goodbye(uint64_t now, PolicyOutput& out) {
    for (const auto& [id, p] : m_peers)
        out.disconnects.push_back({id, uint32_t(RefuseReason::Shutdown)});
    // Gone from here on, whether or not the goodbye is acknowledged in time.
    m_book.record([&](ServerReport& r) {
        for (const auto& [id, p] : m_peers)
            if (r.peers[id].disconnectedUs == 0)
                r.peers[id].disconnectedUs = now;
    });
}

void SessionPolicy::kick(uint16_t id, Peer& p, RefuseReason why, PolicyOutput& out, uint64_t now) {
    p.kicked = true;
    m_book.peer(id, [](PeerReport& r) { r.kicked = true; });
    out.disconnects.push_back({id, uint32_t(why)});
    if (releaseTakeOvers(id))
        out.log.push_back({now, ReleaseEvent{id}});
    if (p.hello)
        m_roster.mark(true);
}

void SessionPolicy::refuse(uint16_t id, uint32_t data, uint64_t now, PolicyOutput& out) {
    auto it = m_peers.find(id);
    if (it == m_peers.end() || it->second.kicked)
        return;
    kick(id, it->second, RefuseReason::None, out, now);
    out.disconnects.back().data = data;
}

void SessionPolicy::refuseVolume(uint16_t id, uint64_t now, PolicyOutput& out) {
    auto it = m_peers.find(id);
    if (it != m_peers.end() && !it->second.kicked)
        kick(id, it->second, RefuseReason::VolumeTooLarge, out, now);
}

bool SessionPolicy::live(uint16_t id) const {
    auto it = m_peers.find(id);
    return it != m_peers.end() && !it->second.kicked;
}

Host::InFlight SessionPolicy::inFlight(uint16_t id) const {
    auto it = m_peers.find(id);
    return it == m_peers.end() ? Host::InFlight{} : it->second.inFlight;
}

void SessionPolicy::holdHelloClock(uint16_t id, uint64_t now) {
    if (auto it = m_peers.find(id); it != m_peers.end() && !it->second.hello)
        it->second.connectedUs = now;
}

// [SECTION] time

void SessionPolicy::update(uint64_t now, PolicyOutput& out) {
    const bool walk = now >= m_walkUs;
    if (walk) {
        m_walkUs = now + kScanPeriodUs;
        updateAvailability(now, out);
        // A connection that never says hello would hold a client slot for good.
        for (auto& [id, p] : m_peers) {
            if (p.hello || p.kicked)
                continue;
            if (now - p.connectedUs > helloTimeoutUs()) {
                m_book.count(&ServerCounters::helloTimeouts);
                kick(id, p, RefuseReason::BadHello, out, now);
            } else {
                walkBy(p.connectedUs + helloTimeoutUs() + 1);
            }
        }
    }
    // The whole list, paced: an instructor editing fast (in an open session, any hello may claim
    // the role) cannot make the server queue a list per edit for every participant.
    if (m_marksOut.due(now))
        out.messages.push_back({participants(), Channel::Control, marksMessage()});
    if (m_roster.due(now)) {
        out.messages.push_back({participants(), Channel::Control, rosterMessage()});
        HandLinks links = handLinksInForce();
        if (!links.list.empty() || m_handLinksListed)
            out.messages.push_back({participants(), Channel::Control, encodeMessage(links)});
        m_handLinksListed = !links.list.empty();
    }
    if (!walk)
        return;
    for (auto& [id, p] : m_peers)
        if (!p.kicked && p.modeSwitch.pending()) {
            if (p.modeSwitch.due(now))
                pushSwitch(id, p, now, out);
            else
                walkBy(p.modeSwitch.dueAtUs());
        }
    countSwitches();
}

// [SECTION] messages

PolicyOutput SessionPolicy::receive(uint16_t id, std::span<const uint8_t> message, uint64_t now) {
    PolicyOutput out;
    auto it = m_peers.find(id);
    if (it == m_peers.end() || it->second.kicked)
        return out;
    Peer& p = it->second;
    p.heardUs = now;
    if (!handle(id, p, message, now, out))
        countMalformed(id, p, out, now);
    return out;
}

PolicyOutput SessionPolicy::reject(uint16_t id, uint64_t now) {
    PolicyOutput out;
    auto it = m_peers.find(id);
    if (it != m_peers.end() && !it->second.kicked)
        countMalformed(id, it->second, out, now);
    return out;
}

void SessionPolicy::countMalformed(uint16_t id, Peer& p, PolicyOutput& out, uint64_t now) {
    out.malformed = true;
    m_book.peer(id, [](PeerReport& r) { ++r.malformed; });
    if (++p.malformed > m_config.malformedLimit && !p.kicked) {
        m_book.count(&ServerCounters::malformedKicks);
        kick(id, p, RefuseReason::Malformed, out, now);
    }
}

void SessionPolicy::authenticate(uint16_t id, Role role) {
    if (auto it = m_peers.find(id); it != m_peers.end())
        it->second.proven = role;
}

// False for a malformed message.
bool SessionPolicy::handle(uint16_t id, Peer& p, std::span<const uint8_t> data, uint64_t now,
                           PolicyOutput& out) {
    if (!p.hello)
        return hello(id, p, data, now, out);
    // A message only the server sends, or of no type, is malformed (the table's direction).
    return dispatchReceived<Side::Server>(
        peekMessageType(data),
        Handlers{
            [](MessageTag<Hello>) { return false; },     // a second hello
            [](MessageTag<Handshake>) { return false; }, // the gate's, before the hello
            [&](MessageTag<ViewRequest>) {
                ViewRequest r;
                if (!decodeMessage(data, r))
                    return false;
                const bool tooLarge = viewTooLarge(r.view); // well-formed, but more than we serve
                m_book.record([&](ServerReport& rep) {
                    ++rep.peers[id].viewRequests;
                    rep.counters.viewsRefused += tooLarge;
                    rep.peers[id].viewsRefused += tooLarge;
                });
                if (tooLarge)
                    return true;
                return viewRequest(id, p, r, now, out);
            },
            [&](MessageTag<ViewAs>) { // net/view_follow.h
                ViewAs m;
                if (!decodeMessage(data, m))
                    return false;
                if (p.helloMsg.role == Role::Instructor)
                    if (const auto view = m_follow.follow(id, m.clientId)) {
                        ParticipantView seen{m.clientId, *view};
                        out.messages.push_back({{id}, Channel::Control, encodeMessage(seen)});
                    }
                return true;
            },
            [&](MessageTag<ToolState>) { return toolState(id, p, data, now, out); },
            [&](MessageTag<SyncMode>) { return syncMode(id, p, data, now, out); },
            [&](MessageTag<Annotate>) { return annotate(id, p, data, now, out); },
            [&](MessageTag<TakeOver>) { return takeOver(id, p, data, now, out); },
            [&](MessageTag<HandLinks>) { return handLink(id, p, data); },
            [&](MessageTag<Remove>) { return remove(id, p, data, now, out); },
            [&](MessageTag<Codes>) { return codes(id, p, data, out); },
            [&](MessageTag<ReplayControl>) {
                ReplayControl c;
                if (!decodeMessage(data, c))
                    return false;
                if (m_config.replay)
                    out.replayControls.push_back(c);
                else
                    m_book.count(&ServerCounters::replayControlsRefused);
                return true;
            },
            [&](MessageTag<ImageAck>) { // the outbox judges it (net/outbox.h)
                ImageAck a;
                if (!decodeMessage(data, a))
                    return false;
                out.imageAcks.push_back({id, a});
                return true;
            },
            [&](MessageTag<Ping>) {
                Ping ping;
                if (!decodeMessage(data, ping))
                    return false;
                Pong pong{ping.clientTimeUs, now};
                out.messages.push_back({{id}, Channel::Control, encodeMessage(pong)});
                return true;
            },
        },
        false);
}

bool SessionPolicy::hello(uint16_t id, Peer& p, std::span<const uint8_t> data, uint64_t now,
                          PolicyOutput& out) {
    Hello h;
    if (peekMessageType(data) != uint8_t(MessageType::Hello) || !decodeMessage(data, h))
        return false;
    std::vector<uint8_t> worn; // the others' colours: a newcomer gets one nobody wears
    for (const auto& [other, q] : m_peers)
        if (q.hello && !q.kicked)
            worn.push_back(q.colour);
    p.colour = pickParticipantColour(worn);
    if (p.proven) // the role comes from the code, never from the hello
        h.role = *p.proven;
    h.name = uniqueName(id, h.name);
    p.hello = true;
    p.helloMsg = h;
    p.sync = h.sync;
    p.volumeCodec = h.volumeCodec;
    m_book.peer(id, [&](PeerReport& r) {
        r.hello = true;
        r.name = h.name;
        r.role = h.role;
        r.sync = h.sync;
    });
    RefuseReason refusal = RefuseReason::None;
    if (viewTooLarge(h.view)) {
        refusal = RefuseReason::BadHello;
    } else if (admittedCount() > m_config.maxClients) { // others were admitted since it connected
        refusal = RefuseReason::ServerFull;
        m_book.count(&ServerCounters::refusedFull);
    } else if (overViewTotal(id, h.view)) {
        refusal = RefuseReason::ViewsFull;
        m_book.record([](ServerReport& r) { ++r.availability.refusedViewTotal; });
    }
    if (refusal != RefuseReason::None) {
        // Refused before it is listed: nobody else hears of it.
        p.kicked = true;
        m_book.peer(id, [](PeerReport& r) { r.kicked = true; });
        out.disconnects.push_back({id, uint32_t(refusal)});
        return true;
    }
    p.pixels = int64_t(h.view.width) * int64_t(h.view.height);
    walkBy(0); // the next pass notes its idle clock; a waiting view may no longer fit the total
    out.log.push_back({now, HelloEvent{id, h.role, h.name}});
    welcome(id, now, out);
    m_follow.setView(id, h.view);
    out.events.push_back(
        {0, JoinEvent{id, h.view, h.codec, h.sync, h.volumeCodec, h.role, h.name, p.inFlight}});
    return true;
}

// What a newcomer is told after its hello: the welcome, the scene, then the marks; everyone gets
// the roster.
void SessionPolicy::welcome(uint16_t id, uint64_t now, PolicyOutput& out) {
    Welcome w;
    w.clientId = id;
    w.serverTimeUs = now;
    w.volumeDims = m_dims;
    w.spacing = m_spacing;
    w.volumeName = m_config.volumeName; // at most kMaxVolumeNameBytes (checked at start)
    w.maxViewPixels = uint32_t(m_config.maxViewPixels);
    out.messages.push_back({{id}, Channel::Control, encodeMessage(w)});
    out.messages.push_back({{id}, Channel::Control, m_sceneMessage}); // net/scene.h
    m_roster.mark(true);
    if (!m_marks.empty())
        out.messages.push_back({{id}, Channel::Control, marksMessage()});
    if (!m_replayState.empty())
        out.messages.push_back({{id}, Channel::Control, m_replayState});
    if (m_peers.at(id).helloMsg.role == Role::Instructor)
        sendCodes({id}, out); // the codes to read out (session_codes.cpp)
}

bool SessionPolicy::toolState(uint16_t id, Peer& p, std::span<const uint8_t> data, uint64_t now,
                              PolicyOutput& out) {
    ToolState t;
    if (!decodeMessage(data, t))
        return false;
    // Forces and cutting both take the unit rotation (the message only bounds its norm).
    t.orientation = glm::normalize(t.orientation);
    try {
        shapeOf(t).validate();
    } catch (const Error&) {
        return false; // a diameter the tool cannot have
    }
    m_book.peer(id, [](PeerReport& r) { ++r.toolStates; });
    // A paused drill (taken over, or an instructor holding nobody) still touches the bone, as a
    // burr that does not spin: forces, relays, no cutting.
    if (t.drilling && !mayCut(id, p.helloMsg.role)) {
        t.drilling = false;
        m_book.count(&ServerCounters::drillingPaused);
    }
    float forceN = -1.0f;
    if (m_config.hapticModels)
        forceN = answerHaptic(id, p, t, now, out);
    out.events.push_back({now, ToolEvent{id, t, forceN}}); // the force: the assessment's figures
    const std::vector<uint16_t> others = participants(id);
    if (!others.empty()) {
        ToolRelay relay{id, t};
        out.messages.push_back({others, Channel::ToolState, encodeMessage(relay)});
    }
    return true;
}

// The force at the tool's pose, answered at once (before and independent of drilling), and
// relayed to every instructor but the tool's own client.
float SessionPolicy::answerHaptic(uint16_t id, Peer& p, const ToolState& t, uint64_t now,
                                  PolicyOutput& out) {
    HapticModel m;
    m.toolSequence = t.sequence;
    m.serverReceivedUs = now;
    m.clientTimeUs = t.clientTimeUs;
    m.position = t.position;
    // The drilling resistance resists the tool's motion: its velocity from this peer's states.
    const glm::vec3 velocity = p.toolVelocity.update(t.position, double(t.clientTimeUs) * 1e-6);
    const ForceAnswer f = m_force(t, velocity);
    m.force = f.force.force;
    m.gradient = f.force.gradient;
    m.contact = f.force.contact;
    m.serverSentUs = f.doneUs;
    const Role instructor = Role::Instructor;
    const std::vector<uint16_t> instructors = participants(id, &instructor);
    // Counted before it is sent: readers never see fewer than were received.
    m_book.record([&](ServerReport& r) {
        r.forceComputeUs.add(double(f.computeUs));
        r.hapticServiceUs.add(double(f.doneUs - now));
        ++r.counters.hapticModelsSent;
        r.counters.hapticRelaysSent += instructors.size();
    });
    out.messages.push_back({{id}, Channel::Haptic, encodeMessage(m)});
    if (!instructors.empty()) {
        HapticRelay relay{id, m};
        out.messages.push_back({instructors, Channel::Haptic, encodeMessage(relay)});
    }
    out.flush = true;
    return glm::length(f.force.force);
}

bool SessionPolicy::syncMode(uint16_t id, Peer& p, std::span<const uint8_t> data, uint64_t now,
                             PolicyOutput& out) {
    SyncMode m;
    if (!decodeMessage(data, m))
        return false;
    const bool changed = p.sync != m.sync;
    // The mode and codec the client already has: nothing to do (a switch to volume encodes the
    // whole volume; a client repeating it would slow every other one).
    if (!changed && m.volumeCodec == p.volumeCodec)
        return true;
    p.sync = m.sync;
    p.volumeCodec = m.volumeCodec;
    // Paced: what reaches the simulation when it is due is the latest mode. Counted as waiting
    // before the report shows the switch, so a reader of both never sees an idle server.
    p.modeSwitch.mark();
    if (p.modeSwitch.due(now))
        pushSwitch(id, p, now, out);
    else
        walkBy(p.modeSwitch.dueAtUs());
    countSwitches();
    m_book.peer(id, [&](PeerReport& r) {
        r.sync = m.sync;
        ++r.syncSwitches;
    });
    if (changed)
        m_roster.mark();
    return true;
}

void SessionPolicy::pushSwitch(uint16_t id, Peer& p, uint64_t now, PolicyOutput& out) {
    out.events.push_back({now, SyncEvent{id, p.sync, p.volumeCodec}});
}

// Well-formed but not allowed: counted, not applied (and not malformed).
bool SessionPolicy::annotate(uint16_t id, const Peer& p, std::span<const uint8_t> data,
                             uint64_t now, PolicyOutput& out) {
    Annotate a;
    if (!decodeMessage(data, a))
        return false;
    auto refuse = [&] {
        m_book.count(&ServerCounters::annotationsRefused);
        return true;
    };
    if (p.helloMsg.role != Role::Instructor)
        return refuse();
    MarkEvent logged{a.op, {}};
    switch (a.op) {
    case Annotate::Op::Add:
        if (m_marks.size() >= kMaxAnnotations || m_nextMarkId == 0)
            return refuse();
        m_marks[m_nextMarkId] = {m_nextMarkId, id, a.position, a.label};
        logged.mark = m_marks[m_nextMarkId];
        ++m_nextMarkId;
        break;
    case Annotate::Op::Remove:
        if (!m_marks.erase(a.id))
            return true; // already gone (another instructor removed it): nothing to do
        logged.mark.id = a.id;
        break;
    case Annotate::Op::Clear:
        if (m_marks.empty())
            return true;
        m_marks.clear();
        break;
    }
    out.log.push_back({now, logged});
    m_marksOut.mark();
    return true;
}

bool SessionPolicy::takeOver(uint16_t id, const Peer& p, std::span<const uint8_t> data,
                             uint64_t now, PolicyOutput& out) {
    TakeOver m;
    if (!decodeMessage(data, m))
        return false;
    auto refuse = [&] {
        m_book.count(&ServerCounters::takeOversRefused);
        return true;
    };
    if (p.helloMsg.role != Role::Instructor)
        return refuse();
    if (m.trainee == 0) {
        if (releaseTakeOvers(id)) {
            out.log.push_back({now, ReleaseEvent{id}});
            m_roster.mark();
        }
        return true;
    }
    auto target = m_peers.find(m.trainee);
    if (target == m_peers.end() || !target->second.hello || target->second.kicked ||
        target->second.helloMsg.role != Role::Trainee)
        return refuse();
    auto held = m_takenOver.find(m.trainee);
    if (held != m_takenOver.end())
        return held->second == id ? true : refuse(); // another instructor's: handed back first
    releaseTakeOvers(id);                            // one trainee at a time
    m_takenOver[m.trainee] = id;
    out.log.push_back({now, HoldEvent{id, m.trainee}});
    m_roster.mark();
    return true;
}

// An instructor joins its force device to a participant's forces, or to the hand of the trainee
// it holds; everyone hears of it with the roster.
bool SessionPolicy::handLink(uint16_t id, const Peer& p, std::span<const uint8_t> data) {
    HandLinks m;
    if (!decodeMessage(data, m))
        return false;
    const std::vector<uint16_t> others = participants(id);
    if (p.helloMsg.role != Role::Instructor || m.list.size() != 1 ||
        (m.list[0].feels != 0 && std::ranges::find(others, m.list[0].feels) == others.end())) {
        m_book.count(&ServerCounters::handLinksRefused);
        return true;
    }
    HandLink link{id, m.list[0].feels, m.list[0].guides};
    if (link.feels == 0 && !link.guides)
        m_handLinks.erase(id);
    else
        m_handLinks[id] = link;
    m_roster.mark();
    return true;
}

// An instructor sends a participant away for good (until it allows them back): the gate keeps
// the address and the role's code (net/session_gate.h).
bool SessionPolicy::remove(uint16_t id, const Peer& p, std::span<const uint8_t> data, uint64_t now,
                           PolicyOutput& out) {
    Remove m;
    if (!decodeMessage(data, m))
        return false;
    if (p.helloMsg.role != Role::Instructor) {
        m_book.record([](ServerReport& r) { ++r.security.removalsRefused; });
        return true;
    }
    if (m.op == Remove::Op::AllowRejoin) {
        out.allowRejoin = true;
        return true;
    }
    auto target = m_peers.find(m.clientId);
    if (m.clientId == id || target == m_peers.end() || !target->second.hello ||
        target->second.kicked) {
        m_book.record([](ServerReport& r) { ++r.security.removalsRefused; });
        return true;
    }
    kick(m.clientId, target->second, RefuseReason::Removed, out, now);
    out.removed.push_back(m.clientId);
    return true;
}

// [SECTION] helpers

std::vector<uint16_t> SessionPolicy::participants(uint16_t except, const Role* role) const {
    std::vector<uint16_t> ids;
    for (const auto& [id, p] : m_peers)
        if (id != except && p.hello && !p.kicked && (!role || p.helloMsg.role == *role))
            ids.push_back(id);
    return ids;
}

std::vector<uint8_t> SessionPolicy::rosterMessage() const {
    Participants roster;
    auto heldBy = [&](uint16_t id) {
        auto held = m_takenOver.find(id);
        return held == m_takenOver.end() ? uint16_t(0) : held->second;
    };
    for (const auto& [id, p] : m_peers) {
        if (!p.hello || p.kicked)
            continue;
        roster.list.push_back({id, p.helloMsg.role, p.sync, p.helloMsg.name, heldBy(id),
                               participantPalette()[p.colour]});
    }
    // A replay's recorded participants, in id order with the others (the message wants it).
    for (const auto& [id, p] : m_replayed)
        roster.list.push_back({id, p.role, p.sync, p.name, heldBy(id),
                               participantPalette()[id % participantPalette().size()]});
    std::sort(
        roster.list.begin(), roster.list.end(),
        [](const ParticipantInfo& a, const ParticipantInfo& b) { return a.clientId < b.clientId; });
    return encodeMessage(roster);
}

HandLinks SessionPolicy::handLinksInForce() const {
    HandLinks links;
    for (const auto& [id, asked] : m_handLinks) {
        if (m_peers.at(id).kicked)
            continue;
        HandLink l = asked;
        auto felt = m_peers.find(l.feels);
        if (felt == m_peers.end() || !felt->second.hello || felt->second.kicked)
            l.feels = 0;
        l.guides = l.guides && std::ranges::any_of(m_takenOver, [&](const auto& held) {
                       return held.second == id;
                   });
        if (l.feels || l.guides)
            links.list.push_back(l);
    }
    return links;
}

std::vector<uint8_t> SessionPolicy::marksMessage() const {
    Annotations marks;
    for (const auto& [id, a] : m_marks)
        marks.list.push_back(a);
    return encodeMessage(marks);
}

// A trainee nobody holds, or an instructor holding a trainee, may cut; nobody watching a replay.
bool SessionPolicy::mayCut(uint16_t id, Role role) const {
    if (m_config.replay)
        return false;
    if (role == Role::Trainee)
        return !m_takenOver.count(id);
    return std::any_of(m_takenOver.begin(), m_takenOver.end(),
                       [&](const auto& held) { return held.second == id; });
}

// Hands back whatever `id` holds or is held by; true when that changed anything. A guide ends
// with its hold: it is never carried to the next trainee the instructor takes.
bool SessionPolicy::releaseTakeOvers(uint16_t id) {
    return std::erase_if(m_takenOver, [&](const auto& held) {
               if (held.first != id && held.second != id)
                   return false;
               if (auto link = m_handLinks.find(held.second); link != m_handLinks.end()) {
                   link->second.guides = false;
                   if (link->second.feels == 0)
                       m_handLinks.erase(link);
               }
               return true;
           }) > 0;
}

bool SessionPolicy::viewTooLarge(const ViewSpec& v) const {
    return int64_t(v.width) * int64_t(v.height) > m_config.maxViewPixels;
}

void SessionPolicy::countSwitches() {
    m_switchesWaiting = int(std::count_if(m_peers.begin(), m_peers.end(), [](const auto& kv) {
        return kv.second.modeSwitch.pending();
    }));
}

} // namespace trephine::net

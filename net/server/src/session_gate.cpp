#include "net/session_gate.h"

#include "libsim/error.h"

#include <sodium.h>

#include <algorithm>

namespace trephine::net {

nlohmann::ordered_json securityJson(const SecurityCounters& c) {
    return {{"handshakes", c.handshakes},
            {"codes_refused", c.codesRefused},
            {"attempts_limited", c.attemptsLimited},
            {"removed", c.removed},
            {"removed_refused", c.removedRefused},
            {"removals_refused", c.removalsRefused},
            {"forged_dropped", c.forged},
            {"replayed_dropped", c.replayed},
            {"spoofed_dropped", c.spoofed},
            {"unauthenticated_dropped", c.unauthenticated},
            {"codes_issued", c.codesIssued},
            {"new_codes_refused", c.newCodesRefused}};
}

SessionGate::SessionGate(const ServerConfig& config, ReportBook& book) : m_book(book) {
    const bool trainee = !config.traineeCode.empty(), instructor = !config.instructorCode.empty();
    if (!trainee && !instructor)
        return;
    if (trainee != instructor)
        throw Error("server: give both codes (--trainee-code and --instructor-code), or --open");
    const std::string t = normaliseCode(config.traineeCode, "--trainee-code");
    const std::string i = normaliseCode(config.instructorCode, "--instructor-code");
    if (t == i)
        throw Error("server: the trainee and instructor codes are the same: a trainee could act "
                    "as the instructor");
    initSodium();
    Codes c;
    randombytes_buf(c.salt.data(), c.salt.size()); // fresh per server: no table of codes carries
    c.trainee = codeScalar(t, c.salt);
    c.instructor = codeScalar(i, c.salt);
    m_codes = c;
}

void SessionGate::count(uint64_t SecurityCounters::*counter) {
    m_book.record([&](ServerReport& r) { ++(r.security.*counter); });
}

std::vector<uint8_t> SessionGate::connect(uint16_t id, const ENetAddress& address) {
    Peer& p = m_peers[id] = Peer{};
    p.host = address.host;
    Handshake challenge;
    challenge.step = Handshake::Step::Challenge;
    challenge.open = open();
    if (m_codes)
        challenge.salt = m_codes->salt;
    return encodeMessage(challenge);
}

SessionGate::Bucket& SessionGate::bucket(uint32_t host, uint64_t now) {
    // Full buckets hold nothing worth keeping: dropped when the map grows, so addresses cannot
    // grow it without bound.
    if (m_buckets.size() >= 4096)
        std::erase_if(m_buckets, [&](const auto& kv) {
            return kv.second.tokens +
                       double(now - kv.second.atUs) * 1e-6 / AttemptLimit::kRefillS >=
                   AttemptLimit::kBurst;
        });
    auto [it, fresh] = m_buckets.try_emplace(host);
    Bucket& b = it->second;
    if (fresh)
        b.atUs = now;
    b.tokens = std::min(AttemptLimit::kBurst,
                        b.tokens + double(now - b.atUs) * 1e-6 / AttemptLimit::kRefillS);
    b.atUs = now;
    return b;
}

bool SessionGate::firstInLine(const Peer& p) const {
    for (const auto& [id, q] : m_peers)
        if (q.stage == Peer::Stage::Waiting && q.host == p.host && q.turn < p.turn)
            return false;
    return true;
}

bool SessionGate::mayAnswer(const Peer& p, uint64_t now) {
    Bucket& b = bucket(p.host, now);
    if (b.tokens >= 1.0) {
        b.tokens -= 1.0; // given back when the code is proven
        return true;
    }
    if (now < b.nextExcessUs)
        return false;
    m_excessTokens = std::min(AttemptLimit::kExcessInAllPerS,
                              m_excessTokens + double(now - std::min(now, m_excessAtUs)) * 1e-6 *
                                                   AttemptLimit::kExcessInAllPerS);
    m_excessAtUs = now;
    if (m_excessTokens < 1.0)
        return false;
    m_excessTokens -= 1.0;
    b.nextExcessUs = now + uint64_t(AttemptLimit::kExcessS * 1e6);
    return true;
}

bool SessionGate::answer(Peer& p) {
    Handshake answer;
    answer.step = Handshake::Step::Answer;
    std::vector<std::pair<Role, const Bytes32*>> codes{{Role::Trainee, &m_codes->trainee}};
    if (p.wanted == Role::Instructor)
        codes.insert(codes.begin(), {Role::Instructor, &m_codes->instructor});
    for (const auto& [role, w] : codes) {
        const auto a = spakeAnswer(*w, m_codes->salt, p.wanted, role, p.share);
        if (!a) {
            p.answers.clear();
            return false;
        }
        answer.entries.push_back({role, a->share, a->keys.serverConfirm});
        p.answers.emplace_back(role, a->keys);
    }
    p.stage = Peer::Stage::Answered;
    m_reply = encodeMessage(answer);
    return true;
}

std::vector<uint16_t> SessionGate::held() const {
    std::vector<uint16_t> ids;
    for (const auto& [id, p] : m_peers)
        if (p.stage == Peer::Stage::Waiting)
            ids.push_back(id);
    return ids;
}

bool SessionGate::progressing(uint16_t id) const {
    auto it = m_peers.find(id);
    return it != m_peers.end() && it->second.stage != Peer::Stage::Connected &&
           it->second.stage != Peer::Stage::Refused;
}

std::vector<std::pair<uint16_t, std::vector<uint8_t>>> SessionGate::release(uint64_t now) {
    std::vector<std::pair<uint16_t, std::vector<uint8_t>>> out;
    std::vector<std::pair<uint64_t, uint16_t>> waiting;
    for (const auto& [id, p] : m_peers)
        if (p.stage == Peer::Stage::Waiting)
            waiting.push_back({p.turn, id});
    std::sort(waiting.begin(), waiting.end());
    // In arrival order, each address's first waiting offer only: the others wait behind it.
    std::set<uint32_t> seen;
    for (const auto& [turn, id] : waiting) {
        Peer& p = m_peers.at(id);
        if (!seen.insert(p.host).second || !mayAnswer(p, now))
            continue;
        if (answer(p))
            out.push_back({id, m_reply});
        else
            p.stage = Peer::Stage::Refused; // not a point of the group: nothing more from it
    }
    return out;
}

SessionGate::Result SessionGate::refuse(Peer& p, RefuseReason why, uint32_t detail,
                                        uint64_t SecurityCounters::*counter) {
    p.stage = Peer::Stage::Refused;
    count(counter);
    Result r;
    r.kind = Result::Kind::Refuse;
    r.refuse = uint32_t(why) | (detail << 8);
    return r;
}

SessionGate::Result SessionGate::receive(uint16_t id, Channel channel,
                                         std::span<const uint8_t> data, uint64_t now) {
    Result r;
    auto it = m_peers.find(id);
    if (it == m_peers.end() || it->second.stage == Peer::Stage::Refused)
        return r;
    Peer& p = it->second;
    if (p.stage == Peer::Stage::Secure)
        return openSealed(p, channel, data);
    const uint8_t type = peekMessageType(data);
    if (!m_codes) {
        // An open session: the hello names the role, and a removed address cannot take it.
        Hello h;
        if (type == uint8_t(MessageType::Hello) && decodeMessage(data, h)) {
            p.wanted = h.role;
            if (m_removed.count({p.host, h.role}))
                return refuse(p, RefuseReason::Removed, 0, &SecurityCounters::removedRefused);
        }
        r.kind = Result::Kind::Deliver;
        r.message = data;
        return r;
    }
    if (type == uint8_t(MessageType::Hello)) // a client without a code
        return refuse(p, RefuseReason::WrongCode, uint32_t(CodeRefusal::None),
                      &SecurityCounters::codesRefused);
    if (type != uint8_t(MessageType::Handshake)) {
        count(&SecurityCounters::unauthenticated);
        return r;
    }
    return handshake(p, data, now);
}

SessionGate::Result SessionGate::handshake(Peer& p, std::span<const uint8_t> data, uint64_t now) {
    Result r;
    Handshake m;
    if (!decodeMessage(data, m))
        return r;
    if (m.step == Handshake::Step::Offer && p.stage == Peer::Stage::Connected) {
        if (m_removed.count({p.host, m.role}))
            return refuse(p, RefuseReason::Removed, 0, &SecurityCounters::removedRefused);
        p.wanted = m.role;
        p.share = m.share;
        p.stage = Peer::Stage::Waiting;
        p.turn = m_nextTurn++;
        if (!firstInLine(p) || !mayAnswer(p, now)) {
            count(&SecurityCounters::attemptsLimited);
            r.kind = Result::Kind::Held;
            return r;
        }
        if (!answer(p)) { // not a point of the group: malformed
            p.stage = Peer::Stage::Connected;
            return r;
        }
        r.kind = Result::Kind::Reply;
        r.message = m_reply;
        return r;
    }
    if (m.step == Handshake::Step::Confirm && p.stage == Peer::Stage::Answered) {
        if (m.entry >= p.answers.size() || !sameMac(m.mac, p.answers[m.entry].second.clientConfirm))
            return refuse(p, RefuseReason::WrongCode, uint32_t(CodeRefusal::Wrong),
                          &SecurityCounters::codesRefused);
        const auto& [role, keys] = p.answers[m.entry];
        if (role != p.wanted)
            return refuse(p, RefuseReason::WrongCode, uint32_t(CodeRefusal::TraineeAsInstructor),
                          &SecurityCounters::codesRefused);
        Bucket& b = bucket(p.host, now);
        b.tokens = std::min(AttemptLimit::kBurst, b.tokens + 1.0);
        p.channel.emplace(keys, true);
        p.answers.clear();
        p.stage = Peer::Stage::Secure;
        count(&SecurityCounters::handshakes);
        r.kind = Result::Kind::Proven;
        r.role = role;
        return r;
    }
    return r; // a step out of order
}

SessionGate::Result SessionGate::openSealed(Peer& p, Channel channel,
                                            std::span<const uint8_t> data) {
    Result r;
    switch (p.channel->open(channel, data, m_plain)) {
    case SecureChannel::Opened::Ok:
        r.kind = Result::Kind::Deliver;
        r.message = m_plain;
        return r;
    case SecureChannel::Opened::Forged:
        count(&SecurityCounters::forged);
        return r;
    case SecureChannel::Opened::Replayed:
        count(&SecurityCounters::replayed);
        return r;
    }
    return r;
}

bool SessionGate::sealing(uint16_t id) const {
    auto it = m_peers.find(id);
    return it != m_peers.end() && it->second.channel.has_value();
}

std::vector<uint8_t> SessionGate::seal(uint16_t id, Channel channel,
                                       std::span<const uint8_t> plain) {
    auto it = m_peers.find(id);
    if (it == m_peers.end() || !it->second.channel)
        return {plain.begin(), plain.end()};
    return it->second.channel->seal(channel, plain);
}

void SessionGate::leave(uint16_t id) {
    m_peers.erase(id);
}

void SessionGate::remove(uint16_t id) {
    auto it = m_peers.find(id);
    if (it == m_peers.end())
        return;
    // The role its code proved (the one it asked for); in an open session, its hello's.
    m_removed.insert({it->second.host, it->second.wanted});
    count(&SecurityCounters::removed);
}

void SessionGate::allowRejoin() {
    m_removed.clear();
}

} // namespace trephine::net

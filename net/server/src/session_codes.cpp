#include "net/session_codes.h"

#include "net/net_stats.h"
#include "net/secure_channel.h"
#include "net/session_gate.h"
#include "net/session_policy.h"

#include <sodium.h>

#include <fmt/format.h>

namespace trephine::net {

std::string codeIssuedLine(Role role, const std::string& code, const std::string& byName) {
    return fmt::format("new {} code {} (issued by {}; the old one no longer joins)",
                       role == Role::Instructor ? "instructor" : "trainee", code, byName);
}

std::string codeText(const std::string& code) {
    return code.size() <= kMaxCodeTextBytes ? code : normaliseCode(code);
}

std::vector<std::string> issueCodes(SessionGate& gate, SessionPolicy& policy, PolicyOutput& out) {
    std::vector<std::string> lines;
    for (const CodeRequest& r : std::exchange(out.newCodes, {})) {
        const std::string code = gate.issue(r.role);
        if (code.empty())
            continue; // an open session's gate has no codes (the policy asks none of it)
        policy.codeIssued(r.role, code, out);
        lines.push_back(codeIssuedLine(r.role, code, r.byName));
    }
    return lines;
}

MintedCode mintCode(const Salt& salt) {
    MintedCode m;
    m.code = generateCode();
    m.w = codeScalar(normaliseCode(m.code), salt);
    return m;
}

// [SECTION] the mint

void CodeMint::start(const CodeRequest& r, const Salt& salt, uint64_t now) {
    m_hashing.insert(r.role);
    m_worker->post([this, r, salt, now] {
        const uint64_t t0 = steadyNowUs();
        MintedCode minted = mintCode(salt);
        const uint64_t us = steadyNowUs() - t0;
        std::lock_guard lock(m_mutex);
        m_done.push_back({r, std::move(minted), us, now});
    });
}

void CodeMint::request(const CodeRequest& r, const Salt& salt, uint64_t now) {
    if (m_hashing.count(r.role) || now < m_turnUs[r.role])
        m_waiting[r.role] = {r, salt}; // the newest request wins
    else
        start(r, salt, now);
}

std::vector<CodeMint::Done> CodeMint::take(uint64_t now) {
    std::vector<Done> out;
    for (;;) {
        std::vector<Done> done;
        {
            std::lock_guard lock(m_mutex);
            done.swap(m_done);
        }
        for (Done& d : done) {
            m_hashing.erase(d.request.role);
            m_turnUs[d.request.role] = d.startedUs + uint64_t(double(d.us) / kDutyCycle);
            out.push_back(std::move(d));
        }
        // Waiting requests whose turn has come; an inline worker hashes them at once: again.
        bool started = false;
        for (auto it = m_waiting.begin(); it != m_waiting.end();) {
            const Role role = it->first;
            if (m_hashing.count(role) || now < m_turnUs[role]) {
                ++it;
                continue;
            }
            const auto [r, salt] = it->second;
            it = m_waiting.erase(it);
            start(r, salt, now);
            started = true;
        }
        if (!started)
            return out;
    }
}

// [SECTION] the gate

std::optional<Salt> SessionGate::salt() const {
    if (!m_codes)
        return std::nullopt;
    return m_codes->salt;
}

std::string SessionGate::issue(Role role) {
    if (!m_codes)
        return {}; // the policy refuses any request in an open session
    MintedCode m;
    do
        m = mintCode(m_codes->salt); // the Challenge's salt, still
    while (!install(role, m.w));
    return m.code;
}

bool SessionGate::install(Role role, const Bytes32& w) {
    if (!m_codes)
        return false;
    // 40 random bits: the other role's code again is unlikely, and would make roles one.
    if (w == (role == Role::Trainee ? m_codes->instructor : m_codes->trainee))
        return false;
    (role == Role::Trainee ? m_codes->trainee : m_codes->instructor) = w;
    // A handshake answered with the old code must not end in the session: its confirmation can
    // no longer match, so it is refused as a wrong code.
    for (auto& [id, p] : m_peers)
        for (auto& [answered, keys] : p.answers)
            if (answered == role)
                randombytes_buf(keys.clientConfirm.data(), keys.clientConfirm.size());
    std::erase_if(m_removed, [&](const auto& r) { return r.second == role; });
    count(&SecurityCounters::codesIssued);
    return true;
}

// [SECTION] the policy

bool SessionPolicy::codes(uint16_t id, const Peer& p, std::span<const uint8_t> data,
                          PolicyOutput& out) {
    Codes m;
    if (!decodeMessage(data, m) || m.op != Codes::Op::Issue)
        return false; // the codes themselves only ever come from the server
    if (p.helloMsg.role != Role::Instructor || m_config.traineeCode.empty()) {
        m_book.record([](ServerReport& r) { ++r.security.newCodesRefused; });
        return true;
    }
    out.newCodes.push_back({m.role, id, p.helloMsg.name});
    return true;
}

void SessionPolicy::codeIssued(Role role, const std::string& code, PolicyOutput& out) {
    if (code.empty())
        return;
    (role == Role::Trainee ? m_config.traineeCode : m_config.instructorCode) = code;
    const Role instructor = Role::Instructor;
    sendCodes(participants(0, &instructor), out);
}

void SessionPolicy::sendCodes(std::vector<uint16_t> to, PolicyOutput& out) const {
    if (m_config.traineeCode.empty() || to.empty())
        return;
    Codes m;
    m.op = Codes::Op::Current;
    m.trainee = codeText(m_config.traineeCode);
    m.instructor = codeText(m_config.instructorCode);
    out.messages.push_back({std::move(to), Channel::Control, encodeMessage(m)});
}

} // namespace trephine::net

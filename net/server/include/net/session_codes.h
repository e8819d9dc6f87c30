// Role codes issued while the server runs (docs/security.md, "New codes"): an instructor asks for
// a new trainee or instructor code (Codes), the gate makes it and replaces the old one, and every
// instructor is sent the session's codes. The policy's request reaches the gate through
// PolicyOutput::newCodes, as a removal does.
#pragma once

#include "net/executor.h"
#include "net/protocol.h"
#include "net/secure_channel.h"

#include <cstdint>
#include <map>
#include <mutex>
#include <optional>
#include <set>
#include <string>
#include <vector>

namespace trephine::net {

class SessionGate;
class SessionPolicy;
struct PolicyOutput;

// An instructor's request for a new code of `role`: its client id and its name in the roster.
struct CodeRequest {
    Role role = Role::Trainee;
    uint16_t by = 0;
    std::string byName;
};

// The line (without the "trephine server: " prefix) the server prints for a new code.
std::string codeIssuedLine(Role role, const std::string& code, const std::string& byName);

// A code as an instructor's window shows it: as given when it fits kMaxCodeTextBytes, else its
// normalised form (normaliseCode).
std::string codeText(const std::string& code);

// A new code and its hash with the session's salt (codeScalar: crypto_pwhash, ~20 ms).
struct MintedCode {
    std::string code;
    Bytes32 w{};
};
MintedCode mintCode(const Salt& salt);

// New codes hashed apart from the network thread, newest wins per role: a request while that
// role's code is being hashed, or waits for its turn, replaces the one waiting. A role's hashing
// takes at most kDutyCycle of the time (a hash of d starts the next d / kDutyCycle after it
// began), so an instructor asking 200 times a second costs a hundredth of one low-priority core,
// not the network thread. An 8 MiB hash slows whatever shares the cores while it runs: at a tenth
// a trainee's update p99 read 4-10x, at a hundredth within 1.3x (docs/session.md,
// "Availability"); an honest instructor's second code of a role within ~1 s waits that long.
class CodeMint {
public:
    static constexpr double kDutyCycle = 0.01;
    struct Done {
        CodeRequest request;
        MintedCode minted;
        uint64_t us = 0;        // the hashing's time, charged to the requester
        uint64_t startedUs = 0; // the server's time when it was started
    };
    // `worker` runs the hashing (inline: at request()); it outlives this.
    explicit CodeMint(Executor& worker) : m_worker(&worker) {}
    ~CodeMint() { m_worker->cancel(); }
    CodeMint(const CodeMint&) = delete;
    CodeMint& operator=(const CodeMint&) = delete;
    // [Before any request] Where the hashing runs from now on.
    void setWorker(Executor& worker) { m_worker = &worker; }

    // [Network thread] `now`: the server's time (microseconds).
    void request(const CodeRequest& r, const Salt& salt, uint64_t now);
    // The codes hashed since the last call, oldest first; a request whose turn has come starts.
    std::vector<Done> take(uint64_t now);
    bool busy() const { return !m_hashing.empty() || !m_waiting.empty(); }

private:
    void start(const CodeRequest& r, const Salt& salt, uint64_t now);

    Executor* m_worker;
    // [Network thread] The roles being hashed, when each may start its next, what waits.
    std::set<Role> m_hashing;
    std::map<Role, uint64_t> m_turnUs;
    std::map<Role, std::pair<CodeRequest, Salt>> m_waiting;
    std::mutex m_mutex;       // the worker's results
    std::vector<Done> m_done; // under m_mutex
};

// The network thread's step for `out.newCodes`: the gate issues each code, the policy tells every
// instructor (into `out.messages`). Returns the lines to print, one per code.
std::vector<std::string> issueCodes(SessionGate& gate, SessionPolicy& policy, PolicyOutput& out);

} // namespace trephine::net

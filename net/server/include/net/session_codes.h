// Role codes issued while the server runs (docs/security.md, "New codes"): an instructor asks for
// a new trainee or instructor code (Codes), the gate makes it and replaces the old one, and every
// instructor is sent the session's codes. The policy's request reaches the gate through
// PolicyOutput::newCodes, as a removal does.
#pragma once

#include "net/protocol.h"

#include <cstdint>
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

// The network thread's step for `out.newCodes`: the gate issues each code, the policy tells every
// instructor (into `out.messages`). Returns the lines to print, one per code.
std::vector<std::string> issueCodes(SessionGate& gate, SessionPolicy& policy, PolicyOutput& out);

} // namespace trephine::net

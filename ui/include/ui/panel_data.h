// The window's own panel state as plain structs (take-over script, marks and their undo); the
// histories the panels plot live in the client model (net/client_model.h). Tested without GL.
#pragma once

#include "libsim/dbi.h"
#include "net/client_model.h"
#include "net/protocol.h"

#include <cstdint>
#include <deque>
#include <glm/vec3.hpp>
#include <map>
#include <optional>
#include <string>
#include <vector>

namespace trephine::ui {

// The histories the panels plot are the client model's (net/client_model.h): the window and the
// headless trainee fold them from the same snapshots with the same code.
using net::ComparisonFigures;
using net::ComparisonHistory;
using net::DirtyBoxHistory;
using net::ForceHistory;
using net::kSyncDesignCount;
using net::NetworkHistory;
using net::ParticipantForces;
using net::SyncDesign;
using net::syncDesignName;

// `--take-over NAME|ID`: the trainee to take over now, once per connection. A reconnect (a new
// connection attempt) asks again: the server hands a trainee back when its instructor leaves.
struct ScriptedTakeOver {
    std::string who; // a trainee's name or id; empty: none asked for
    int sentOnAttempt = -1;
    // The trainee to send a TakeOver for on connection `attempt`, if one is listed and none was
    // sent on this connection yet (marks it sent).
    std::optional<uint16_t> due(int attempt,
                                const std::map<uint16_t, net::ParticipantInfo>& participants);
};

// The label of a mark placed without one: "mark N", N the number of marks + 1, or the next number
// no mark's label already has (after a removal, "mark 2" may still be on the skull).
std::string defaultMarkLabel(const std::vector<net::AnnotationInfo>& marks);

// One step of undo for an instructor's removals: *remove* or *clear marks* takes marks off the
// skull for everyone, and a slip of the mouse must not lose them. Remembers what the last
// removal took (as the list showed it) and turns it back into Adds (new ids, same places and
// labels). A removal replaces what was remembered; nothing is kept across windows.
class MarkUndo {
public:
    // Call with the list as shown, before the Remove or Clear is sent.
    void removing(const std::vector<net::AnnotationInfo>& shown, uint32_t id);
    void clearing(const std::vector<net::AnnotationInfo>& shown);
    // The Adds that put the last removal back; forgets it.
    std::vector<net::Annotate> undo();
    size_t pending() const { return m_taken.size(); }

private:
    std::vector<net::AnnotationInfo> m_taken;
};

} // namespace trephine::ui

// Instructor view-as: which instructor watches through which participant's camera, and every
// participant's current view (its hello's, then its newest view request's), as the server's
// network thread keeps them. Pure bookkeeping, tested without sockets: the server sends what it
// returns as ParticipantView messages (docs/protocol.md), and the instructor asks for that view
// like any other, so nothing is rendered twice (clients with equal cameras share a render).
#pragma once

#include "net/protocol.h"

#include <cstdint>
#include <map>
#include <optional>
#include <vector>

namespace trephine::net {

class ViewFollowers {
public:
    // `id`'s view is now `view`: the followers to send it to.
    std::vector<uint16_t> setView(uint16_t id, const ViewSpec& view);
    // `follower` watches through `target`'s camera from now on (0: its own again). The target's
    // view when it is known (a participant that said hello), to send at once.
    std::optional<ViewSpec> follow(uint16_t follower, uint16_t target);
    // `id` left: its view and whom it followed are forgotten, and those following it stop.
    void leave(uint16_t id);
    // Whom `follower` watches through (0: nobody).
    uint16_t following(uint16_t follower) const;

private:
    std::map<uint16_t, ViewSpec> m_views;
    std::map<uint16_t, uint16_t> m_following; // follower -> target
};

} // namespace trephine::net

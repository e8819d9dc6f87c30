// What the view says about the link to the server: connecting, lost (the picture dimmed), and
// after a few failed attempts the likely causes (wrong address, wrong port, no server running).
#pragma once

#include "net/client_thread.h"

#include <string>

namespace trephine::ui {

// Failed attempts after which the view lists the likely causes.
inline constexpr int kHintAfterFailures = 3;

struct LinkMessage {
    std::string text; // empty: nothing to say
    bool dim = false; // the picture on screen is stale: dim it
};

// `attempts`: connection attempts so far (ClientSnapshot::attempts); `attemptsWhenConnected`:
// that count when the link was last up (-1: never), so only the failures since count.
LinkMessage linkMessage(net::LinkState state, int attempts, int attemptsWhenConnected,
                        const std::string& closeReason, const std::string& address,
                        bool havePicture);

} // namespace trephine::ui

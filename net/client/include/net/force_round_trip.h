// The force round trip through a real session server: a client sends a tool state and times the
// HapticModel that answers it (device sample -> force model back at the client). Used by
// `trephine study haptics` and benchmarks/net; the paper measured 0.82 ms over its LAN.
#pragma once

#include "libsim/tool.h"
#include "net/enet_host.h"

#include <cstdint>
#include <string>

namespace trephine::net {

struct ForceRoundTripConfig {
    ToolShape shape = ToolShape::burr(2.0f);
    ToolPose pose;          // where the tool is held (object space, mm)
    int samples = 1000;     // round trips timed (after a few warm-up ones)
    int warmup = 20;        // round trips not timed
    double rateHz = 1000.0; // tool states per second; one in flight at a time
    double guardS = 30.0;   // give up (returning what was measured) after this long
    std::string code;       // the server's trainee code (docs/security.md); empty: an open session
};

struct ForceRoundTripResult {
    int samples = 0;
    double p50Us = 0, p99Us = 0, meanUs = 0, maxUs = 0;
    double serverP50Us = 0; // serverSentUs - serverReceivedUs: the server's own share
    int contacts = 0;       // models that reported contact
    int lost = 0;           // tool states with no answer within 100 ms
};

// Connects to the server at `server` as a client with a tiny view, waits for its welcome and
// first image, then sends one tool state at a time and waits for its model. Throws
// trephine::Error when the server does not answer.
ForceRoundTripResult measureForceRoundTrip(const ENetAddress& server,
                                           const ForceRoundTripConfig& config);

} // namespace trephine::net

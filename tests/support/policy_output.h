// What a session policy's output (net/session_policy.h) sends one client, for tests that drive
// the policy without sockets.
#pragma once

#include "net/session_policy.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <vector>

namespace trephine::testing {

// Every message of type M in `out` addressed to `id`, decoded.
template <typename M>
std::vector<M> sentTo(const net::PolicyOutput& out, uint16_t id) {
    std::vector<M> found;
    for (const net::PolicyOutput::Message& m : out.messages) {
        if (std::find(m.to.begin(), m.to.end(), id) == m.to.end() ||
            net::peekMessageType(m.bytes) != uint8_t(M::kType))
            continue;
        M decoded;
        EXPECT_TRUE(net::decodeMessage(m.bytes, decoded));
        found.push_back(std::move(decoded));
    }
    return found;
}

} // namespace trephine::testing

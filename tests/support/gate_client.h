// The client's side of the role-code handshake against a SessionGate (docs/security.md), as
// SessionClient runs it, for tests that drive the gate without sockets.
#pragma once

#include "net/protocol.h"
#include "net/secure_channel.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <optional>
#include <span>
#include <string>
#include <vector>

namespace trephine::testing {

struct GateClient {
    explicit GateClient(std::string c, net::Role r = net::Role::Trainee)
        : code(std::move(c)), role(r) {}
    std::string code;
    net::Role role;
    std::optional<net::Bytes32> w; // the code's hash, kept: a guesser's next attempt reuses it
    std::optional<net::SpakeClient> spake;
    std::optional<net::SessionKeys> keys;

    std::vector<uint8_t> offer(std::span<const uint8_t> challengeBytes) {
        net::Handshake c;
        EXPECT_TRUE(net::decodeMessage(challengeBytes, c));
        net::Salt salt;
        std::copy(c.salt.begin(), c.salt.end(), salt.begin());
        if (!w)
            w = net::codeScalar(net::normaliseCode(code), salt);
        spake.emplace(*w, salt, role);
        net::Handshake o;
        o.step = net::Handshake::Step::Offer;
        o.role = role;
        o.share = spake->share();
        return net::encodeMessage(o);
    }
    std::vector<uint8_t> confirm(std::span<const uint8_t> answerBytes) {
        net::Handshake a;
        EXPECT_TRUE(net::decodeMessage(answerBytes, a));
        net::Handshake c;
        c.step = net::Handshake::Step::Confirm;
        for (size_t i = 0; i < a.entries.size(); ++i) {
            const auto k = spake->keys(a.entries[i].share, a.entries[i].role);
            if (k && net::sameMac(k->serverConfirm, a.entries[i].mac)) {
                c.entry = uint8_t(i);
                c.mac = k->clientConfirm;
                keys = k;
            }
        }
        return net::encodeMessage(c);
    }
};

} // namespace trephine::testing

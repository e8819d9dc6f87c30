// A session recorded in-process for the replay tests: a server with a recorder on the 48^3
// sphere, pumped by the caller's thread, and a trainee, Ada, drilling two strokes of 12 tool
// states, one after the other.
#pragma once

#include "net/replay_feed.h"
#include "net/session_client.h"
#include "net/session_log.h"
#include "net/session_server.h"

#include "libsim/skull.h"

#include "loopback.h"

#include <gtest/gtest.h>

#include <string>

namespace trephine::testing {

inline net::LogContents recordTwoStrokes(const std::string& log) {
    using namespace trephine::net;
    constexpr int kN = 48;
    const Volume sphere = makeSphere(kN);
    ServerConfig c = loopbackServerConfig("sphere:48");
    c.recorder = SessionRecorder::create(log, makeLogHeader(sphere, c, "sphere:48", false, 1));
    {
        SessionServer server(sphere, c);
        Pumped pumped(server);
        SessionClient ada(namedClientConfig(sphere, "Ada", Role::Trainee, 40));
        ada.connect(loopback(server.port()));
        EXPECT_TRUE(pumpUntil({&ada}, [&] { return ada.hasFullImage(); }));
        uint64_t sent = 0;
        for (float degrees : {0.0f, 50.0f}) {
            const float a = glm::radians(degrees);
            const glm::vec3 normal(std::sin(a), 0.0f, std::cos(a));
            const SurfaceSite site{normal * sphereRadiusMm(kN), normal};
            for (int i = 0; i < 12; ++i, ++sent) {
                net::ToolState t = burrState(site, i, 12, 1000000 + sent * 10000);
                t.sequence = uint32_t(sent + 1); // the server applies newer sequences only
                ada.sendToolState(t);
                pollAll({&ada});
            }
            EXPECT_TRUE(pumpUntil({&ada}, [&] { return server.toolStatesApplied() >= sent; }));
        }
        ada.disconnect();
        server.stop();
    }
    c.recorder.reset(); // the log is closed before it is read
    return readSessionLog(log);
}

} // namespace trephine::testing

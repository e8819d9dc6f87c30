// Loopback session helpers for net and ui tests: a server config on a port the OS picks, the
// loopback address of a port, and pumping clients until a condition holds.
#pragma once

#include "libsim/skull.h"
#include "libsim/tool.h"
#include "net/client_thread.h"
#include "net/codec.h"
#include "net/enet_host.h"
#include "net/net_stats.h"
#include "net/session_client.h"
#include "net/session_server.h"
#include "net/view.h"

#include <glm/gtx/quaternion.hpp>
#include <gtest/gtest.h>

#include <random>

#include <atomic>
#include <chrono>
#include <exception>
#include <functional>
#include <memory>
#include <string>
#include <thread>
#include <vector>

namespace trephine::testing {

// A server on any free port (see SessionServer::port()) serving the named built-in volume.
inline net::ServerConfig loopbackServerConfig(const std::string& volumeName,
                                              int renderThreads = 1) {
    net::ServerConfig c;
    c.port = 0;
    c.volumeName = volumeName;
    c.renderThreads = renderThreads;
    return c;
}

// A client of `role` called `name` looking at `v` from the top in a window x window view.
inline net::ClientConfig namedClientConfig(const Volume& v, const std::string& name, net::Role role,
                                           int window) {
    net::ClientConfig c;
    c.name = name;
    c.role = role;
    c.view = net::toViewSpec(cameraPreset("top", v, {window, window}));
    return c;
}

inline ENetAddress loopback(uint16_t port) {
    return net::parseAddress("127.0.0.1:" + std::to_string(port));
}

// A server the test pumps on its own thread instead of starting the server's threads: while it
// lives, every wait below (pumpUntil, pollAll, waitFor, drillThrough) pumps it, with the steady
// clock plus the time the test has skipped. One thread runs the whole session, so nothing races
// and a timeout is reached by skipping time, not by sleeping.
class Pumped {
public:
    explicit Pumped(net::SessionServer& server) : m_server(&server), m_list(&all()) {
        m_list->push_back(this);
    }
    // From the list of the thread that made it, whichever thread ends it.
    ~Pumped() { std::erase(*m_list, this); }
    Pumped(const Pumped&) = delete;
    Pumped& operator=(const Pumped&) = delete;

    // The server's clock jumps `seconds` ahead (its next pass sees the time passed).
    void skip(double seconds) { m_skippedUs += uint64_t(seconds * 1e6); }
    uint64_t now() const { return net::steadyNowUs() + m_skippedUs; }
    void pump() { m_server->pump(now()); }

    // One pass of every server this thread pumps.
    static void pumpAll() {
        for (Pumped* p : all())
            p->pump();
    }

private:
    static std::vector<Pumped*>& all() {
        thread_local std::vector<Pumped*> pumped;
        return pumped;
    }
    net::SessionServer* m_server;
    std::vector<Pumped*>* m_list;
    uint64_t m_skippedUs = 0;
};

// One round: every pumped server passes once, then every client polls (1 ms each).
inline void pollAll(const std::vector<net::SessionClient*>& clients) {
    Pumped::pumpAll();
    for (net::SessionClient* c : clients)
        c->poll(1);
}

// Polls every client (1 ms each), and pumps every pumped server, until pred() holds; false once
// the guard deadline passes. The guard only stops a hung test: tests never assert on how long
// this takes.
inline bool pumpUntil(const std::vector<net::SessionClient*>& clients,
                      const std::function<bool()>& pred, double guardS = 60.0) {
    auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(guardS);
    while (std::chrono::steady_clock::now() < deadline) {
        pollAll(clients);
        if (pred())
            return true;
    }
    return false;
}

// A whole volume too large for one message even compressed: noise, 330^3 voxels of 0.5 mm
// (~45 MB in zstd, over the 30 MiB ENet delivers). A volume client of it is refused
// (RefuseReason::VolumeTooLarge).
inline Volume incompressibleVolume() {
    Volume noise({330, 330, 330}, glm::vec3(0.5f));
    std::mt19937 rng(7);
    for (size_t i = 0; i < noise.voxelCount(); ++i) {
        const uint32_t r = rng();
        const uint8_t d = uint8_t(r);
        noise.densityData()[i] = d;
        noise.materialData()[i] = d ? uint8_t(1 + (r >> 8) % 4) : uint8_t(Material::Air);
    }
    return noise;
}

// A raw ENet host standing in for a server, so a test can send a client hand-made messages.
struct FakeServer {
    net::Host host = net::Host::listen(0, 2);
    ENetPeer* peer = nullptr; // the client, once it has connected

    uint16_t port() const { return host.port(); }
    void send(net::Channel channel, const std::vector<uint8_t>& bytes) {
        host.send(peer, channel, bytes);
    }
    // Services this host and `client` (1 ms each) until pred() holds; false after the guard.
    bool pumpWith(net::SessionClient& client, const std::function<bool()>& pred,
                  double guardS = 20.0) {
        auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(guardS);
        while (std::chrono::steady_clock::now() < deadline) {
            host.service(1, [&](const ENetEvent& e) {
                if (e.type == ENET_EVENT_TYPE_CONNECT)
                    peer = e.peer;
            });
            client.poll(1);
            if (pred())
                return true;
        }
        return false;
    }
};

// A burr stroke: the 5 mm burr starts 1 mm above the site and feeds 2.5 mm in along the normal
// over `count` states 10 ms apart (client time), drilling at full speed. State i of the stroke.
inline net::ToolState burrState(const SurfaceSite& site, int i, int count, uint64_t baseUs) {
    net::ToolState t;
    t.sequence = uint32_t(i + 1);
    t.clientTimeUs = baseUs + uint64_t(i) * 10000;
    t.toolKind = uint8_t(ToolKind::Burr);
    t.diameterMm = 5.0f;
    float depth = -1.0f + 3.5f * float(i) / float(count);
    t.position = site.position - site.normal * depth;
    t.orientation = glm::rotation(glm::vec3(0, 0, 1), site.normal);
    t.speed = 1.0f;
    t.drilling = true;
    return t;
}

// What a zstd or lz4 client should hold for `view`: the server's render with its depth through
// the quantiser (DepthQuantizer), colour as it is.
inline Dbi quantised(const Dbi& render, const net::ViewSpec& view) {
    net::DepthQuantizer q(net::toCamera(view));
    Dbi out = render;
    for (int y = 0; y < out.height(); ++y)
        for (int x = 0; x < out.width(); ++x)
            out.depth()[out.index(x, y)] = q.dequantize(q.quantize(render.depth(x, y)));
    return out;
}

// A zstd client (predicted updates) of the paper view (160 x 160) of skull:64 at the paper's
// spacing, joined to its own server (two render threads), which stops with it.
struct PaperZstdSession {
    Volume volume = makeSkull(64);
    net::ViewSpec view;
    std::unique_ptr<net::SessionServer> server;
    std::unique_ptr<Pumped> pumped;
    std::unique_ptr<net::SessionClient> client;

    PaperZstdSession() {
        volume.setSpacing(glm::vec3(paperSpacingMm(64)));
        view = net::toViewSpec(cameraPreset("paper", volume, {160, 160}));
        server = std::make_unique<net::SessionServer>(volume, loopbackServerConfig("skull:64", 2));
        pumped = std::make_unique<Pumped>(*server);
        net::ClientConfig cc;
        cc.codec = net::Codec::Zstd;
        cc.view = view;
        client = std::make_unique<net::SessionClient>(cc);
        client->connect(loopback(server->port()));
        EXPECT_TRUE(pumpUntil({client.get()}, [&] { return client->hasFullImage(); }));
    }
    ~PaperZstdSession() {
        server->stop();
        pumped.reset();
    }
};

// The top of makeSphere(n), facing +z.
inline SurfaceSite sphereTop(int n) {
    return {{0.0f, 0.0f, sphereRadiusMm(n)}, {0.0f, 0.0f, 1.0f}};
}

// Checks `pred` every millisecond until it holds (true) or `seconds` pass (pred's last answer),
// pumping the pumped servers meanwhile: for clients on their own thread (ClientThread).
template <class F>
bool waitFor(F pred, double seconds = 30.0) {
    auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds);
    while (std::chrono::steady_clock::now() < end) {
        Pumped::pumpAll();
        if (pred())
            return true;
        std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
    return pred();
}

// Pumps the pumped servers for `seconds` of the steady clock: a client thread's pace (tool
// states 10 ms apart), not a wait for anything.
inline void pumpFor(double seconds) {
    auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds);
    do {
        Pumped::pumpAll();
        std::this_thread::sleep_for(std::chrono::microseconds(500));
    } while (std::chrono::steady_clock::now() < end);
}

// Runs `steps` on a thread of the test while this thread pumps the server until they return, and
// after each pass runs `between` (what must happen on the pumping thread, such as a stop). The
// session's own timeouts end a step the server never answers; what the steps throw is thrown here.
inline void pumpWhile(const std::function<void()>& steps,
                      const std::function<void()>& between = {}) {
    std::atomic<bool> done = false;
    std::exception_ptr thrown;
    std::thread session([&] {
        try {
            steps();
        } catch (...) {
            thrown = std::current_exception();
        }
        done = true;
    });
    while (!done) {
        trephine::testing::pumpFor(0.001);
        if (between)
            between();
    }
    session.join();
    if (thrown)
        std::rethrow_exception(thrown);
}

// Drills at `site` through a ClientThread: `states` 5 mm burr tool states 10 ms apart, 0.08 mm
// deeper each, from 1 mm above.
inline void drillThrough(net::ClientThread& client, const SurfaceSite& site, int states) {
    for (int i = 0; i < states; ++i) {
        net::ToolState t;
        t.toolKind = uint8_t(ToolKind::Burr);
        t.diameterMm = 5.0f;
        t.position = site.position - site.normal * (-1.0f + 0.08f * float(i));
        t.orientation = glm::rotation(glm::vec3(0, 0, 1), site.normal);
        t.speed = 1.0f;
        t.drilling = true;
        EXPECT_TRUE(client.sendToolState(t));
        pumpFor(0.010);
    }
}

} // namespace trephine::testing

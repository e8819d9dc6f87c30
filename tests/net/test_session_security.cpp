// A session with role codes end to end over loopback (docs/security.md): the right codes join in
// their roles, sealed; no code, a wrong code and the trainee code in instructor mode are each
// refused in one line naming the reason, and receive no byte of image, volume, roster, marks or
// forces; a replayed, a tampered and a foreign datagram (through a relay that can do to the
// client's datagrams what an attacker on the path can) are dropped and counted while the session
// goes on; an instructor removes a participant and lets it back. The gate's rules themselves are
// tested without sockets in test_secure_channel.cpp.
#include "net/enet_host.h"
#include "net/protocol.h"
#include "net/session_client.h"
#include "net/session_server.h"
#include "net/view.h"

#include "libsim/skull.h"
#include "libsim/stats.h"

#include "loopback.h"

#include <gtest/gtest.h>

#include <poll.h>

#include <algorithm>
#include <atomic>
#include <cstdio>
#include <memory>
#include <mutex>
#include <optional>
#include <random>
#include <thread>

using namespace trephine;
using namespace trephine::net;
using trephine::testing::burrState;
using trephine::testing::loopback;
using trephine::testing::loopbackServerConfig;
using trephine::testing::Pumped;
using trephine::testing::pumpUntil;
using trephine::testing::sphereTop;

namespace {

constexpr const char* kTraineeCode = "QX7M-4KTD";
constexpr const char* kInstructorCode = "HW2R-9PZE";

ServerConfig codedServerConfig() {
    ServerConfig c = loopbackServerConfig("sphere:32");
    c.traineeCode = kTraineeCode;
    c.instructorCode = kInstructorCode;
    return c;
}

ClientConfig member(const Volume& v, const std::string& name, Role role, const std::string& code) {
    ClientConfig c = trephine::testing::namedClientConfig(v, name, role, 32);
    c.code = code;
    return c;
}

// Everything of the session a client received: any of it makes the refusal a leak.
uint64_t sessionBytes(const SessionClient& c) {
    return c.stats().totalBytesIn(Channel::Image) + c.stats().totalBytesIn(Channel::Volume) +
           c.stats().totalBytesIn(Channel::Haptic) + c.stats().totalBytesIn(Channel::ToolState);
}

// [SECTION] a relay on the path

// Relays one client's datagrams to the server and back, like a router on the path. It keeps the
// newest datagram that carries a tool state (an unsequenced packet on the tool channel), can
// flip a bit of the next one, and can send a captured one again, re-framed so ENet takes it for
// a new packet (ENet's headers carry no authentication: an attacker can), from its own address
// or from another.
class Relay {
public:
    explicit Relay(uint16_t serverPort) : m_server(loopback(serverPort)) {
        ENetAddress any{};
        any.host = ENET_HOST_ANY;
        m_front = bound(loopback(0));
        m_back = bound(any);
        m_stranger = bound(any);
        ENetAddress a{};
        enet_socket_get_address(m_front, &a);
        m_port = a.port;
        m_thread = std::thread([this] { run(); });
    }
    ~Relay() {
        m_stop = true;
        m_thread.join();
        for (ENetSocket s : {m_front, m_back, m_stranger})
            enet_socket_destroy(s);
    }
    uint16_t port() const { return m_port; }

    void flipNextToolState() { m_flip = true; }
    uint64_t flipped() const { return m_flipped.load(); }
    bool captured() {
        std::lock_guard lock(m_mutex);
        return m_capture.has_value();
    }
    // The captured tool state again, as a new ENet packet: from the client's address (a replay)
    // or from another one (a stranger naming the client's peer).
    void replay(bool fromStranger) {
        std::vector<uint8_t> d;
        {
            std::lock_guard lock(m_mutex);
            d = m_capture->bytes;
            // Past every group the client used: ENet's own duplicate check lets it through.
            const uint16_t group = uint16_t(m_highestGroup + 1);
            d[m_capture->groupAt] = uint8_t(group >> 8);
            d[m_capture->groupAt + 1] = uint8_t(group);
        }
        ENetBuffer b{d.data(), d.size()};
        enet_socket_send(fromStranger ? m_stranger : m_back, &m_server, &b, 1);
    }

private:
    struct ToolDatagram {
        std::vector<uint8_t> bytes; // the header and the tool state's command only
        size_t groupAt = 0, lastByte = 0;
    };

    static ENetSocket bound(const ENetAddress& at) {
        ENetSocket s = enet_socket_create(ENET_SOCKET_TYPE_DATAGRAM);
        enet_socket_set_option(s, ENET_SOCKOPT_NONBLOCK, 1);
        EXPECT_EQ(enet_socket_bind(s, &at), 0);
        return s;
    }

    // The unsequenced tool-channel command in an ENet datagram, if it has one.
    std::optional<ToolDatagram> toolCommand(const std::vector<uint8_t>& d) {
        if (d.size() < 2)
            return std::nullopt;
        const uint16_t header = uint16_t(d[0] << 8 | d[1]);
        const size_t headerSize = (header & ENET_PROTOCOL_HEADER_FLAG_SENT_TIME) ? 4 : 2;
        auto be16 = [&](size_t at) { return size_t(d[at] << 8 | d[at + 1]); };
        for (size_t pos = headerSize; pos + 4 <= d.size();) {
            const uint8_t command = d[pos] & ENET_PROTOCOL_COMMAND_MASK;
            const size_t size = enet_protocol_command_size(command);
            if (size == 0 || pos + size > d.size())
                return std::nullopt;
            size_t data = 0;
            if (command == ENET_PROTOCOL_COMMAND_SEND_RELIABLE)
                data = be16(pos + 4);
            else if (command == ENET_PROTOCOL_COMMAND_SEND_UNRELIABLE ||
                     command == ENET_PROTOCOL_COMMAND_SEND_UNSEQUENCED ||
                     command == ENET_PROTOCOL_COMMAND_SEND_FRAGMENT ||
                     command == ENET_PROTOCOL_COMMAND_SEND_UNRELIABLE_FRAGMENT)
                data = be16(pos + 6);
            if (pos + size + data > d.size())
                return std::nullopt;
            if (command == ENET_PROTOCOL_COMMAND_SEND_UNSEQUENCED &&
                d[pos + 1] == uint8_t(Channel::ToolState) && data > 0) {
                ToolDatagram t;
                t.bytes.assign(d.begin(), d.begin() + std::ptrdiff_t(headerSize));
                t.groupAt = t.bytes.size() + 4;
                t.bytes.insert(t.bytes.end(), d.begin() + std::ptrdiff_t(pos),
                               d.begin() + std::ptrdiff_t(pos + size + data));
                t.lastByte = pos + size + data - 1;
                m_highestGroup = std::max<uint32_t>(m_highestGroup, uint32_t(be16(pos + 4)));
                return t;
            }
            pos += size + data;
        }
        return std::nullopt;
    }

    void run() {
        std::vector<uint8_t> buf(4096);
        while (!m_stop) {
            pollfd fds[2] = {{int(m_front), POLLIN, 0}, {int(m_back), POLLIN, 0}};
            if (::poll(fds, 2, 2) <= 0)
                continue;
            ENetAddress from{};
            ENetBuffer b{buf.data(), buf.size()};
            if (fds[0].revents & POLLIN) {
                const int n = enet_socket_receive(m_front, &from, &b, 1);
                if (n > 0) {
                    m_client = from;
                    std::vector<uint8_t> d(buf.begin(), buf.begin() + n);
                    {
                        std::lock_guard lock(m_mutex);
                        if (auto t = toolCommand(d)) {
                            if (m_flip.exchange(false)) {
                                d[t->lastByte] ^= 0x10; // a bit of the tag
                                ++m_flipped;
                            } else {
                                m_capture = std::move(t);
                            }
                        }
                    }
                    ENetBuffer out{d.data(), d.size()};
                    enet_socket_send(m_back, &m_server, &out, 1);
                }
            }
            b = ENetBuffer{buf.data(), buf.size()};
            if (fds[1].revents & POLLIN) {
                const int n = enet_socket_receive(m_back, &from, &b, 1);
                if (n > 0 && m_client.port != 0) {
                    ENetBuffer out{buf.data(), size_t(n)};
                    enet_socket_send(m_front, &m_client, &out, 1);
                }
            }
        }
    }

    EnetLibrary m_lib;
    ENetAddress m_server, m_client{};
    ENetSocket m_front, m_back, m_stranger;
    uint16_t m_port = 0;
    std::mutex m_mutex;
    std::optional<ToolDatagram> m_capture;
    uint32_t m_highestGroup = 0;
    std::atomic<bool> m_flip{false}, m_stop{false};
    std::atomic<uint64_t> m_flipped{0};
    std::thread m_thread;
};

} // namespace

// [SECTION] joining

TEST(SessionSecurity, TheRightCodesJoinInTheirRolesAndTheSessionIsSealed) {
    Volume sphere = makeSphere(32);
    SessionServer server(sphere, codedServerConfig());
    Pumped pumped(server);
    SessionClient ada(member(sphere, "Ada", Role::Trainee, "qx7m 4ktd")); // as read out
    SessionClient cho(member(sphere, "Dr. Cho", Role::Instructor, kInstructorCode));
    std::vector<SessionClient*> all = {&ada, &cho};
    for (SessionClient* c : all)
        c->connect(loopback(server.port()));
    ASSERT_TRUE(pumpUntil(all,
                          [&] {
                              return ada.hasFullImage() && cho.hasFullImage() &&
                                     ada.participants().size() == 2 &&
                                     cho.participants().size() == 2;
                          }))
        << ada.closeReason() << " / " << cho.closeReason();
    EXPECT_TRUE(ada.sealed());
    EXPECT_TRUE(cho.sealed());
    EXPECT_EQ(ada.participants().at(ada.welcome().clientId).role, Role::Trainee);
    EXPECT_EQ(ada.participants().at(cho.welcome().clientId).role, Role::Instructor);
    // The session works sealed: a stroke drills, forces come back, marks reach everyone.
    const SurfaceSite site = sphereTop(32);
    const uint64_t before = ada.updatesApplied();
    for (int i = 0; i < 20; ++i)
        ada.sendToolState(burrState(site, i, 20, steadyNowUs()));
    cho.annotate(Annotate{Annotate::Op::Add, 0, site.position, "here"});
    ASSERT_TRUE(pumpUntil(all, [&] {
        return ada.updatesApplied() > before && ada.hapticModelsReceived() > 0 &&
               ada.annotations().size() == 1 && cho.relaysReceived() > 0;
    }));
    EXPECT_EQ(ada.sealedDropped(), 0u);
    EXPECT_EQ(server.security().handshakes, 2u);
    EXPECT_EQ(server.security().forged + server.security().replayed, 0u);
    std::printf("[ handshake ] trainee %.1f ms, instructor %.1f ms (connect to sealed, the code's "
                "argon2id hash included)\n",
                double(ada.handshakeUs()) * 1e-3, double(cho.handshakeUs()) * 1e-3);
    server.stop();
}

TEST(SessionSecurity, StrangersAreRefusedInOneLineNamingTheReasonAndGetNothing) {
    Volume sphere = makeSphere(32);
    SessionServer server(sphere, codedServerConfig());
    Pumped pumped(server);
    // A session in full swing: a trainee drilling, an instructor's mark.
    SessionClient ada(member(sphere, "Ada", Role::Trainee, kTraineeCode));
    SessionClient cho(member(sphere, "Dr. Cho", Role::Instructor, kInstructorCode));
    std::vector<SessionClient*> members = {&ada, &cho};
    for (SessionClient* c : members)
        c->connect(loopback(server.port()));
    ASSERT_TRUE(pumpUntil(members, [&] { return ada.hasFullImage() && cho.welcomed(); }));
    const SurfaceSite site = sphereTop(32);
    cho.annotate(Annotate{Annotate::Op::Add, 0, site.position, "secret"});

    struct Case {
        const char* what;
        Role role;
        std::string code;
        const char* reason;
    };
    const Case cases[] = {
        {"no code", Role::Trainee, "",
         "this session needs a code: give the one the server "
         "printed (--code)"},
        {"a wrong code", Role::Trainee, "AAAA-BBBB", "wrong session code"},
        {"the trainee code in instructor mode", Role::Instructor, kTraineeCode,
         "that is the trainee code: the instructor's role needs the instructor code"},
    };
    for (const Case& c : cases) {
        SCOPED_TRACE(c.what);
        SessionClient stranger(member(sphere, "Eve", c.role, c.code));
        stranger.connect(loopback(server.port()));
        std::vector<SessionClient*> all = {&ada, &cho, &stranger};
        int i = 0;
        ASSERT_TRUE(pumpUntil(all, [&] {
            ada.sendToolState(burrState(site, i % 40, 40, steadyNowUs()));
            ++i;
            return stranger.closed();
        }));
        EXPECT_EQ(stranger.closeReason(), c.reason);
        EXPECT_EQ(stranger.closeReason().find('\n'), std::string::npos);
        EXPECT_EQ(stranger.closeCode() & 0xff, uint32_t(RefuseReason::WrongCode));
        // Nothing of the session: no image or volume byte, no roster, marks, tools or forces.
        EXPECT_EQ(stranger.stats().totalBytesIn(Channel::Image), 0u);
        EXPECT_EQ(stranger.stats().totalBytesIn(Channel::Volume), 0u);
        EXPECT_EQ(sessionBytes(stranger), 0u);
        EXPECT_FALSE(stranger.welcomed());
        EXPECT_EQ(stranger.scene(), nullptr);
        EXPECT_EQ(stranger.rostersReceived(), 0u);
        EXPECT_EQ(stranger.annotationListsReceived(), 0u);
        EXPECT_EQ(stranger.relaysReceived() + stranger.hapticModelsReceived(), 0u);
        EXPECT_EQ(stranger.updatesApplied(), 0u);
        std::printf("[ refused ] %s: \"%s\"; image and volume bytes received: %llu\n", c.what,
                    stranger.closeReason().c_str(),
                    (unsigned long long)(stranger.stats().totalBytesIn(Channel::Image) +
                                         stranger.stats().totalBytesIn(Channel::Volume)));
    }
    // The members never saw the strangers.
    for (SessionClient* m : members)
        EXPECT_EQ(m->participants().size(), 2u);
    EXPECT_EQ(server.security().codesRefused, 3u);
    server.stop();
}

TEST(SessionSecurity, AClientWithACodeWillNotJoinAnOpenSession) {
    Volume sphere = makeSphere(32);
    SessionServer server(sphere, loopbackServerConfig("sphere:32"));
    Pumped pumped(server);
    SessionClient c(member(sphere, "Ada", Role::Trainee, kTraineeCode));
    c.connect(loopback(server.port()));
    ASSERT_TRUE(pumpUntil({&c}, [&] { return c.closed(); }));
    EXPECT_EQ(c.closeReason(), "the server runs an open session (no codes, nothing encrypted): "
                               "not joining it with --code");
    EXPECT_FALSE(c.welcomed());
    server.stop();
}

// [SECTION] an attacker on the path

TEST(SessionSecurity, ReplayedTamperedAndForeignDatagramsAreDroppedAndCountedAndTheSessionGoesOn) {
    Volume sphere = makeSphere(32);
    SessionServer server(sphere, codedServerConfig());
    Pumped pumped(server);
    Relay relay(server.port());
    SessionClient ada(member(sphere, "Ada", Role::Trainee, kTraineeCode));
    ada.connect(loopback(relay.port()));
    ASSERT_TRUE(pumpUntil({&ada}, [&] { return ada.hasFullImage(); })) << ada.closeReason();
    const SurfaceSite site = sphereTop(32);
    // A tool state the relay captures (a still tool above the bone: it changes nothing).
    ToolState still = burrState(site, 0, 40, steadyNowUs());
    still.drilling = false;
    int sent = 0;
    auto sendStill = [&] {
        still.clientTimeUs = steadyNowUs();
        ada.sendToolState(still);
        ++sent;
    };
    ASSERT_TRUE(pumpUntil({&ada}, [&] {
        sendStill();
        return relay.captured();
    }));

    auto securityIs = [&](auto pred) {
        return pumpUntil(
            {&ada}, [&] { return pred(server.security()); }, 20.0);
    };
    int flips = 0;
    // Replayed from the client's own address.
    relay.replay(false);
    EXPECT_TRUE(securityIs([](const SecurityCounters& s) { return s.replayed >= 1; }));
    // One bit flipped in a tool state. A flipped datagram can fall in an ENet group the replay
    // above took (ENet then drops it as a duplicate, unseen): flip the next one until one counts.
    EXPECT_TRUE(pumpUntil({&ada}, [&] {
        if (server.security().forged >= 1)
            return true;
        if (relay.flipped() == uint64_t(flips)) {
            relay.flipNextToolState();
            ++flips;
            sendStill();
        }
        return false;
    }));
    // From a second address, naming the client's peer.
    relay.replay(true);
    EXPECT_TRUE(securityIs([](const SecurityCounters& s) { return s.spoofed >= 1; }));
    const SecurityCounters s = server.security();
    std::printf("[ dropped ] replayed %llu, forged %llu, foreign %llu\n",
                (unsigned long long)s.replayed, (unsigned long long)s.forged,
                (unsigned long long)s.spoofed);

    // The session goes on: the client is still in, drills, and feels forces.
    const uint64_t models = ada.hapticModelsReceived(), updates = ada.updatesApplied();
    int i = 0;
    ASSERT_TRUE(pumpUntil({&ada}, [&] {
        if (i < 40)
            ada.sendToolState(burrState(site, i++, 40, steadyNowUs()));
        return ada.updatesApplied() > updates && ada.hapticModelsReceived() > models;
    }));
    EXPECT_FALSE(ada.closed());
    EXPECT_EQ(server.clientCount(), 1u);
    EXPECT_EQ(server.disconnectedForMalformed(), 0u);
    server.stop();
}

// [SECTION] the instructor's powers

// A session with codes on the 32^3 sphere, trainee Ada and instructor Dr. Cho connecting.
struct AdaAndCho {
    Volume sphere = makeSphere(32);
    SessionServer server{sphere, codedServerConfig()};
    Pumped pumped{server};
    SessionClient ada{member(sphere, "Ada", Role::Trainee, kTraineeCode)};
    SessionClient cho{member(sphere, "Dr. Cho", Role::Instructor, kInstructorCode)};
    std::vector<SessionClient*> both{&ada, &cho};
    AdaAndCho() {
        for (SessionClient* c : both)
            c->connect(loopback(server.port()));
    }
    // Trainee `name` connecting with `code`, pumped (with Dr. Cho) until it is refused or has its
    // picture.
    std::unique_ptr<SessionClient> trainee(const std::string& name, const std::string& code) {
        auto c = std::make_unique<SessionClient>(member(sphere, name, Role::Trainee, code));
        c->connect(loopback(server.port()));
        pumpUntil({&cho, c.get()}, [&] { return c->closed() || c->hasFullImage(); });
        return c;
    }
};

TEST(SessionSecurity, AnInstructorRemovesAParticipantWhoCannotRejoinUntilAllowed) {
    AdaAndCho session;
    SessionServer& server = session.server;
    SessionClient &ada = session.ada, &cho = session.cho;
    std::vector<SessionClient*>& both = session.both;
    ASSERT_TRUE(pumpUntil(
        both, [&] { return ada.welcomed() && cho.welcomed() && cho.participants().size() == 2; }));
    // A trainee may not remove anyone.
    ada.remove(Remove{Remove::Op::Remove, cho.welcome().clientId});
    ASSERT_TRUE(pumpUntil(both, [&] { return server.security().removalsRefused == 1; }));
    EXPECT_FALSE(cho.closed());

    cho.remove(Remove{Remove::Op::Remove, ada.welcome().clientId});
    ASSERT_TRUE(pumpUntil(both, [&] { return ada.closed() && cho.participants().size() == 1; }));
    EXPECT_EQ(ada.closeReason(), "the instructor removed you from the session");

    const auto again = session.trainee("Ada", kTraineeCode);
    ASSERT_TRUE(again->closed());
    EXPECT_EQ(again->closeReason(), "the instructor removed you from the session");
    EXPECT_EQ(sessionBytes(*again), 0u);

    cho.remove(Remove{Remove::Op::AllowRejoin, 0});
    // The server applies the instructor's messages in order: once the mark sent after the allow
    // comes back, the allow has been applied.
    cho.annotate(Annotate{Annotate::Op::Add, 0, glm::vec3(0.0f), "after"});
    ASSERT_TRUE(pumpUntil({&cho}, [&] { return cho.annotations().size() == 1; }));
    const auto back = session.trainee("Ada", kTraineeCode);
    ASSERT_TRUE(back->hasFullImage()) << back->closeReason();
    EXPECT_EQ(server.security().removed, 1u);
    EXPECT_EQ(server.security().removedRefused, 1u);
    server.stop();
}

// A new trainee code while the server runs (docs/security.md, "New codes"): the instructor is
// sent the codes and asks for a new one; the removed trainee rejoins with it, the old code is
// refused as wrong, and the trainee is never sent the codes.
TEST(SessionSecurity, AnInstructorIssuesANewTraineeCodeThatLetsTheRemovedBack) {
    AdaAndCho session;
    SessionServer& server = session.server;
    SessionClient &ada = session.ada, &cho = session.cho;
    std::vector<SessionClient*>& both = session.both;
    ASSERT_TRUE(pumpUntil(
        both, [&] { return ada.welcomed() && cho.codes() && cho.participants().size() == 2; }));
    EXPECT_EQ(cho.codes()->trainee, kTraineeCode);
    EXPECT_EQ(cho.codes()->instructor, kInstructorCode);
    ada.newCode(Role::Trainee); // a trainee's is refused
    ASSERT_TRUE(pumpUntil(both, [&] { return server.security().newCodesRefused == 1; }));
    cho.remove(Remove{Remove::Op::Remove, ada.welcome().clientId});
    ASSERT_TRUE(pumpUntil(both, [&] { return ada.closed(); }));
    EXPECT_FALSE(ada.codes().has_value());

    cho.newCode(Role::Trainee);
    ASSERT_TRUE(pumpUntil({&cho}, [&] { return cho.codes()->trainee != kTraineeCode; }));
    const std::string fresh = cho.codes()->trainee;
    EXPECT_EQ(cho.codes()->instructor, kInstructorCode);
    const auto old = session.trainee("Eve", kTraineeCode);
    ASSERT_TRUE(old->closed());
    EXPECT_EQ(old->closeReason(), "wrong session code");
    EXPECT_EQ(sessionBytes(*old), 0u);
    const auto back = session.trainee("Ada", fresh);
    ASSERT_TRUE(back->hasFullImage()) << back->closeReason();
    EXPECT_FALSE(back->codes().has_value());
    EXPECT_FALSE(cho.closed());
    EXPECT_EQ(server.security().codesIssued, 1u);
    server.stop();
}

// Random datagrams at the server's port while a client runs its handshake (some naming its
// peer, most nothing): the handshake completes, and the server neither crashes nor lets any in.
TEST(SessionSecurity, RandomDatagramsDuringAHandshakeDoNotStopIt) {
    Volume sphere = makeSphere(32);
    SessionServer server(sphere, codedServerConfig());
    Pumped pumped(server);
    EnetLibrary lib;
    ENetSocket noise = enet_socket_create(ENET_SOCKET_TYPE_DATAGRAM);
    const ENetAddress target = loopback(server.port());
    std::mt19937 rng(26);
    auto blast = [&](int n) {
        for (int i = 0; i < n; ++i) {
            std::vector<uint8_t> d(1 + rng() % 120);
            for (uint8_t& b : d)
                b = uint8_t(rng());
            if (i % 4 == 0 && d.size() >= 2) { // a header naming peer 0..3
                d[0] = 0;
                d[1] = uint8_t(rng() % 4);
            }
            ENetBuffer b{d.data(), d.size()};
            enet_socket_send(noise, &target, &b, 1);
        }
    };
    SessionClient ada(member(sphere, "Ada", Role::Trainee, kTraineeCode));
    ada.connect(loopback(server.port()));
    ASSERT_TRUE(pumpUntil({&ada}, [&] {
        blast(20);
        return ada.hasFullImage() || ada.closed();
    })) << ada.closeReason();
    EXPECT_TRUE(ada.sealed());
    EXPECT_FALSE(ada.closed()) << ada.closeReason();
    EXPECT_EQ(server.clientCount(), 1u);
    EXPECT_EQ(server.security().handshakes, 1u);
    enet_socket_destroy(noise);
    server.stop();
}

// What an eavesdropper sees of a sealed session: neither the code nor the hello's name nor any
// message in the clear; in an open session the same name is there to read.
TEST(SessionSecurity, NothingOfTheCodeOrTheMessagesTravelsInTheClear) {
    Volume sphere = makeSphere(32);
    const std::string name = "Ada Lovelace of Ockham";
    auto wireOf = [&](const ServerConfig& sc, const std::string& code) {
        SessionServer server(sphere, sc);
        Pumped pumped(server);
        SessionClient ada(member(sphere, name, Role::Trainee, code));
        std::vector<std::vector<uint8_t>> wire;
        ada.setSendTapForTest([&](Channel, std::span<const uint8_t> bytes) {
            wire.emplace_back(bytes.begin(), bytes.end());
        });
        ada.connect(loopback(server.port()));
        EXPECT_TRUE(pumpUntil({&ada}, [&] { return ada.hasFullImage(); })) << ada.closeReason();
        server.stop();
        return wire;
    };
    auto contains = [](const std::vector<std::vector<uint8_t>>& wire, const std::string& text) {
        return std::any_of(wire.begin(), wire.end(), [&](const std::vector<uint8_t>& m) {
            return std::search(m.begin(), m.end(), text.begin(), text.end()) != m.end();
        });
    };
    const auto sealed = wireOf(codedServerConfig(), kTraineeCode);
    ASSERT_FALSE(sealed.empty());
    EXPECT_EQ(sealed[0][0], uint8_t(MessageType::Handshake)); // the offer, then the confirm
    EXPECT_EQ(sealed[1][0], uint8_t(MessageType::Handshake));
    EXPECT_FALSE(contains(sealed, name));
    EXPECT_FALSE(contains(sealed, kTraineeCode));
    EXPECT_FALSE(contains(sealed, "QX7M4KTD"));
    const auto open = wireOf(loopbackServerConfig("sphere:32"), "");
    EXPECT_TRUE(contains(open, name));
}

// A client whose server sends what it cannot use ends the session at once, naming the server and
// the message: a malformed welcome, scene or first full image (SessionClient::fault, the
// ClientThread's snapshot, the headless trainee's one line); a bad rectangle once a picture is
// shown is only dropped. A client the server drops for forged traffic is told so without blame.
// Fake servers over loopback in this process; deadlines only guard against hangs.
#include "net/client_thread.h"
#include "net/scene.h"
#include "net/session_client.h"
#include "net/session_server.h"
#include "net/view.h"

#include "libsim/skull.h"

#include "loopback.h"
#include "test_support.h"

#include <gtest/gtest.h>

#include <atomic>
#include <functional>
#include <memory>
#include <random>
#include <string>
#include <thread>
#include <vector>

using namespace trephine;
using namespace trephine::net;
using trephine::testing::FakeServer;
using trephine::testing::loopback;
using trephine::testing::loopbackServerConfig;
using trephine::testing::Pumped;
using trephine::testing::pumpUntil;
using trephine::testing::waitFor;

namespace {

const Volume& sphere() {
    static const Volume v = makeSphere(16);
    return v;
}

std::vector<uint8_t> welcomeBytes() {
    Welcome w;
    w.clientId = 1;
    w.volumeDims = sphere().dims();
    w.spacing = sphere().spacing();
    w.volumeName = "sphere:16";
    return encodeMessage(w);
}

std::vector<uint8_t> sceneBytes(const Volume& v) {
    Scene scene = buildScene(v);
    return encodeMessage(scene);
}

std::vector<uint8_t> withTrailingByte(std::vector<uint8_t> bytes) {
    bytes.push_back(0);
    return bytes;
}

// An image of `view` (request `viewId`) at (x, y), w x h, whose pixels do not decode when
// `corrupt` (the payload cut in half).
std::vector<uint8_t> imageBytes(const ViewSpec& view, uint32_t viewId, bool full, uint16_t x,
                                uint16_t y, uint16_t w, uint16_t h, bool corrupt) {
    ImageUpdate u;
    u.viewId = viewId;
    u.full = full;
    u.x = x;
    u.y = y;
    u.width = w;
    u.height = h;
    u.codec = Codec::Raw;
    EncodedImage e = encodeImage(Dbi(w, h), Codec::Raw, toCamera(view));
    u.rawBytes = e.rawBytes;
    u.payload = std::move(e.payload);
    if (corrupt)
        u.payload.resize(u.payload.size() / 2);
    return encodeMessage(u);
}

ClientConfig tinyClient() {
    ClientConfig c;
    c.codec = Codec::Raw;
    c.view = toViewSpec(cameraPreset("top", sphere(), {16, 16}));
    return c;
}

// A SessionClient joined to a FakeServer (connected, nothing received yet).
struct FakeSession {
    FakeServer fake;
    SessionClient client{tinyClient()};
    std::string host;
    FakeSession() {
        client.connect(loopback(fake.port()));
        host = "127.0.0.1:" + std::to_string(fake.port());
    }
    bool pump(const std::function<bool()>& pred) { return fake.pumpWith(client, pred, 10.0); }
};

// A fake server on a thread of its own (for a ClientThread or a trainee process): it hands every
// message it receives to `answer`, which sends what the test wants back.
struct ScriptedServer {
    using Answer = std::function<void(ScriptedServer&, std::span<const uint8_t>)>;
    Host host = Host::listen(0, 2);
    ENetPeer* peer = nullptr;
    Answer answer;
    std::atomic<bool> stop{false};
    std::thread thread;

    explicit ScriptedServer(Answer a) : answer(std::move(a)) {
        thread = std::thread([this] {
            while (!stop)
                host.service(2, [this](const ENetEvent& e) {
                    if (e.type == ENET_EVENT_TYPE_CONNECT)
                        peer = e.peer;
                    else if (e.type == ENET_EVENT_TYPE_RECEIVE)
                        answer(*this, {e.packet->data, e.packet->dataLength});
                });
        });
    }
    ~ScriptedServer() {
        stop = true;
        thread.join();
    }
    std::string address() const { return "127.0.0.1:" + std::to_string(host.port()); }
    void send(Channel channel, const std::vector<uint8_t>& bytes) {
        host.send(peer, channel, bytes);
    }
};

bool isHello(std::span<const uint8_t> m) {
    return peekMessageType(m) == uint8_t(MessageType::Hello);
}

} // namespace

// A welcome that does not decode (too short, or longer than its fields): the client closes at
// once, naming the welcome (it waited for its connect timeout, then said "no answer").
TEST(SessionClientFaults, AMalformedWelcomeEndsTheSessionAtOnceNamingIt) {
    const std::vector<uint8_t> good = welcomeBytes();
    for (const std::vector<uint8_t>& bad :
         {withTrailingByte(good), std::vector<uint8_t>(good.begin(), good.end() - 3)}) {
        FakeSession s;
        ASSERT_TRUE(s.pump([&] { return s.fake.peer && s.client.connected(); }));
        s.fake.send(Channel::Control, bad);
        ASSERT_TRUE(s.pump([&] { return s.client.closed(); })) << bad.size() << " bytes";
        EXPECT_EQ(s.client.closeReason(), s.host + " sent a malformed welcome (" +
                                              std::to_string(bad.size()) +
                                              " bytes that do not decode)");
        ASSERT_TRUE(s.client.fault().has_value());
        EXPECT_EQ(s.client.fault()->type, MessageType::Welcome);
        EXPECT_FALSE(s.client.welcomed());
        EXPECT_EQ(s.client.stats().malformed(), 1u);
    }
}

// A welcome whose type byte was damaged is no welcome the client can tell: it waits out its
// connect timeout, then says what it could not read rather than ask whether a server runs.
TEST(SessionClientFaults, AWelcomeWithADamagedTypeIsNamedWhenTheWaitEnds) {
    ScriptedServer server([](ScriptedServer& s, std::span<const uint8_t> m) {
        if (!isHello(m))
            return;
        std::vector<uint8_t> damaged = welcomeBytes();
        damaged[0] = 0xee; // no type
        s.send(Channel::Control, damaged);
    });
    ClientThreadConfig cc;
    cc.address = server.address();
    cc.client = tinyClient();
    cc.connectTimeoutS = 0.5;
    cc.retryS = 60.0;
    ClientThread client(cc);
    client.start();
    ASSERT_TRUE(waitFor([&] { return client.snapshot()->state == LinkState::Retrying; }, 10.0));
    EXPECT_EQ(client.snapshot()->closeReason,
              "no answer from " + cc.address +
                  " that this client could read: 1 malformed or forged messages (a faulty network, "
                  "an on-path attacker, or no Trephine server at that address)");
    EXPECT_FALSE(client.snapshot()->fault.has_value());
    client.stop();
}

// A scene of another volume than the welcome's, or one that does not decode: the client has no
// presets, sites or field without it, so it closes at once naming the scene (it said "sent no
// scene after its welcome" when the trainee's wait ran out).
TEST(SessionClientFaults, AMalformedSceneEndsTheSessionAtOnceNamingIt) {
    const std::vector<uint8_t> trailing = withTrailingByte(sceneBytes(sphere()));
    for (const auto& [bad, detail] :
         {std::pair{sceneBytes(makeSphere(20)),
                    std::string("its volume's dims or spacing differ from the welcome's")},
          std::pair{trailing, std::to_string(trailing.size()) + " bytes that do not decode"}}) {
        FakeSession s;
        ASSERT_TRUE(s.pump([&] { return s.fake.peer && s.client.connected(); }));
        s.fake.send(Channel::Control, welcomeBytes());
        s.fake.send(Channel::Control, bad);
        ASSERT_TRUE(s.pump([&] { return s.client.closed(); })) << "still waiting: " << detail;
        EXPECT_TRUE(s.client.welcomed());
        EXPECT_EQ(s.client.closeReason(), s.host + " sent a malformed scene (" + detail + ")");
        ASSERT_TRUE(s.client.fault().has_value());
        EXPECT_EQ(s.client.fault()->type, MessageType::Scene);
        EXPECT_EQ(s.client.scene(), nullptr);
    }
}

// The first full image whose pixels do not decode ends the session at once, naming the image (the
// headless trainee waited 30 s and said "no image from HOST: " with no reason). Once a picture is
// shown, a bad rectangle is dropped and counted, and the session goes on.
TEST(SessionClientFaults, AMalformedFirstImageEndsTheSessionButALaterBadRectangleDoesNot) {
    const ViewSpec view = tinyClient().view;
    {
        FakeSession s;
        ASSERT_TRUE(s.pump([&] { return s.fake.peer && s.client.connected(); }));
        s.fake.send(Channel::Control, welcomeBytes());
        s.fake.send(Channel::Image, imageBytes(view, 0, true, 0, 0, 16, 16, true));
        ASSERT_TRUE(s.pump([&] { return s.client.closed(); }));
        EXPECT_EQ(s.client.closeReason(),
                  s.host + " sent a malformed image (its pixels do not decode)");
        ASSERT_TRUE(s.client.fault().has_value());
        EXPECT_EQ(s.client.fault()->type, MessageType::ImageUpdate);
        EXPECT_EQ(s.client.malformedImages(), 1u);
    }
    FakeSession s;
    ASSERT_TRUE(s.pump([&] { return s.fake.peer && s.client.connected(); }));
    s.fake.send(Channel::Control, welcomeBytes());
    s.fake.send(Channel::Image, imageBytes(view, 0, true, 0, 0, 16, 16, false));
    s.fake.send(Channel::Image, imageBytes(view, 0, false, 4, 4, 8, 8, true));
    s.fake.send(Channel::Image, withTrailingByte(imageBytes(view, 0, false, 4, 4, 8, 8, false)));
    s.fake.send(Channel::Image, imageBytes(view, 0, false, 2, 2, 8, 8, false));
    ASSERT_TRUE(s.pump([&] { return s.client.updatesApplied() == 2 || s.client.closed(); }));
    ASSERT_TRUE(s.pump([&] { return s.client.malformedImages() == 2 || s.client.closed(); }));
    EXPECT_FALSE(s.client.closed()) << s.client.closeReason();
    EXPECT_FALSE(s.client.fault().has_value());
    EXPECT_TRUE(s.client.hasFullImage());
}

// The ClientThread's snapshot carries the fault and its text, naming the address as it was given,
// and the thread retries as after any other failure.
TEST(SessionClientFaults, TheClientThreadsSnapshotNamesTheMalformedScene) {
    ScriptedServer server([](ScriptedServer& s, std::span<const uint8_t> m) {
        if (!isHello(m))
            return;
        s.send(Channel::Control, welcomeBytes());
        s.send(Channel::Control, sceneBytes(makeSphere(20)));
    });
    ClientThreadConfig cc;
    cc.address = server.address();
    cc.client = tinyClient();
    cc.retryS = 60.0; // one connection is enough
    ClientThread client(cc);
    client.start();
    ASSERT_TRUE(waitFor([&] { return client.snapshot()->state == LinkState::Retrying; }, 10.0));
    const auto snap = client.snapshot();
    EXPECT_EQ(
        snap->closeReason,
        cc.address +
            " sent a malformed scene (its volume's dims or spacing differ from the welcome's)");
    ASSERT_TRUE(snap->fault.has_value());
    EXPECT_EQ(snap->fault->type, MessageType::Scene);
    client.stop();
}

// `trephine trainee --headless` against a server whose full image of the view it asked for does
// not decode: one line naming the server and the image, as soon as it came.
TEST(SessionClientFaults, TheHeadlessTraineeNamesAMalformedImage) {
    ScriptedServer server([](ScriptedServer& s, std::span<const uint8_t> m) {
        ViewRequest r;
        if (isHello(m)) {
            s.send(Channel::Control, welcomeBytes());
            s.send(Channel::Control, sceneBytes(sphere()));
        } else if (decodeMessage(m, r)) {
            s.send(Channel::Image,
                   imageBytes(r.view, r.requestId, true, 0, 0, r.view.width, r.view.height, true));
        }
    });
    trephine::testing::TempDir dir;
    const auto r =
        trephine::testing::runTrephine(dir, "trainee --headless --connect " + server.address() +
                                                " --camera top --size 32 --duration 1");
    EXPECT_NE(r.exitCode, 0);
    EXPECT_EQ(r.err, "trephine: trainee: " + server.address() +
                         " sent a malformed image (its pixels do not decode)\n");
}

// A server that received malformed or forged datagrams on a connection (here datagrams that fail
// their seal, as an on-path attacker's or a faulty network's would) closes it; the client is told
// so, without being accused of sending them ("dropped us for sending malformed messages").
TEST(SessionClientFaults, AClientDroppedForForgedTrafficIsToldItWasTheNetworkOrAnAttacker) {
    const std::string text = refuseReasonText(uint32_t(RefuseReason::Malformed));
    EXPECT_EQ(text.find("us for sending"), std::string::npos) << text;
    EXPECT_NE(text.find("malformed or forged"), std::string::npos) << text;
    EXPECT_NE(text.find("network"), std::string::npos) << text;
    EXPECT_NE(text.find("attacker"), std::string::npos) << text;

    Volume ball = makeSphere(32);
    ServerConfig sc = loopbackServerConfig("sphere:32");
    sc.traineeCode = "QX7M-4KTD";
    sc.instructorCode = "HW2R-9PZE";
    SessionServer server(ball, sc);
    Pumped pumped(server);
    ClientConfig cc = trephine::testing::namedClientConfig(ball, "Ada", Role::Trainee, 32);
    cc.code = sc.traineeCode;
    SessionClient ada(cc);
    ada.connect(loopback(server.port()));
    ASSERT_TRUE(pumpUntil({&ada}, [&] { return ada.hasFullImage() || ada.closed(); }));
    ASSERT_TRUE(ada.sealed());
    std::mt19937 rng(35);
    ASSERT_TRUE(pumpUntil({&ada}, [&] {
        std::vector<uint8_t> forged(40);
        for (uint8_t& b : forged)
            b = uint8_t(rng());
        ada.sendRaw(Channel::ToolState, forged);
        return ada.closed();
    })) << "never dropped";
    EXPECT_EQ(ada.closeCode(), uint32_t(RefuseReason::Malformed));
    EXPECT_EQ(ada.closeReason(), text);
    EXPECT_FALSE(ada.fault().has_value()) << "the server closed it, not the client";
    server.stop();
}

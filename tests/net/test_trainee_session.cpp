// The trainee session against a loopback server: the steps from join to the drain in order, and
// the one line each step's failure says. The session blocks its caller, so its steps run on a
// thread of the test while the test's own thread pumps the server.
#include "net/trainee_session.h"

#include "libsim/error.h"
#include "libsim/skull.h"
#include "net/scripts.h"

#include "loopback.h"

#include <gtest/gtest.h>

#include <atomic>
#include <exception>
#include <functional>
#include <string>
#include <thread>

using namespace trephine;
using namespace trephine::net;
using trephine::testing::Pumped;
using trephine::testing::pumpWhile;

namespace {

// Plays the rows' poses, each from its time to the next (test_net links no devices library).
class RowsDevice : public Device {
public:
    explicit RowsDevice(std::vector<ScriptSample> rows) : m_rows(std::move(rows)) {}
    std::string name() const override { return "rows"; }
    DeviceState read(double now) override {
        const ScriptSample* row = &m_rows.front();
        for (const ScriptSample& r : m_rows)
            if (r.t <= now)
                row = &r;
        return {{row->tool.position, row->tool.orientation}, 0u, true};
    }
    void setForce(glm::vec3) override {}

private:
    std::vector<ScriptSample> m_rows;
};

void play(TraineeSession& session, std::vector<ScriptSample> script, double endS) {
    auto device = std::make_unique<RowsDevice>(script);
    session.play(std::move(script), endS, std::move(device));
}

TraineeSessionConfig configFor(uint16_t port, int size = 32) {
    TraineeSessionConfig c;
    c.address = "127.0.0.1:" + std::to_string(port);
    c.client.view.width = c.client.view.height = 1; // the placeholder until the preset
    c.size = size;
    return c;
}

// The message of the Error `f` throws ("" when it throws none).
template <typename F>
std::string failure(F f) {
    try {
        f();
    } catch (const Error& e) {
        return e.what();
    }
    return {};
}

class TraineeSessionTest : public ::testing::Test {
protected:
    void TearDown() override { server.stop(); }

    Volume sphere = makeSphere(32);
    SessionServer server{sphere, trephine::testing::loopbackServerConfig("sphere:32")};
    Pumped pumped{server};
};

} // namespace

// join -> scene -> preset -> view -> the burr hole -> lift -> drain: the picture is the preset's
// view, the hole is drilled (incremental updates came), and the drain waited for the server's
// answer to the lift.
TEST_F(TraineeSessionTest, RunsAScriptFromJoinToTheDrain) {
    TraineeSession session(configFor(server.port()));
    Camera camera;
    uint64_t liftSentAfter = 0;
    SessionEnd end;
    pumpWhile([&] {
        const Welcome welcome = session.join();
        EXPECT_GT(welcome.clientId, 0u);
        const ReceivedScene& scene = session.awaitScene();
        EXPECT_NE(findSite(scene.scene, kDefaultSiteName), nullptr);
        camera = session.openPreset("working");
        EXPECT_EQ(camera.width, 32);
        EXPECT_TRUE(session.view().hasPicture());

        std::vector<ScriptSample> script = session.burrhole(1.0); // the plunge
        ASSERT_FALSE(script.empty());
        liftSentAfter = steadyNowUs() + 1'000'000;
        play(session, std::move(script), 1.0);
        session.drill();
        session.liftAndDrain();
        end = session.finish();
    });
    ASSERT_FALSE(HasFatalFailure());
    EXPECT_EQ(end.how, SessionEnd::How::ScriptDone);
    EXPECT_EQ(session.endText(end), "");
    EXPECT_GE(end.elapsedS, 1.0);
    const ClientSnapshot& s = session.snap();
    EXPECT_GT(s.updatesApplied, s.fullUpdates); // the plunge cut bone
    ASSERT_TRUE(s.hapticModel.has_value());
    // The last force model answers the lift, sent after the script's second.
    EXPECT_GE(s.hapticModel->clientTimeUs, liftSentAfter);
    EXPECT_EQ(s.view, toViewSpec(camera));
    EXPECT_EQ(session.view().dbi().width(), 32);
}

// The caller's stop ends the script early; the session says how far it got.
TEST_F(TraineeSessionTest, TheCallersStopEndsItEarly) {
    TraineeSession session(configFor(server.port()));
    SessionEnd end;
    pumpWhile([&] {
        session.join();
        session.awaitScene();
        session.openPreset("top");
        play(session, session.burrhole(kBurrholeSeconds), kBurrholeSeconds);
        session.drill([](double t) { return t < 0.2; });
        session.liftAndDrain(0.1);
        end = session.finish();
    });
    EXPECT_EQ(end.how, SessionEnd::How::Stopped);
    EXPECT_LT(end.elapsedS, kBurrholeSeconds);
    EXPECT_EQ(session.endText(end).rfind("trainee: stopped by a signal ", 0), 0u)
        << session.endText(end);
}

// The server going away mid-script ends the session as closed (its goodbye) or lost (silence).
TEST_F(TraineeSessionTest, AServerThatGoesEndsTheSession) {
    TraineeSession session(configFor(server.port()));
    std::atomic<bool> goAway = false; // the pumping thread stops the server it pumps
    SessionEnd end;
    pumpWhile(
        [&] {
            session.join();
            session.awaitScene();
            session.openPreset("top");
            play(session, session.burrhole(kBurrholeSeconds), kBurrholeSeconds);
            session.drill([&](double t) {
                if (t > 0.2)
                    goAway = true;
                return true;
            });
            session.liftAndDrain();
            end = session.finish();
        },
        [&] {
            if (goAway)
                server.stop();
        });
    EXPECT_TRUE(end.how == SessionEnd::How::Closed || end.how == SessionEnd::How::Lost)
        << session.endText(end);
    EXPECT_FALSE(session.endText(end).empty());
    EXPECT_EQ(session.endText(end).find('\n'), std::string::npos);
}

TEST_F(TraineeSessionTest, APresetTheSceneLacksIsOneLine) {
    TraineeSession session(configFor(server.port()));
    std::string what;
    pumpWhile([&] {
        session.join();
        session.awaitScene();
        what = failure([&] { session.openPreset("nowhere"); });
    });
    EXPECT_EQ(what, "trainee: the server's scene has no camera preset 'nowhere'");
}

TEST(TraineeSession, AViewLargerThanTheServerServesIsRefusedBeforeItIsAsked) {
    Volume sphere = makeSphere(32);
    ServerConfig sc = trephine::testing::loopbackServerConfig("sphere:32");
    sc.maxViewPixels = 32 * 32;
    SessionServer server(sphere, sc);
    Pumped pumped(server);
    TraineeSession session(configFor(server.port(), 64));
    std::string what;
    pumpWhile([&] {
        session.join();
        session.awaitScene();
        what = failure([&] { session.openPreset("top"); });
    });
    EXPECT_EQ(what,
              "trainee: The server serves views of at most 1024 pixels; this view is 64 x 64: "
              "restart with --size 32 or less");
    server.stop();
}

TEST(TraineeSession, NoServerIsNoAnswerNamingTheAddress) {
    TraineeSessionConfig c = configFor(1); // nothing listens on port 1
    c.connectTimeoutS = 0.5;
    TraineeSession session(c);
    const std::string what = failure([&] { session.join(2.0); });
    EXPECT_EQ(what.rfind("trainee: no answer", 0), 0u) << what;
    EXPECT_NE(what.find("127.0.0.1:1"), std::string::npos) << what;
}

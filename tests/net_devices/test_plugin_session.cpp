// Device plugins in a headless trainee session against a pumped loopback server: the simulated
// force device, loaded through the C ABI, drills the burr hole and feels the bone; a plugin that
// hangs is cut off at zero force and the session goes on.
#include "libsim_devices/plugin_device.h"
#include "net/scripts.h"
#include "net/trainee_session.h"

#include "libsim/skull.h"

#include "loopback.h"

#include <glm/geometric.hpp>
#include <gtest/gtest.h>

#include <atomic>
#include <cmath>
#include <exception>
#include <functional>
#include <map>
#include <string>
#include <thread>

using namespace trephine;
using namespace trephine::net;
using trephine::testing::Pumped;

namespace {

const std::string kPlugins = TREPHINE_PLUGIN_DIR;

using trephine::testing::pumpWhile;

class PluginSessionTest : public ::testing::Test {
protected:
    void TearDown() override { server.stop(); }

    TraineeSessionConfig config() const {
        TraineeSessionConfig c;
        c.address = "127.0.0.1:" + std::to_string(server.port());
        c.client.view.width = c.client.view.height = 1;
        c.size = 32;
        return c;
    }
    // Opens `spec` with the lines it reports collected; the session owns the device.
    PluginDevice* open(const std::string& spec, std::unique_ptr<Device>& owner) {
        PluginOptions o;
        o.report = [this](const std::string& line) {
            std::lock_guard lock(m_linesMutex);
            m_lines.push_back(line);
        };
        std::string error;
        auto d = openPlugin(spec, o, error);
        EXPECT_TRUE(d) << error;
        PluginDevice* raw = d.get();
        owner = std::move(d);
        return raw;
    }
    std::vector<std::string> lines() {
        std::lock_guard lock(m_linesMutex);
        return m_lines;
    }

    Volume sphere = makeSphere(32);
    SessionServer server{sphere, trephine::testing::loopbackServerConfig("sphere:32")};
    Pumped pumped{server};

private:
    std::mutex m_linesMutex;
    std::vector<std::string> m_lines;
};

} // namespace

// The hand follows the burr-hole script as its intent, the server cuts the bone, and the force the
// device applies (its own measure, a tick after the loop wrote it) is the server's force model at
// the device's position, within 5 % over the ticks in contact, pointing the way f(P_N) pushes.
TEST_F(PluginSessionTest, TheSimulatedDeviceDrillsABurrHoleAndFeelsTheBone) {
    TraineeSession session(config());
    std::unique_ptr<Device> owner;
    PluginDevice* device = open(kPlugins + "/trephine_sim_device.so", owner);
    ASSERT_TRUE(device);
    SessionEnd end;
    glm::vec3 normal(0.0f);
    pumpWhile([&] {
        session.join();
        const ReceivedScene& scene = session.awaitScene();
        normal = findSite(scene.scene, kDefaultSiteName)->normal;
        session.openPreset("top");
        session.play(session.burrhole(2.0), 2.0, std::move(owner));
        session.drill();
        session.liftAndDrain(0.1);
        end = session.finish();
    });
    ASSERT_FALSE(HasFatalFailure());
    EXPECT_EQ(end.how, SessionEnd::How::ScriptDone) << session.endText(end);
    EXPECT_EQ(device->fault(), "");
    EXPECT_TRUE(lines().empty());
    const ClientSnapshot& s = session.snap();
    EXPECT_GT(s.updatesApplied, s.fullUpdates); // the hand's tool cut bone

    // The applied force at tick k+1 against what the loop wrote at tick k (the server's model at
    // the device's position) and against the newest model's own force f(P_N).
    std::map<double, glm::vec3> applied;
    for (const PluginSample& p : device->history())
        applied[p.time] = p.applied;
    const std::vector<HapticSample> samples = session.core().hapticSamples();
    double fieldSum = 0, fieldErr = 0, modelSum = 0, appliedSum = 0, modelErr = 0, along = 0;
    int contact = 0;
    for (size_t i = 0; i + 1 < samples.size(); ++i) {
        const glm::vec3 model = samples[i].modelForce;
        auto next = applied.find(samples[i + 1].time);
        if (glm::length(model) < 0.5f || next == applied.end())
            continue;
        const glm::vec3 a = next->second;
        contact++;
        fieldSum += glm::length(samples[i].force);
        fieldErr += glm::length(a - samples[i].force);
        modelSum += glm::length(model);
        appliedSum += glm::length(a);
        modelErr += glm::length(a - model);
        along += glm::dot(a, glm::normalize(model)) / std::max(1e-6f, glm::length(a));
    }
    ASSERT_GT(contact, 100) << "the hand never pressed on the bone";
    // It feels the bone: the model's field at its position, within 5 % (a late tick reads zero).
    EXPECT_GT(appliedSum / contact, 0.5);
    EXPECT_LT(fieldErr / contact, 0.05 * fieldSum / contact);
    // And the way the server's own f(P_N) pushes (the field differs from it by J (p - P_N) as the
    // hand moves, and by the blend between models).
    EXPECT_GT(along / contact, 0.6);
    std::printf("[ figures  ] %d contact ticks: mean |field| %.3f N, |applied - field| %.3f N; "
                "mean |f(P_N)| %.3f N, |applied| %.3f N, |applied - f(P_N)| %.3f N, cos %.3f; "
                "%llu of %llu reads missed\n",
                contact, fieldSum / contact, fieldErr / contact, modelSum / contact,
                appliedSum / contact, modelErr / contact, along / contact,
                (unsigned long long)device->missedTicks(),
                (unsigned long long)session.core().hapticStats().ticks);
}

// A plugin that hangs a third of a second into the script is cut off: one line, zero force from
// then on, and the session runs its script to the end.
TEST_F(PluginSessionTest, AHangingPluginIsCutOffAndTheSessionGoesOn) {
    TraineeSession session(config());
    std::unique_ptr<Device> owner;
    PluginDevice* device =
        open(kPlugins + "/trephine_faulty_device.so?mode=hang,after=300,ms=400", owner);
    ASSERT_TRUE(device);
    SessionEnd end;
    pumpWhile([&] {
        session.join();
        session.awaitScene();
        session.openPreset("top");
        session.play(session.burrhole(1.0), 1.0, std::move(owner));
        session.drill();
        session.liftAndDrain(0.1);
        end = session.finish();
    });
    ASSERT_FALSE(HasFatalFailure());
    EXPECT_EQ(end.how, SessionEnd::How::ScriptDone) << session.endText(end);
    ASSERT_EQ(lines().size(), 1u);
    EXPECT_EQ(lines()[0], device->fault());
    EXPECT_NE(lines()[0].find("read did not return within 20.0 ms; force output cut off"),
              std::string::npos)
        << lines()[0];
    EXPECT_EQ(session.core().deviceFault(), device->fault());
    // The loop went on ticking after the cut, at zero force.
    const double cutAt = device->history().back().time;
    int after = 0;
    for (const HapticSample& h : session.core().hapticSamples())
        if (h.time > cutAt) {
            after++;
            EXPECT_EQ(h.force, glm::vec3(0.0f));
        }
    EXPECT_GT(after, 100);
    EXPECT_GT(session.core().deviceGuardStats().gated, 100u);
}

// The trainee's client core without a window: the client model folding snapshots and applied
// updates into the figures both shells report, the script as a tool source, and the core (client
// thread, haptic loop, force source) against a loopback server.
#include "net/client_model.h"
#include "net/tool_model.h"
#include "net/trainee_core.h"

#include "libsim/skull.h"
#include "libsim/tool_catalogue.h"

#include "loopback.h"

#include <glm/gtx/quaternion.hpp>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <chrono>
#include <memory>
#include <thread>

using namespace trephine;
using namespace trephine::net;

namespace {

std::shared_ptr<const ClientSnapshot> connected(uint64_t updates, uint64_t full) {
    auto s = std::make_shared<ClientSnapshot>();
    s->state = LinkState::Connected;
    s->updatesApplied = updates;
    s->fullUpdates = full;
    return s;
}

AppliedRect rect(bool full, uint32_t bytes, uint32_t raw, double latencyUs) {
    AppliedRect r;
    r.full = full;
    r.rect = full ? PixelRect{0, 0, 8, 8} : PixelRect{1, 1, 2, 2};
    r.bytes = bytes;
    r.rawBytes = raw;
    r.latencyUs = latencyUs;
    return r;
}

// The report as a reader sees it: written and parsed back.
nlohmann::json reread(const ClientModel& m, const ClientReportExtras& x = {}) {
    return nlohmann::json::parse(m.report(x).dump(2));
}

// A device held still at one pose.
class StillDevice : public Device {
public:
    explicit StillDevice(ToolPose pose) : m_pose(pose) {}
    std::string name() const override { return "still"; }
    DeviceState read(double) override { return {m_pose, 0u, true}; }
    void setForce(glm::vec3) override {}

private:
    ToolPose m_pose;
};

} // namespace

TEST(ClientModel, IncrementalUpdatesFillTheReportsWindowsAndFullOnesOnlyTheirCount) {
    ClientModel m;
    m.addSnapshot(connected(4, 1), 0.0);
    m.addRect(rect(true, 5000, 9000, -1), 0.1);
    m.addRect(rect(false, 10, 40, 100), 0.2);
    m.addRect(rect(false, 20, 80, 200), 0.3);
    m.addRect(rect(false, 30, 120, 300), 0.4);
    const nlohmann::json j = reread(m);
    EXPECT_EQ(j.at("updates_applied"), 4);
    EXPECT_EQ(j.at("full_updates"), 1);
    EXPECT_EQ(j.at("updates_shown"), 4);
    EXPECT_EQ(j.at("update_bytes").at("count"), 3);
    EXPECT_DOUBLE_EQ(j.at("update_bytes").at("mean").get<double>(), 20.0);
    EXPECT_DOUBLE_EQ(j.at("update_latency_us").at("p50").get<double>(), 200.0);
    EXPECT_DOUBLE_EQ(j.at("update_latency_us").at("max").get<double>(), 300.0);
    EXPECT_DOUBLE_EQ(j.at("compression_ratio").get<double>(), 4.0);
    EXPECT_EQ(j.at("dirty_boxes"), 4); // the full one's, then three
    EXPECT_EQ(m.network.updates.size(), 4u);
}

// A headless shell draws no frames: each second with a picture records a point, its latency the
// updates' own; a windowed shell records a second only when it drew a frame in the design.
TEST(ClientModel, RecordsAComparisonPointEachSecondForTheDesignShown) {
    ClientModel headless;
    headless.addSnapshot(connected(3, 1), 0.0);
    headless.tickComparison(0.0, SyncDesign::Dbi, true, 0);
    headless.addDrawn(SyncDesign::Dbi, 1000, 10, 10, 100, 400);
    headless.addDrawn(SyncDesign::Dbi, 3000, 10, 10, 300, 1200);
    headless.tickComparison(0.5, SyncDesign::Dbi, true, 500); // not a second yet
    EXPECT_FALSE(headless.comparison.measured(SyncDesign::Dbi));
    headless.tickComparison(1.0, SyncDesign::Dbi, true, 1000);
    ASSERT_TRUE(headless.comparison.measured(SyncDesign::Dbi));
    const ComparisonFigures& f = headless.comparison.series(SyncDesign::Dbi).last;
    EXPECT_DOUBLE_EQ(f.bytesPerUpdate, 200.0);
    EXPECT_DOUBLE_EQ(f.rawBytesPerUpdate, 800.0);
    EXPECT_DOUBLE_EQ(f.latencyP50Ms, 2.0);
    EXPECT_DOUBLE_EQ(f.hapticHz, 1000.0);
    EXPECT_EQ(f.frameMs, 0.0);
    EXPECT_FALSE(headless.comparison.measured(SyncDesign::Volume));
    EXPECT_DOUBLE_EQ(reread(headless).at("comparison").at("dbi").at("latency_p50_ms").get<double>(),
                     2.0);

    ClientModel window;
    window.addSnapshot(connected(3, 1), 0.0);
    window.tickComparison(0.0, SyncDesign::Dbi, true, 0);
    window.addFrame(SyncDesign::Volume, 4.0); // frames of the other design only
    window.tickComparison(1.0, SyncDesign::Dbi, true, 1000);
    EXPECT_FALSE(window.comparison.measured(SyncDesign::Dbi));
    window.addFrame(SyncDesign::Dbi, 2.0);
    window.addFrame(SyncDesign::Dbi, 6.0);
    window.tickComparison(2.0, SyncDesign::Dbi, true, 2000);
    ASSERT_TRUE(window.comparison.measured(SyncDesign::Dbi));
    EXPECT_DOUBLE_EQ(window.comparison.series(SyncDesign::Dbi).last.frameMs, 4.0);
    // No point while a switch is under way (record false).
    window.addFrame(SyncDesign::Dbi, 2.0);
    window.tickComparison(3.0, SyncDesign::Dbi, false, 3000);
    EXPECT_EQ(window.comparison.series(SyncDesign::Dbi).points, 1u);
}

// The figures of the session outlive its link: the snapshot after a stop carries none.
TEST(ClientModel, TheReportKeepsTheLastConnectedSnapshotsFigures) {
    ClientModel m;
    m.addSnapshot(connected(7, 2), 0.0);
    auto stopped = std::make_shared<ClientSnapshot>();
    stopped->state = LinkState::Stopped;
    m.addSnapshot(stopped, 1.0);
    const nlohmann::json j = reread(m);
    EXPECT_EQ(j.at("updates_applied"), 7);
    EXPECT_EQ(j.at("full_updates"), 2);
}

TEST(ClientModel, EachNewServerForceModelIsOneSample) {
    ClientModel m;
    auto s = connected(1, 1);
    auto withModel = std::make_shared<ClientSnapshot>(*s);
    withModel->hapticModel = HapticModel{};
    withModel->hapticModel->force = {0, 0, 2};
    withModel->hapticModels = 1;
    m.addSnapshot(withModel, 0.0);
    m.addSnapshot(withModel, 0.01); // the same model again: no new sample
    auto next = std::make_shared<ClientSnapshot>(*withModel);
    next->hapticModels = 2;
    m.addSnapshot(next, 0.02);
    ASSERT_EQ(m.forces.server.size(), 2u);
    EXPECT_EQ(m.forces.server.back().f, glm::vec3(0, 0, 2));
}

TEST(ToolModel, OneConversionForShapesAndForceModels) {
    ToolState t;
    t.toolKind = uint8_t(ToolKind::Perforator);
    t.diameterMm = 9.0f;
    EXPECT_EQ(shapeOf(t).kind, ToolKind::Perforator);
    EXPECT_EQ(shapeOf(t).diameterMm, 9.0f);
    t.toolKind = uint8_t(ToolKind::Burr);
    t.diameterMm = 3.0f;
    EXPECT_EQ(shapeOf(t).kind, ToolKind::Burr);
    HapticModel m;
    m.position = {1, 2, 3};
    m.force = {0, 0, 1.5f};
    m.gradient = glm::mat3(-6.0f);
    m.contact = true;
    m.toolSequence = 42;
    const HapticModelData d = toModelData(m);
    EXPECT_EQ(d.position, m.position);
    EXPECT_EQ(d.force, m.force);
    EXPECT_EQ(d.gradient, m.gradient);
    EXPECT_TRUE(d.contact);
    EXPECT_EQ(d.toolSequence, 42u);
}

// A script row holds until the next; after the end the tool no longer drills.
TEST(ScriptToolSource, RowsHoldAndDrillingStopsAtTheEnd) {
    StillDevice device({{0, 0, 0}, {1, 0, 0, 0}});
    std::vector<ScriptSample> script(2);
    script[0].t = 0.0;
    script[0].tool.toolKind = uint8_t(ToolKind::Burr);
    script[0].tool.diameterMm = 4.0f;
    script[0].tool.speed = 1.0f;
    script[0].tool.drilling = true;
    script[1] = script[0];
    script[1].t = 1.0;
    script[1].tool.toolKind = uint8_t(ToolKind::Perforator);
    script[1].tool.diameterMm = 8.0f;
    ScriptToolSource tools(device, script, 1.5);
    const ToolPose at{{1, 2, 3}, {1, 0, 0, 0}};
    EXPECT_EQ(tools.toolAt(at, 0.5).toolKind, uint8_t(ToolKind::Burr));
    EXPECT_EQ(tools.toolAt(at, 0.5).position, at.position);
    EXPECT_EQ(tools.toolAt(at, 1.2).diameterMm, 8.0f);
    EXPECT_TRUE(tools.toolAt(at, 1.2).drilling);
    EXPECT_FALSE(tools.toolAt(at, 1.5).drilling);
    EXPECT_EQ(tools.toolAt(at, 2.0).speed, 0.0f);
}

// A device with buttons headless (a SpaceMouse): button 0 stops and starts the drill, button 1
// picks the next tool at its default size; a held button counts once.
TEST(ScriptToolSource, ADevicesButtonsTakeOverFromTheRows) {
    StillDevice device({{0, 0, 0}, {1, 0, 0, 0}});
    std::vector<ScriptSample> script(1);
    script[0].tool.toolKind = uint8_t(ToolKind::Burr);
    script[0].tool.diameterMm = 4.0f;
    script[0].tool.speed = 1.0f;
    script[0].tool.drilling = true;
    ScriptToolSource tools(device, script, 10.0);
    const ToolPose at{{1, 2, 3}, {1, 0, 0, 0}};
    tools.noteButtons(0, 0.0);
    EXPECT_TRUE(tools.toolAt(at, 0.1).drilling);
    tools.noteButtons(1u, 0.2);
    tools.noteButtons(1u, 0.3); // still held
    EXPECT_FALSE(tools.toolAt(at, 0.3).drilling);
    EXPECT_EQ(tools.toolAt(at, 0.3).speed, 0.0f);
    tools.noteButtons(0, 0.4);
    tools.noteButtons(1u, 0.5);
    EXPECT_TRUE(tools.toolAt(at, 0.5).drilling);
    tools.noteButtons(2u, 0.6);
    EXPECT_EQ(tools.toolAt(at, 0.6).toolKind, uint8_t(ToolKind::Perforator));
    EXPECT_EQ(tools.toolAt(at, 0.6).diameterMm, toolType(ToolKind::Perforator).defaultDiameterMm);
}

// The core against a loopback server, in both designs: the haptic loop's tool states reach the
// server, its force models come back, and the force is felt from the server's models (DBI) or
// from the local copy of the volume (volume design).
TEST(TraineeCore, SendsToolStatesAndFeelsTheForceInEitherDesign) {
    Volume sphere = makeSphere(32);
    SessionServer server(sphere, trephine::testing::loopbackServerConfig("sphere:32"));
    server.start(); // the core's own waits cannot pump a test's server
    for (Sync design : {Sync::Dbi, Sync::Volume}) {
        SCOPED_TRACE(design == Sync::Dbi ? "dbi" : "volume");
        TraineeCoreConfig cc;
        cc.client.address = "127.0.0.1:" + std::to_string(server.port());
        cc.client.client.sync = design;
        cc.client.client.view = toViewSpec(cameraPreset("top", sphere, {32, 32}));
        TraineeCore core(cc);
        HeadlessView view(32);
        core.connect();
        ASSERT_TRUE(view.waitFor(core.client(), 30.0, [&] { return view.hasPicture(); }));
        // The burr resting on the top of the sphere, not drilling.
        const float top = sphere.extentMm().z * 0.5f * 0.8f;
        StillDevice device({{0, 0, top}, {1, 0, 0, 0}});
        std::vector<ScriptSample> script(1);
        script[0].tool.toolKind = uint8_t(ToolKind::Burr);
        script[0].tool.diameterMm = 4.0f;
        ScriptToolSource tools(device, script, 10.0);
        core.startHaptics(tools);
        EXPECT_TRUE(view.waitFor(core.client(), 30.0, [&] {
            return view.snap()->hapticModels > 5 && core.hapticStats().ticks > 100;
        }));
        core.stop();
        EXPECT_GT(view.model.session()->toolStatesSent, 5u);
        if (design == Sync::Dbi) {
            EXPECT_GT(core.serverForceTicks(), 0u);
            EXPECT_EQ(core.localForceTicks(), 0u);
        } else {
            EXPECT_GT(core.localForceTicks(), 0u);
            EXPECT_EQ(core.localForceTools(), 1u);
        }
        const nlohmann::json j =
            nlohmann::json::parse(view.model.report(core.reportExtras()).dump());
        EXPECT_GT(j.at("haptics").at("ticks").get<double>(), 100.0);
        EXPECT_GT(j.at("haptics").at("models_received").get<double>(), 5.0);
    }
    server.stop();
}

// The headless client's report (net_stats): a JSON document whose values are the statistics'
// own, read back with a JSON parser; text from peers and users that is not UTF-8, and figures
// that are not finite, still give valid JSON.
#include "net/net_stats.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <cmath>
#include <string>

using namespace trephine;
using namespace trephine::net;
using nlohmann::json;

namespace {

ReportInfo someInfo() {
    ReportInfo info;
    info.server = "127.0.0.1:7777";
    info.codec = "zstd";
    info.sync = "volume";
    info.view = "top";
    info.camera = "top 64x64";
    info.script = "burrhole";
    info.durationS = 2.5;
    info.updatesApplied = 42;
    info.fullUpdates = 2;
    info.toolStatesSent = 120;
    info.relaysReceived = 3;
    info.updatesRejected = 1;
    return info;
}

} // namespace

TEST(NetStats, ReportJsonCarriesEveryFigure) {
    NetStats stats;
    for (double us : {100.0, 200.0, 300.0})
        stats.rttUs.add(us);
    stats.updateBytes.add(5000);
    stats.clockOffsetUs = -17;
    stats.packetLoss = 0.25;
    stats.packetsLost = 4;
    stats.countMalformed();
    UpdateRecord r;
    r.mode = Sync::Volume;
    r.bytes = 800;
    r.rawBytes = 1000;
    r.latencyUs = 1500;
    r.erodeUs = 10;
    stats.modes[size_t(Sync::Volume)].add(r);
    stats.countIn(Channel::Control, 64);
    stats.countOut(Channel::ToolState, 32);
    stats.countOut(Channel::ToolState, 32);

    const json j = json::parse(reportJson(someInfo(), stats));
    EXPECT_EQ(j.at("server"), "127.0.0.1:7777");
    EXPECT_EQ(j.at("codec"), "zstd");
    EXPECT_EQ(j.at("sync"), "volume");
    EXPECT_EQ(j.at("script"), "burrhole");
    EXPECT_EQ(j.at("duration_s"), 2.5);
    EXPECT_EQ(j.at("updates_applied"), 42);
    EXPECT_EQ(j.at("full_updates"), 2);
    EXPECT_EQ(j.at("tool_states_sent"), 120);
    EXPECT_EQ(j.at("relays_received"), 3);
    EXPECT_EQ(j.at("updates_rejected"), 1);
    EXPECT_EQ(j.at("malformed_dropped"), 1);
    EXPECT_EQ(j.at("clock_offset_us"), -17);
    EXPECT_EQ(j.at("packet_loss"), 0.25);
    EXPECT_EQ(j.at("packets_lost"), 4);
    const json& rtt = j.at("rtt_us");
    EXPECT_EQ(rtt.at("count"), 3);
    EXPECT_EQ(rtt.at("mean"), 200.0);
    EXPECT_EQ(rtt.at("min"), 100.0);
    EXPECT_EQ(rtt.at("p50"), 200.0);
    EXPECT_EQ(rtt.at("max"), 300.0);
    EXPECT_EQ(j.at("update_bytes").at("count"), 1);
    const json& volume = j.at("modes").at("volume");
    EXPECT_EQ(volume.at("updates"), 1);
    EXPECT_EQ(volume.at("bytes").at("mean"), 800.0);
    EXPECT_EQ(volume.at("raw_bytes").at("mean"), 1000.0);
    EXPECT_EQ(volume.at("latency_us").at("p50"), 1500.0);
    EXPECT_EQ(volume.at("erode_us").at("count"), 1);
    EXPECT_EQ(volume.at("transmit_us").at("count"), 0) << "a stage not measured adds no sample";
    EXPECT_EQ(j.at("modes").at("dbi").at("updates"), 0);
    EXPECT_EQ(j.at("channels").at(channelName(Channel::Control)).at("bytes_in"), 64);
    EXPECT_EQ(j.at("channels").at(channelName(Channel::ToolState)).at("messages_out"), 2);
    EXPECT_FALSE(j.contains("haptics")) << "no haptic loop ran";
}

TEST(NetStats, ReportJsonHasTheHapticLoopWhenOneRan) {
    NetStats stats;
    stats.hapticRoundTripUs.add(400);
    ReportInfo info = someInfo();
    info.hapticLoop = true;
    info.toolRateHz = 50;
    info.hapticRateHz = 1000;
    info.achievedRateHz = 998.5;
    info.hapticTicks = 2000;
    info.hapticModels = 90;
    info.modelsApplied = 88;
    info.modelsDropped = 2;
    const json h = json::parse(reportJson(info, stats)).at("haptics");
    EXPECT_EQ(h.at("tool_rate_hz"), 50.0);
    EXPECT_EQ(h.at("rate_hz"), 1000.0);
    EXPECT_EQ(h.at("achieved_rate_hz"), 998.5);
    EXPECT_EQ(h.at("ticks"), 2000);
    EXPECT_EQ(h.at("models_received"), 90);
    EXPECT_EQ(h.at("models_applied"), 88);
    EXPECT_EQ(h.at("models_dropped"), 2);
    EXPECT_EQ(h.at("force_round_trip_p50_us"), 400.0);
}

TEST(NetStats, ReportJsonStaysValidForAnyTextAndFigure) {
    NetStats stats;
    stats.packetLoss = std::nan("");
    ReportInfo info = someInfo();
    info.script = std::string("cut \"a\"\n\xff\xfe end");
    info.durationS = INFINITY;
    json j;
    ASSERT_NO_THROW(j = json::parse(reportJson(info, stats)));
    const std::string script = j.at("script");
    EXPECT_EQ(script.rfind("cut \"a\"\n", 0), 0u) << script;
    EXPECT_NE(script.find(" end"), std::string::npos) << script;
    EXPECT_TRUE(j.at("packet_loss").is_null());
    EXPECT_TRUE(j.at("duration_s").is_null());
}

// The text pieces the server's report is still built from keep their layout.
TEST(NetStats, TextPiecesAreJson) {
    SampleWindow w{8};
    w.add(1.5);
    w.add(2.5);
    const json window = json::parse(jsonWindow(w));
    EXPECT_EQ(window.at("count"), 2);
    EXPECT_EQ(window.at("mean"), 2.0);
    EXPECT_EQ(jsonWindow(w).rfind("{\"count\": 2, \"mean\": 2,", 0), 0u) << jsonWindow(w);
    EXPECT_EQ(json::parse(jsonString("a\"b\\c\n")), "a\"b\\c\n");
    NetStats stats;
    stats.countIn(Channel::Control, 10);
    const json channels = json::parse(jsonChannels(stats));
    EXPECT_EQ(channels.at(channelName(Channel::Control)).at("bytes_in"), 10);
}

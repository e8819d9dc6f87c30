// The server report on its own: the counters and figures the parts record, as JSON.
#include "net/server_report.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

using namespace trephine;
using namespace trephine::net;

TEST(ServerReport, TheJsonHoldsTheRecordedFiguresInTheDocumentedOrder) {
    ReportBook book;
    NetStats stats;
    stats.countIn(Channel::ToolState, 40);
    stats.countMalformed();
    book.record([](ServerReport& r) {
        r.port = 7777;
        r.volume = "skull:64";
        r.maxClients = 16;
        r.counters.clients = 2;
        r.counters.hapticModelsSent = 9;
        r.peers[1].name = "Ada";
        r.peers[1].hello = true;
        r.peers[1].sync = Sync::Volume;
        r.peers[2].name = "left";
        r.peers[2].hello = true;
        r.peers[2].disconnectedUs = 5;
        r.modes[size_t(Sync::Volume)].sent.updates = 3;
        r.modes[size_t(Sync::Volume)].encodeUs.add(10.0);
        r.modes[size_t(Sync::Volume)].encodeUs.add(30.0);
    });
    book.count(&ServerCounters::viewsRefused, 2);
    EXPECT_EQ(book.counter(&ServerCounters::viewsRefused), 2u);
    const std::string text = book.read([&](const ServerReport& r) { return toJsonText(r, stats); });
    nlohmann::json j = nlohmann::json::parse(text);
    EXPECT_EQ(j["port"], 7777);
    EXPECT_EQ(j["volume"], "skull:64");
    EXPECT_EQ(j["clients"], 2);
    EXPECT_EQ(j["haptic_models_sent"], 9);
    EXPECT_EQ(j["views_refused"], 2);
    EXPECT_EQ(j["malformed_dropped"], 1);
    EXPECT_EQ(j["channels"]["tool"]["bytes_in"], 40);
    EXPECT_EQ(j["modes"]["volume"]["clients"], 1) << "Ada; the one who left is not counted";
    EXPECT_EQ(j["modes"]["dbi"]["clients"], 0);
    EXPECT_EQ(j["modes"]["volume"]["updates_sent"], 3);
    EXPECT_EQ(j["modes"]["volume"]["encode_us"]["count"], 2);
    EXPECT_DOUBLE_EQ(j["modes"]["volume"]["encode_us"]["mean"].get<double>(), 20.0);
    ASSERT_EQ(j["peers"].size(), 2u);
    EXPECT_EQ(j["peers"][0]["name"], "Ada");
    EXPECT_EQ(j["peers"][0]["connected"], true);
    EXPECT_EQ(j["peers"][1]["connected"], false);
    // The order docs/session.md lists: port first, peers last.
    EXPECT_LT(text.find("\"port\""), text.find("\"volume\""));
    EXPECT_LT(text.find("\"modes\""), text.find("\"peers\""));
}

TEST(ServerReport, NamesThatAreNotUtf8AreReplacedNotFatal) {
    ServerReport r;
    r.peers[1].name = std::string("Ad\xff\xfe", 4);
    r.volume = std::string("vol\xc3", 4);
    NetStats stats;
    std::string text;
    ASSERT_NO_THROW(text = toJsonText(r, stats));
    nlohmann::json j = nlohmann::json::parse(text);
    EXPECT_EQ(j["peers"][0]["name"].get<std::string>().substr(0, 2), "Ad");
}

// What a client shows as its image rate counts full images and drilling rectangles alike.
TEST(NetStats, ImageBytesCountBothImageChannels) {
    std::array<ChannelRates, size_t(Channel::Count)> rates{};
    rates[size_t(Channel::Image)].bytesInPerS = 1000;
    rates[size_t(Channel::ImageLossy)].bytesInPerS = 250;
    rates[size_t(Channel::Volume)].bytesInPerS = 7;
    rates[size_t(Channel::Image)].bytesOutPerS = 99;
    EXPECT_DOUBLE_EQ(imageBytesInPerS(rates), 1250);
}

#include "net/protocol.h"

#include <gtest/gtest.h>

#include <random>

using namespace trephine::net;

TEST(Protocol, MessagesRoundTrip) {
    Hello h;
    h.role = Role::Instructor;
    h.name = "Dr. Ada";
    h.codec = Codec::Zstd;
    h.view.eye = {1, 2, 3};
    h.view.width = 640;
    auto bytes = encodeMessage(h);
    ASSERT_FALSE(bytes.empty());
    EXPECT_EQ(peekMessageType(bytes), uint8_t(MessageType::Hello));
    Hello back;
    ASSERT_TRUE(decodeMessage(bytes, back));
    EXPECT_EQ(back.role, Role::Instructor);
    EXPECT_EQ(back.name, "Dr. Ada");
    EXPECT_EQ(back.codec, Codec::Zstd);
    EXPECT_EQ(back.view, h.view);

    HapticModel hm;
    hm.force = {0.5f, -1.0f, 2.0f};
    hm.gradient[1][2] = 3.5f;
    hm.contact = true;
    auto hb = encodeMessage(hm);
    HapticModel hmBack;
    ASSERT_TRUE(decodeMessage(hb, hmBack));
    EXPECT_EQ(hmBack.force, hm.force);
    EXPECT_EQ(hmBack.gradient, hm.gradient);
    // A message of one type never decodes as another.
    EXPECT_FALSE(decodeMessage(hb, back));
}

TEST(Protocol, RejectsOutOfRangeRectanglesAndTrailingBytes) {
    ImageUpdate u;
    u.x = 4000;
    u.width = 200; // runs past the largest window
    u.height = 4;
    u.rawBytes = 10;
    u.payload = {1, 2, 3};
    EXPECT_TRUE(encodeMessage(u).empty());

    u.x = 10;
    auto ok = encodeMessage(u);
    ImageUpdate back;
    ASSERT_TRUE(decodeMessage(ok, back));
    ok.push_back(0);
    EXPECT_FALSE(decodeMessage(ok, back)) << "trailing bytes accepted";

    ToolState t;
    t.speed = 0.5f;
    auto tb = encodeMessage(t);
    ToolState tBack;
    ASSERT_TRUE(decodeMessage(tb, tBack));
    // Poison the position with a NaN: position.x starts after seq(4)+time(8)+kind(1)+diam(4).
    float nan = std::nanf("");
    std::memcpy(&tb[1 + 17], &nan, 4);
    EXPECT_FALSE(decodeMessage(tb, tBack));
}

TEST(Protocol, TruncatedAndRandomPacketsNeverDecode) {
    ImageUpdate u;
    u.width = u.height = 8;
    u.rawBytes = 64;
    u.payload.assign(64, 7);
    auto bytes = encodeMessage(u);
    for (size_t n = 0; n < bytes.size(); ++n) {
        ImageUpdate back;
        EXPECT_FALSE(decodeMessage(std::span(bytes.data(), n), back)) << n;
    }
    std::mt19937 rng(7);
    int decoded = 0;
    for (int i = 0; i < 5000; ++i) {
        std::vector<uint8_t> junk(1 + rng() % 80);
        for (auto& b : junk)
            b = uint8_t(rng());
        junk[0] = uint8_t(MessageType::ToolState);
        ToolState t;
        decoded += decodeMessage(junk, t);
    }
    EXPECT_LT(decoded, 5); // random bytes almost never make a valid, exactly sized tool state
}

TEST(Protocol, RefuseReasonsReadAsSentences) {
    uint32_t data = uint32_t(RefuseReason::Version) | (7u << 8);
    EXPECT_NE(refuseReasonText(data).find("version 7"), std::string::npos);
    EXPECT_NE(refuseReasonText(uint32_t(RefuseReason::Shutdown)).find("shutting down"),
              std::string::npos);
}

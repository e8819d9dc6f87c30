#include "net/serialize.h"

#include <gtest/gtest.h>

#include <random>

using namespace trephine::net;

namespace {

struct Sample {
    uint8_t kind = 0;
    int32_t delta = 0;
    uint64_t stamp = 0;
    float f = 0;
    bool flag = false;
    std::string name;
    std::vector<uint8_t> payload;

    template <typename S>
    bool serialize(S& s) {
        return s.ranged(kind, uint8_t(0), uint8_t(3)) && s.integer(delta) && s.integer(stamp) &&
               s.f32(f) && s.boolean(flag) && s.string(name, 32) && s.blob(payload, 1024);
    }
};

std::vector<uint8_t> write(Sample s) {
    std::vector<uint8_t> out;
    WriteStream w(out);
    EXPECT_TRUE(s.serialize(w));
    return out;
}

} // namespace

TEST(Serialize, RoundTripIsExactAndLittleEndian) {
    Sample a{2, -5, 0x0102030405060708ull, 1.5f, true, "trainee", {1, 2, 3}};
    auto bytes = write(a);
    MeasureStream m;
    Sample copy = a;
    ASSERT_TRUE(copy.serialize(m));
    EXPECT_EQ(m.size(), bytes.size());
    // stamp starts after kind (1) and delta (4): least significant byte first.
    EXPECT_EQ(bytes[5], 0x08);
    EXPECT_EQ(bytes[12], 0x01);

    Sample b;
    ReadStream r(bytes);
    ASSERT_TRUE(b.serialize(r));
    EXPECT_TRUE(r.atEnd());
    EXPECT_EQ(b.kind, 2);
    EXPECT_EQ(b.delta, -5);
    EXPECT_EQ(b.stamp, a.stamp);
    EXPECT_EQ(b.f, 1.5f);
    EXPECT_TRUE(b.flag);
    EXPECT_EQ(b.name, "trainee");
    EXPECT_EQ(b.payload, a.payload);
}

TEST(Serialize, EveryTruncationFailsCleanly) {
    auto bytes = write(Sample{1, 7, 99, 2.0f, false, "x", std::vector<uint8_t>(100, 9)});
    for (size_t n = 0; n < bytes.size(); ++n) {
        Sample b;
        ReadStream r(std::span(bytes.data(), n));
        EXPECT_FALSE(b.serialize(r)) << "prefix of " << n << " bytes was accepted";
    }
}

TEST(Serialize, RangeAndLengthChecksRejectHostileValues) {
    auto bytes = write(Sample{1, 0, 0, 0, false, "", {}});
    bytes[0] = 9; // kind out of range
    Sample b;
    ReadStream r(bytes);
    EXPECT_FALSE(b.serialize(r));

    bytes = write(Sample{1, 0, 0, 0, false, "", {}});
    bytes[17] = 2; // boolean that is neither 0 nor 1
    ReadStream r2(bytes);
    EXPECT_FALSE(b.serialize(r2));

    bytes = write(Sample{1, 0, 0, 0, false, "", {}});
    // Claim a 4 GiB payload: the blob length is the last four bytes.
    for (size_t i = bytes.size() - 4; i < bytes.size(); ++i)
        bytes[i] = 0xff;
    ReadStream r3(bytes);
    EXPECT_FALSE(b.serialize(r3));

    Sample tooLong{0, 0, 0, 0, false, std::string(40, 'a'), {}};
    std::vector<uint8_t> out;
    WriteStream w(out);
    EXPECT_FALSE(tooLong.serialize(w));
}

TEST(Serialize, RandomBytesNeverCrash) {
    std::mt19937 rng(42);
    for (int i = 0; i < 2000; ++i) {
        std::vector<uint8_t> junk(rng() % 64);
        for (auto& b : junk)
            b = uint8_t(rng());
        Sample s;
        ReadStream r(junk);
        (void)s.serialize(r); // must simply return
    }
    SUCCEED();
}

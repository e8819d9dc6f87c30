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

// The size of the valid Sample encoding `b` begins with, 0 when it begins with none: kind (1 byte,
// at most 3), delta (4), stamp (8), f (4), flag (1 byte, 0 or 1), name (u16 length at most 32,
// then its bytes), payload (u32 length at most 1024, then its bytes); little-endian.
size_t validPrefix(const std::vector<uint8_t>& b) {
    size_t at = 0;
    auto have = [&](size_t n) { return b.size() - at >= n; };
    auto take = [&](size_t n) {
        uint32_t v = 0;
        for (size_t i = 0; i < n; ++i)
            v |= uint32_t(b[at + i]) << (8 * i);
        at += n;
        return v;
    };
    if (!have(18) || b[0] > 3 || b[17] > 1)
        return 0;
    at = 18;
    if (!have(2))
        return 0;
    const uint32_t name = take(2);
    if (name > 32 || !have(name))
        return 0;
    at += name;
    if (!have(4))
        return 0;
    const uint32_t payload = take(4);
    if (payload > 1024 || !have(payload))
        return 0;
    return at + payload;
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

// Random bytes, and valid encodings with a byte changed, cut short or followed by more: a read
// accepts exactly the inputs that begin with a valid encoding (told from the layout alone, by
// validPrefix), consumes exactly that encoding, and reads back what writes those bytes again.
TEST(Serialize, RandomBytesReadOnlyAsTheirValidPrefix) {
    std::mt19937 rng(42);
    int accepted = 0, refused = 0;
    for (int i = 0; i < 4000; ++i) {
        std::vector<uint8_t> bytes;
        if (i % 2 == 0) {
            bytes.resize(rng() % 64);
            for (auto& b : bytes)
                b = uint8_t(rng());
        } else {
            Sample a{uint8_t(rng() % 4),
                     int32_t(rng()),
                     uint64_t(rng()) << 32 | rng(),
                     float(rng() % 1000) * 0.5f,
                     rng() % 2 == 1,
                     std::string(rng() % 33, 'n'),
                     std::vector<uint8_t>(rng() % 40, uint8_t(rng()))};
            bytes = write(a);
            switch (rng() % 3) {
            case 0:
                bytes[rng() % bytes.size()] = uint8_t(rng());
                break;
            case 1:
                bytes.resize(rng() % (bytes.size() + 1));
                break;
            default:
                bytes.insert(bytes.end(), rng() % 8, uint8_t(rng()));
            }
        }
        const size_t valid = validPrefix(bytes);
        Sample s;
        ReadStream r(bytes);
        const bool ok = s.serialize(r);
        ASSERT_EQ(ok, valid > 0) << "input " << i << " of " << bytes.size() << " bytes";
        if (!ok) {
            ++refused;
            continue;
        }
        ++accepted;
        EXPECT_EQ(r.remaining(), bytes.size() - valid) << "input " << i;
        EXPECT_EQ(write(s), std::vector<uint8_t>(bytes.begin(), bytes.begin() + ptrdiff_t(valid)))
            << "input " << i;
    }
    // Both outcomes are exercised, so neither half of the check is vacuous.
    EXPECT_GT(accepted, 500);
    EXPECT_GT(refused, 500);
}

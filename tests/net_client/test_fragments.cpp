#include "net/fragments.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <numeric>
#include <random>
#include <vector>

using namespace trephine::net;

namespace {

std::vector<uint8_t> message(size_t n, uint32_t seed) {
    std::mt19937 rng(seed);
    std::vector<uint8_t> m(n);
    for (uint8_t& b : m)
        b = uint8_t(rng());
    return m;
}

using Fragments = std::vector<std::vector<uint8_t>>;

// Feeds every fragment but those in `lose`; the message it completes, if any.
std::optional<std::vector<uint8_t>> deliver(FragmentAssembler& a, const Fragments& f,
                                            const std::vector<size_t>& lose = {}) {
    std::optional<std::vector<uint8_t>> whole;
    for (size_t i = 0; i < f.size(); ++i) {
        if (std::find(lose.begin(), lose.end(), i) != lose.end())
            continue;
        std::vector<uint8_t> out;
        if (a.add(f[i], out) == FragmentAssembler::Result::Complete)
            whole = out;
    }
    return whole;
}

} // namespace

TEST(Fragments, EveryMessageComesBackWholeWithOrWithoutParity) {
    for (size_t n : {size_t(0), size_t(1), size_t(255), size_t(256), size_t(257), size_t(5000)}) {
        for (uint32_t loss : {0u, 10u, 50u}) {
            const auto m = message(n, uint32_t(n));
            const Fragments f = splitMessage(m, 7, 270, loss);
            const int data = n <= 256 ? 1 : int((n + 255) / 256); // 270 less a 14-byte header
            const int stripes = (data + kMaxStripe - 1) / kMaxStripe;
            const int parity = n == 0 ? 0 : parityFor((data + stripes - 1) / stripes, loss);
            EXPECT_EQ(f.size(), size_t(data + stripes * parity)) << n << " bytes, loss " << loss;
            for (const auto& piece : f)
                EXPECT_LE(piece.size(), 270u);
            FragmentAssembler a(1 << 20);
            EXPECT_EQ(deliver(a, f), m) << n << " bytes, loss " << loss;
            EXPECT_EQ(a.lost(), 0u);
        }
    }
}

TEST(Fragments, ParityRebuildsAsManyLostFragmentsAsItHasAndNoMore) {
    EXPECT_EQ(parityFor(11, 0), 0);
    EXPECT_EQ(parityFor(11, 10), 2);
    EXPECT_EQ(parityFor(23, 10), 3);
    EXPECT_EQ(parityFor(11, 50), 4);
    // 15000 bytes: 59 data fragments of 255 bytes (the last 210) in stripes of 30 and 29, with 3
    // parity fragments each at 1 %: data 0-29, their parity 59-61; data 30-58, parity 62-64.
    const auto m = message(15000, 1);
    const Fragments f = splitMessage(m, 1, 270, 10);
    ASSERT_EQ(f.size(), 65u);
    // Sent in stripe order: positions 0-29 data, 30-32 parity, 33-61 data, 62-64 parity.
    const std::vector<std::vector<size_t>> rebuilt = {
        {0, 1, 2},          // three data of one stripe
        {0, 31, 61, 64},    // data and parity of both, the short last one among them
        {30, 31, 32},       // a stripe's whole parity
        {5, 6, 40, 41, 42}, // two in one stripe, three in the other
    };
    for (const auto& lose : rebuilt) {
        FragmentAssembler a(1 << 20);
        EXPECT_EQ(deliver(a, f, lose), m) << "lost " << lose.size();
    }
    FragmentAssembler a(1 << 20);
    EXPECT_EQ(deliver(a, f, {0, 1, 2, 30}), std::nullopt) << "four of one stripe";
    // Any three of each stripe's 33, drawn at random.
    std::mt19937 rng(3);
    for (int trial = 0; trial < 200; ++trial) {
        std::vector<size_t> lose;
        for (auto [first, count] : {std::pair<size_t, size_t>{0, 33}, {33, 32}}) {
            std::vector<size_t> stripe(count);
            std::iota(stripe.begin(), stripe.end(), first);
            std::shuffle(stripe.begin(), stripe.end(), rng);
            lose.insert(lose.end(), stripe.begin(), stripe.begin() + 3);
        }
        FragmentAssembler r(1 << 20);
        ASSERT_EQ(deliver(r, f, lose), m) << "trial " << trial;
    }
    FragmentAssembler b(1 << 20);
    EXPECT_EQ(deliver(b, splitMessage(m, 1, 270, 0), {5}), std::nullopt) << "no parity";
}

TEST(Fragments, NewestWinsAndOnlyAFewIncompleteMessagesAreKept) {
    FragmentAssembler a(1 << 20);
    const auto m1 = message(900, 1), m2 = message(900, 2); // four fragments each
    const Fragments f1 = splitMessage(m1, 1, 270, 0), f2 = splitMessage(m2, 2, 270, 0);
    std::vector<uint8_t> out;
    EXPECT_EQ(a.add(f1[0], out), FragmentAssembler::Result::Incomplete);
    EXPECT_EQ(deliver(a, f2), m2);
    // Message 1 is older than one delivered: its rest is stale, and it was counted as dropped.
    EXPECT_EQ(a.add(f1[1], out), FragmentAssembler::Result::Stale);
    // Incomplete messages past kMaxPartial: the oldest goes; the newer ones still complete.
    std::vector<Fragments> pending;
    for (uint32_t id = 10; id < 10 + FragmentAssembler::kMaxPartial + 1; ++id) {
        pending.push_back(splitMessage(message(900, id), id, 270, 0));
        EXPECT_EQ(a.add(pending.back()[0], out), FragmentAssembler::Result::Incomplete);
    }
    // The evicted one's late fragment does not evict a newer one.
    EXPECT_EQ(a.add(pending[0][1], out), FragmentAssembler::Result::Stale);
    EXPECT_EQ(deliver(a, {pending.back()[1], pending.back()[2], pending.back()[3]}),
              message(900, uint32_t(10 + FragmentAssembler::kMaxPartial)));
}

TEST(Fragments, AnythingThatIsNotAFragmentIsRefusedAndNeverCrashes) {
    FragmentAssembler a(4096);
    std::vector<uint8_t> out;
    const Fragments f = splitMessage(message(1000, 3), 5, 270, 50);
    auto bad = [&](std::vector<uint8_t> d) { return a.add(d, out); };
    using R = FragmentAssembler::Result;
    EXPECT_EQ(bad({1, 2, 3}), R::Refused); // shorter than a header
    auto truncated = f[0];
    truncated.pop_back();
    EXPECT_EQ(bad(truncated), R::Refused); // not the size its header says
    auto index = f[0];
    index[4] = 200; // past the data and parity fragments
    EXPECT_EQ(bad(index), R::Refused);
    auto big = f[0];
    big[12] = 1; // 64 KiB: past what this assembler takes
    EXPECT_EQ(bad(big), R::Refused);
    auto count = f[0];
    count[6] = 0; // no data fragments
    count[7] = 0;
    EXPECT_EQ(bad(count), R::Refused);
    auto stripe = f[0];
    stripe[8] = 0; // stripes of nothing
    EXPECT_EQ(bad(stripe), R::Refused);
    stripe[8] = 1; // stripes other than the sender's even ones
    EXPECT_EQ(bad(stripe), R::Refused);
    // Thousands of one-byte fragments for a datagram: no sender splits so.
    std::vector<uint8_t> tiny = {9, 0, 0, 0, 0, 0, 0, 16, 32, 16, 0, 16, 0, 0, 0};
    EXPECT_EQ(bad(tiny), R::Refused);
    auto parity = f[0];
    parity[9] = kMaxParity + 1;
    EXPECT_EQ(bad(parity), R::Refused);
    EXPECT_EQ(bad(f[0]), R::Incomplete);
    auto other = f[1];
    other[9] = 1; // the same message with other parity
    EXPECT_EQ(bad(other), R::Refused);
    // Random datagrams, and random mutations of real ones.
    std::mt19937 rng(9);
    for (int i = 0; i < 20000; ++i) {
        std::vector<uint8_t> d = f[size_t(rng()) % f.size()];
        if (i % 2)
            d.resize(size_t(rng()) % 120);
        for (int k = 0; k < 3; ++k)
            if (!d.empty())
                d[size_t(rng()) % d.size()] = uint8_t(rng());
        a.add(d, out);
    }
}

TEST(Fragments, TheLossFigureFollowsTheLink) {
    FragmentAssembler a(1 << 20);
    std::mt19937 rng(4);
    std::bernoulli_distribution lost(0.01);
    for (uint32_t id = 1; id <= 400; ++id) {
        const Fragments f = splitMessage(message(6000, id), id, 270, 10);
        std::vector<size_t> lose;
        for (size_t i = 0; i < f.size(); ++i)
            if (lost(rng))
                lose.push_back(i);
        deliver(a, f, lose);
    }
    EXPECT_GT(a.received(), 9000u);
    // One-datagram messages lost whole count too.
    FragmentAssembler small(1 << 20);
    for (uint32_t id = 1; id <= 1000; ++id)
        if (id % 50 != 0)
            deliver(small, splitMessage(message(40, id), id, 270, 0));
    EXPECT_EQ(small.lost(), 19u); // the last one lost is not followed by another
    EXPECT_GE(small.lossPermille(), 10u);
    EXPECT_LE(small.lossPermille(), 40u);
    EXPECT_GE(a.lossPermille(), 3u);
    EXPECT_LE(a.lossPermille(), 25u);
}

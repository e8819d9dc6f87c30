#include "libsim/stats.h"

#include <gtest/gtest.h>

using namespace trephine;

TEST(Stats, PercentileInterpolatesLikeNumpy) {
    std::vector<double> v{4, 1, 3, 2, 5};
    EXPECT_DOUBLE_EQ(percentile(v, 50), 3.0);
    EXPECT_DOUBLE_EQ(percentile(v, 0), 1.0);
    EXPECT_DOUBLE_EQ(percentile(v, 100), 5.0);
    EXPECT_DOUBLE_EQ(percentile(v, 25), 2.0);
    EXPECT_DOUBLE_EQ(percentile(v, 90), 4.6);
    EXPECT_DOUBLE_EQ(percentile(std::vector<double>{}, 50), 0.0);
}

TEST(Stats, SampleWindowKeepsTheNewestSamplesAndAllTotals) {
    SampleWindow w(3);
    for (double x : {10.0, 20.0, 30.0, 40.0, 50.0})
        w.add(x);
    EXPECT_EQ(w.size(), 3u);
    EXPECT_EQ(w.totalCount(), 5u);
    EXPECT_DOUBLE_EQ(w.mean(), 30.0);
    EXPECT_DOUBLE_EQ(w.min(), 10.0);
    EXPECT_DOUBLE_EQ(w.max(), 50.0);
    EXPECT_EQ(w.samples(), (std::vector<double>{30, 40, 50}));
    EXPECT_DOUBLE_EQ(w.percentile(50), 40.0);
}

TEST(Stats, HistogramClampsOutliersIntoEndBuckets) {
    Histogram h(0.0, 10.0, 5);
    for (double x : {-1.0, 0.5, 2.0, 2.5, 9.9, 42.0})
        h.add(x);
    EXPECT_EQ(h.total(), 6u);
    EXPECT_EQ(h.count(0), 2u);
    EXPECT_EQ(h.count(1), 2u);
    EXPECT_EQ(h.count(4), 2u);
    EXPECT_DOUBLE_EQ(h.bucketLow(2), 4.0);
}

// Statistics as data: exact percentiles over a bounded window of samples, and a fixed-bucket
// histogram for plots. Used by the network statistics, the benchmarks and the study.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

namespace trephine {

// The p-th percentile (p in [0, 100]) by linear interpolation between order statistics, as
// numpy's default. Returns 0 for no samples.
double percentile(std::span<const double> samples, double p);

// Keeps the most recent `capacity` samples (a ring) plus running totals over all samples.
class SampleWindow {
public:
    explicit SampleWindow(size_t capacity = 4096) : m_capacity(capacity) {}

    void add(double v);
    void clear();

    size_t size() const { return m_samples.size(); }
    uint64_t totalCount() const { return m_total; }
    double totalSum() const { return m_sum; }
    double mean() const { return m_total ? m_sum / double(m_total) : 0.0; }
    double min() const { return m_min; }
    double max() const { return m_max; }
    // Percentile over the samples still in the window.
    double percentile(double p) const;
    // The window's samples, oldest first.
    std::vector<double> samples() const;

private:
    size_t m_capacity;
    std::vector<double> m_samples;
    size_t m_next = 0;
    uint64_t m_total = 0;
    double m_sum = 0.0;
    double m_min = 0.0, m_max = 0.0;
};

// Fixed buckets [lo + i*width, lo + (i+1)*width); values outside land in the end buckets.
class Histogram {
public:
    Histogram(double lo, double hi, int buckets);
    void add(double v);
    int bucketCount() const { return int(m_counts.size()); }
    uint64_t count(int bucket) const { return m_counts[size_t(bucket)]; }
    double bucketLow(int bucket) const { return m_lo + bucket * m_width; }
    double bucketWidth() const { return m_width; }
    uint64_t total() const { return m_total; }

private:
    double m_lo, m_width;
    std::vector<uint64_t> m_counts;
    uint64_t m_total = 0;
};

} // namespace trephine

#include "libsim/stats.h"

#include <algorithm>
#include <cassert>
#include <cmath>

namespace trephine {

double percentile(std::span<const double> samples, double p) {
    if (samples.empty())
        return 0.0;
    std::vector<double> v(samples.begin(), samples.end());
    std::sort(v.begin(), v.end());
    double rank = std::clamp(p, 0.0, 100.0) / 100.0 * double(v.size() - 1);
    size_t lo = size_t(std::floor(rank));
    size_t hi = std::min(lo + 1, v.size() - 1);
    double f = rank - double(lo);
    return v[lo] + (v[hi] - v[lo]) * f;
}

void SampleWindow::add(double v) {
    if (m_total == 0) {
        m_min = m_max = v;
    } else {
        m_min = std::min(m_min, v);
        m_max = std::max(m_max, v);
    }
    ++m_total;
    m_sum += v;
    if (m_capacity == 0)
        return;
    if (m_samples.size() < m_capacity) {
        m_samples.push_back(v);
    } else {
        m_samples[m_next] = v;
        m_next = (m_next + 1) % m_capacity;
    }
}

void SampleWindow::clear() {
    m_samples.clear();
    m_next = 0;
    m_total = 0;
    m_sum = m_min = m_max = 0.0;
}

double SampleWindow::percentile(double p) const {
    return trephine::percentile(m_samples, p);
}

std::vector<double> SampleWindow::samples() const {
    std::vector<double> out;
    out.reserve(m_samples.size());
    for (size_t i = 0; i < m_samples.size(); ++i)
        out.push_back(m_samples[(m_next + i) % m_samples.size()]);
    return out;
}

Histogram::Histogram(double lo, double hi, int buckets)
    : m_lo(lo), m_width((hi - lo) / buckets), m_counts(size_t(buckets), 0) {
    assert(buckets > 0 && hi > lo && "Histogram needs hi > lo and at least one bucket");
}

void Histogram::add(double v) {
    int b = int(std::floor((v - m_lo) / m_width));
    b = std::clamp(b, 0, int(m_counts.size()) - 1);
    m_counts[size_t(b)]++;
    ++m_total;
}

} // namespace trephine

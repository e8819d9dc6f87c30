#include "study/progress.h"

#include <fmt/format.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>

namespace trephine::study {

namespace {

double nowS() {
    return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch())
        .count();
}

} // namespace

ProgressBar::ProgressBar(int total, int enabled, std::FILE* out)
    : m_total(std::max(total, 1)), m_enabled(enabled < 0 ? isatty(fileno(out)) != 0 : enabled != 0),
      m_out(out), m_startS(nowS()) {}

ProgressBar::~ProgressBar() {
    finish();
}

std::string ProgressBar::line() const {
    constexpr int kWidth = 30;
    const int filled = m_done * kWidth / m_total;
    std::string bar(size_t(filled), '#');
    bar.append(size_t(kWidth - filled), '.');
    std::string s = fmt::format("[{}] {:3}% {:5.0f}s {}", bar, m_done * 100 / m_total,
                                nowS() - m_startS, m_label);
    if (s.size() > 100)
        s.resize(100);
    return s;
}

void ProgressBar::set(int done, const std::string& label) {
    m_done = std::clamp(done, 0, m_total);
    m_label = label;
    if (!m_enabled || m_finished)
        return;
    // \033[K clears what a longer previous label left on the line.
    fmt::print(m_out, "\r{}\033[K", line());
    std::fflush(m_out);
}

void ProgressBar::finish() {
    if (m_finished)
        return;
    m_finished = true;
    if (m_enabled) {
        fmt::print(m_out, "\r\033[K");
        std::fflush(m_out);
    }
}

} // namespace trephine::study

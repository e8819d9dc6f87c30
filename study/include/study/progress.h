// A one-line progress bar for long studies: drawn in place on a terminal (stderr), silent when
// stderr is not a terminal (logs and CI stay clean). Thread-compatible, not thread-safe.
#pragma once

#include <cstdio>
#include <string>

namespace trephine::study {

class ProgressBar {
public:
    // `total` steps; `enabled` < 0: decide by isatty(stderr).
    explicit ProgressBar(int total, int enabled = -1, std::FILE* out = stderr);
    ~ProgressBar(); // finishes the line

    // Moves to `done` steps (clamped to total) and shows `label` beside the bar.
    void set(int done, const std::string& label);
    void step(const std::string& label) { set(m_done + 1, label); }
    void finish();

    bool enabled() const { return m_enabled; }
    int done() const { return m_done; }
    int total() const { return m_total; }
    // The text drawn for the current state (without the carriage return), for tests.
    std::string line() const;

private:
    int m_total;
    int m_done = 0;
    bool m_enabled;
    bool m_finished = false;
    std::FILE* m_out;
    std::string m_label;
    double m_startS;
};

} // namespace trephine::study

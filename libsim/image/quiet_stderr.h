// Holds the process's stderr on /dev/null while alive. libpng, inside OpenImageIO, prints its own
// "libpng error: ..." line before OpenImageIO hands back the same reason, which we report as the
// one line a bad file gets: without this a corrupt slice printed two. Only for reads done while
// nothing else runs (loading a volume at start-up): it silences every thread's stderr meanwhile.
#pragma once

#include <cstdio>
#include <fcntl.h>
#include <unistd.h>

namespace trephine {

class QuietStderr {
public:
    QuietStderr() {
        std::fflush(stderr);
        m_saved = ::dup(2);
        const int null = ::open("/dev/null", O_WRONLY | O_CLOEXEC);
        if (m_saved >= 0 && null >= 0)
            ::dup2(null, 2);
        if (null >= 0)
            ::close(null);
    }
    ~QuietStderr() {
        std::fflush(stderr);
        if (m_saved >= 0) {
            ::dup2(m_saved, 2);
            ::close(m_saved);
        }
    }
    QuietStderr(const QuietStderr&) = delete;
    QuietStderr& operator=(const QuietStderr&) = delete;

private:
    int m_saved = -1;
};

} // namespace trephine

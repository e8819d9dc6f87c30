#include "net/send_passes.h"

#include <chrono>

namespace trephine::net {

void SendPasses::open() {
    std::lock_guard lock(m_mutex);
    m_open = true;
}

void SendPasses::close() {
    {
        std::lock_guard lock(m_mutex);
        m_open = false;
    }
    m_ended.notify_all();
}

SendPasses::Pass::Pass(SendPasses& passes) : m_passes(passes) {
    std::lock_guard lock(m_passes.m_mutex);
    ++m_passes.m_begun;
}

SendPasses::Pass::~Pass() {
    {
        std::lock_guard lock(m_passes.m_mutex);
        ++m_passes.m_done;
    }
    m_passes.m_ended.notify_all();
}

// A pass under way may have begun before the post, so the one after it is waited for.
void SendPasses::posted() {
    std::lock_guard lock(m_mutex);
    m_wanted = m_begun + 1;
}

bool SendPasses::awaitPosted(uint64_t maxWaitUs) {
    std::unique_lock lock(m_mutex);
    return m_ended.wait_for(lock, std::chrono::microseconds(maxWaitUs),
                            [&] { return !m_open || m_done >= m_wanted; });
}

} // namespace trephine::net

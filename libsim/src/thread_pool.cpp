#include "libsim/thread_pool.h"

#include <fmt/format.h>
#include <pthread.h>

#include <algorithm>

namespace trephine {

ThreadPool::ThreadPool(int threads, const std::string& name) {
    if (threads <= 0)
        threads = int(std::max(1u, std::thread::hardware_concurrency()));
    for (int i = 1; i < threads; ++i) {
        // Linux takes 15 bytes and a NUL; the number is kept, the name cut.
        const std::string number = fmt::format("-{}", i);
        const std::string threadName =
            fmt::format("{}{}", name.substr(0, 15 - number.size()), number);
        m_workers.emplace_back([this, threadName] {
            pthread_setname_np(pthread_self(), threadName.c_str());
            workerLoop();
        });
    }
}

ThreadPool::~ThreadPool() {
    {
        std::lock_guard lock(m_mutex);
        m_stop = true;
    }
    m_wake.notify_all();
    for (std::thread& t : m_workers)
        t.join();
}

void ThreadPool::runItems(uint32_t generation, int count, const std::function<void(int)>* fn) {
    uint64_t v = m_claim.load(std::memory_order_acquire);
    for (;;) {
        // A claim is valid only for this job and below its count. While a claimed item is
        // unfinished the caller cannot return, so fn (this job's) stays alive while it runs.
        if (uint32_t(v >> 32) != generation || int(uint32_t(v)) >= count)
            return;
        if (!m_claim.compare_exchange_weak(v, v + 1, std::memory_order_acq_rel,
                                           std::memory_order_acquire))
            continue;
        (*fn)(int(uint32_t(v)));
        if (m_remaining.fetch_sub(1, std::memory_order_acq_rel) == 1)
            m_remaining.notify_all();
        v = m_claim.load(std::memory_order_acquire);
    }
}

void ThreadPool::workerLoop() {
    uint32_t seen = 0;
    for (;;) {
        const std::function<void(int)>* fn;
        int count;
        {
            std::unique_lock lock(m_mutex);
            m_wake.wait(lock, [&] { return m_stop || m_generation != seen; });
            if (m_stop)
                return;
            seen = m_generation;
            fn = m_fn;
            count = m_count;
        }
        runItems(seen, count, fn);
    }
}

void ThreadPool::parallelFor(int count, const std::function<void(int)>& fn) {
    if (count <= 0)
        return;
    if (m_workers.empty() || count == 1) {
        for (int i = 0; i < count; ++i)
            fn(i);
        return;
    }
    uint32_t generation;
    {
        std::lock_guard lock(m_mutex);
        generation = ++m_generation;
        m_fn = &fn;
        m_count = count;
        m_remaining.store(count, std::memory_order_relaxed);
        m_claim.store(uint64_t(generation) << 32, std::memory_order_release);
    }
    m_wake.notify_all();
    runItems(generation, count, &fn);
    // Items the workers still run: wait for them to finish (not for idle workers to wake).
    for (int left = m_remaining.load(std::memory_order_acquire); left != 0;
         left = m_remaining.load(std::memory_order_acquire))
        m_remaining.wait(left, std::memory_order_acquire);
}

} // namespace trephine

#include "libsim/thread_pool.h"

#include <fmt/format.h>
#include <pthread.h>
#include <sys/resource.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <algorithm>

namespace trephine {

ThreadPool::ThreadPool(int threads, const std::string& name, int nice) : m_callerWorks(nice <= 0) {
    if (threads <= 0)
        threads = int(std::max(1u, std::thread::hardware_concurrency()));
    for (int i = m_callerWorks ? 1 : 0; i < threads; ++i) {
        // Linux takes 15 bytes and a NUL; the number is kept, the name cut.
        const std::string number = fmt::format("-{}", i);
        const std::string threadName =
            fmt::format("{}{}", name.substr(0, 15 - number.size()), number);
        m_workers.emplace_back([this, threadName, nice] {
            pthread_setname_np(pthread_self(), threadName.c_str());
            if (nice > 0)
                setpriority(PRIO_PROCESS, id_t(syscall(SYS_gettid)), nice);
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

void ThreadPool::runItems(uint32_t generation, const Job& job, int below) {
    uint64_t v = m_claim.load(std::memory_order_acquire);
    for (;;) {
        // A claim is valid only for this job and below its count (a closed job's counter is past
        // it). While a claimed item is unfinished the caller cannot return, so the job's
        // functions stay alive while it runs.
        const uint32_t item = uint32_t(v);
        if (uint32_t(v >> 32) != generation || int64_t(item) >= below)
            return;
        if (!m_claim.compare_exchange_weak(v, v + 1, std::memory_order_acq_rel,
                                           std::memory_order_acquire))
            continue;
        (*job.fn)(int(item));
        // Asked while this item is unfinished, so the caller (and `stop`) is still there, when
        // the next to claim is past the first `atLeast`.
        if (job.stop) {
            const uint32_t next = uint32_t(m_claim.load(std::memory_order_acquire));
            if (!(next & kClosed) && int(next) >= job.atLeast && int(next) < job.count &&
                (*job.stop)())
                close(generation, job.count);
        }
        finished(1);
        v = m_claim.load(std::memory_order_acquire);
    }
}

void ThreadPool::close(uint32_t generation, int count) {
    uint64_t v = m_claim.load(std::memory_order_acquire);
    for (;;) {
        const uint32_t item = uint32_t(v);
        if (uint32_t(v >> 32) != generation || int64_t(item) >= count)
            return; // claimed to the end, or closed by another thread
        if (m_claim.compare_exchange_weak(v, (uint64_t(generation) << 32) | (item | kClosed),
                                          std::memory_order_acq_rel, std::memory_order_acquire))
            break;
    }
    finished(count - int(uint32_t(v)));
}

void ThreadPool::finished(int n) {
    if (m_remaining.fetch_sub(n, std::memory_order_acq_rel) == n) {
        m_signal.fetch_add(1, std::memory_order_release);
        m_signal.notify_all();
    }
}

void ThreadPool::nudge() {
    m_signal.fetch_add(1, std::memory_order_release);
    m_signal.notify_all();
}

void ThreadPool::workerLoop() {
    uint32_t seen = 0;
    for (;;) {
        Job job;
        {
            std::unique_lock lock(m_mutex);
            m_wake.wait(lock, [&] { return m_stop || m_generation != seen; });
            if (m_stop)
                return;
            seen = m_generation;
            job = m_job;
        }
        runItems(seen, job, job.count);
    }
}

void ThreadPool::parallelFor(int count, const std::function<void(int)>& fn) {
    run(Job{&fn, count});
}

int ThreadPool::parallelForUntil(int count, const std::function<void(int)>& fn,
                                 const std::function<bool()>& stop, int atLeast) {
    return run(Job{&fn, count, &stop, std::clamp(atLeast, 0, std::max(count, 0))});
}

int ThreadPool::run(const Job& job) {
    if (job.count <= 0)
        return 0;
    if (m_workers.empty() || (job.count == 1 && m_callerWorks)) {
        for (int i = 0; i < job.count; ++i) {
            if (job.stop && i >= job.atLeast && (*job.stop)())
                return i;
            (*job.fn)(i);
        }
        return job.count;
    }
    uint32_t generation;
    {
        std::lock_guard lock(m_mutex);
        generation = ++m_generation;
        m_job = job;
        m_remaining.store(job.count, std::memory_order_relaxed);
        m_claim.store(uint64_t(generation) << 32, std::memory_order_release);
    }
    m_wake.notify_all();
    if (m_callerWorks)
        runItems(generation, job, job.count);
    // Items the workers still run: wait for them to finish (not for idle workers to wake). The
    // signal is read before the count, so a finish or nudge between the two ends the wait at once.
    for (bool closed = !job.stop;;) {
        const uint32_t signal = m_signal.load(std::memory_order_acquire);
        if (m_remaining.load(std::memory_order_acquire) == 0)
            break;
        if (!closed && (*job.stop)()) {
            // Workers not yet on the CPU claim nothing more: the caller does what must be done.
            runItems(generation, job, job.atLeast);
            close(generation, job.count);
            closed = true;
            continue;
        }
        m_signal.wait(signal, std::memory_order_acquire);
    }
    // Every claimed item is done; the counter says how far the claims went.
    return std::min(job.count, int(uint32_t(m_claim.load(std::memory_order_acquire)) & ~kClosed));
}

} // namespace trephine

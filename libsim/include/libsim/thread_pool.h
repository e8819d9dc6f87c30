// A small fork-join worker pool for the renderer: parallelFor hands out work items to the workers
// and the calling thread, and returns when all are done. One job at a time.
//
// The caller never waits for a worker that has not started: items are claimed from one atomic
// counter tagged with the job's generation, and the caller returns as soon as every item has
// *finished*, whoever ran it. A worker that wakes late finds the job's items all claimed (or a
// newer generation) and goes back to sleep, so a small job on a busy machine costs the caller no
// hand-off latency beyond the work itself.
#pragma once

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

namespace trephine {

class ThreadPool {
public:
    // threads counts the calling thread: 0 means std::thread::hardware_concurrency(); 1 runs
    // everything on the caller. The workers are named "<name>-1", "<name>-2", ... (15 bytes at
    // most), so a profiler or top -H tells whose they are.
    //
    // With `nice` above 0 the pool is for background work: `threads` workers run at that nice
    // value (Linux: each thread's own) and the calling thread only waits for them, so all the
    // work yields the CPU to whatever else runs, the caller's other work included.
    explicit ThreadPool(int threads = 0, const std::string& name = "pool", int nice = 0);
    ~ThreadPool();
    ThreadPool(const ThreadPool&) = delete;
    ThreadPool& operator=(const ThreadPool&) = delete;

    // Threads that take part in parallelFor: the caller too, unless the pool is a background one.
    int size() const { return int(m_workers.size()) + (m_callerWorks ? 1 : 0); }

    // Calls fn(i) for every i in [0, count), spread over the pool; items are taken in increasing
    // order. Not reentrant: call it from one thread at a time.
    void parallelFor(int count, const std::function<void(int)>& fn);
    // As parallelFor, but past the first `atLeast` items `stop` is asked as each item finishes
    // (from any of the threads, while the job runs), and by the waiting caller when the job starts
    // and at each nudge(): once it says so no more are started past the first `atLeast`, but at
    // most one a worker, claimed without asking (its first, or the one after an owed item).
    // Returns how many were done, always the first ones: items are claimed in order.
    int parallelForUntil(int count, const std::function<void(int)>& fn,
                         const std::function<bool()>& stop, int atLeast = 1);
    // Asks the running job's `stop` again from the waiting caller, now: call it when what `stop`
    // reads has changed. A background pool's workers may wait long for the CPU; the caller then
    // runs the first `atLeast` items itself if they are not yet claimed, and waits only for the
    // items already claimed. Any thread, any time; without a job it does nothing.
    void nudge();

private:
    struct Job {
        const std::function<void(int)>* fn = nullptr;
        int count = 0;
        const std::function<bool()>* stop = nullptr; // asked before item atLeast on
        int atLeast = 0;
    };
    int run(const Job& job);
    void workerLoop();
    // Claims and runs items of job `generation` below index `below` until none is left (or a
    // newer job started).
    void runItems(uint32_t generation, const Job& job, int below);
    // Counts `n` items finished; the last one wakes the caller.
    void finished(int n);
    // Claims no more items of job `generation` (its claim counter gets kClosed); the ones not
    // claimed count as finished.
    void close(uint32_t generation, int count);

    std::vector<std::thread> m_workers;
    bool m_callerWorks = true;
    std::mutex m_mutex;
    std::condition_variable m_wake;
    Job m_job;                 // guarded by m_mutex
    uint32_t m_generation = 0; // guarded by m_mutex; bumped for every job
    bool m_stop = false;
    // (generation << 32) | next unclaimed item of the current job, | kClosed once stopped.
    static constexpr uint32_t kClosed = 1u << 31;
    std::atomic<uint64_t> m_claim{0};
    // Items of the current job not yet finished; the caller returns at 0.
    std::atomic<int> m_remaining{0};
    // What the caller waits on: bumped when m_remaining reaches 0 and by nudge().
    std::atomic<uint32_t> m_signal{0};
};

} // namespace trephine

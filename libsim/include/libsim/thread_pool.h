// A small fork-join worker pool for the renderer: parallelFor hands out work items to the workers
// and the calling thread, and returns when all are done. One job at a time.
#pragma once

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <mutex>
#include <thread>
#include <vector>

namespace trephine {

class ThreadPool {
public:
    // threads counts the calling thread: 0 means std::thread::hardware_concurrency(); 1 runs
    // everything on the caller.
    explicit ThreadPool(int threads = 0);
    ~ThreadPool();
    ThreadPool(const ThreadPool&) = delete;
    ThreadPool& operator=(const ThreadPool&) = delete;

    // Threads that take part in parallelFor, the caller included.
    int size() const { return int(m_workers.size()) + 1; }

    // Calls fn(i) for every i in [0, count), spread over the pool; items are taken in increasing
    // order. Not reentrant: call it from one thread at a time.
    void parallelFor(int count, const std::function<void(int)>& fn);

private:
    void workerLoop();
    void runItems();

    std::vector<std::thread> m_workers;
    std::mutex m_mutex;
    std::condition_variable m_wake;
    std::condition_variable m_done;
    const std::function<void(int)>* m_fn = nullptr;
    int m_count = 0;
    std::atomic<int> m_next{0};
    int m_busy = 0;            // workers still inside the current job
    uint64_t m_generation = 0; // bumped for every job
    bool m_stop = false;
};

} // namespace trephine

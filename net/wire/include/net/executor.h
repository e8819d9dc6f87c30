// Where a part's background work runs: a worker thread (the outbox's coder when the server runs
// its threads; the recorder's syncer unless it is given another), or InlineExecutor, which does
// the work before post() returns (a pumped server's coder; the recorder's tests).
#pragma once

#include <condition_variable>
#include <deque>
#include <functional>
#include <mutex>
#include <string>
#include <thread>

namespace trephine::net {

class Executor {
public:
    virtual ~Executor() = default;
    // Runs `task` once, after this call or during it (never on a thread holding a caller's lock
    // the task takes: an inline executor runs it at once, on the caller's thread).
    virtual void post(std::function<void()> task) = 0;
    // Drops the tasks not yet started and waits for the running one: nothing posted so far runs
    // after this returns.
    virtual void cancel() = 0;
    // Waits until no task waits or runs (posts meanwhile extend the wait).
    virtual void drain() = 0;
};

class InlineExecutor final : public Executor {
public:
    void post(std::function<void()> task) override { task(); }
    void cancel() override {}
    void drain() override {}
};

// One named thread that runs the tasks in order, at a nice value (Linux: a thread's own) so it
// takes what the server's own threads leave of the CPU. The thread starts at the first post.
class WorkerExecutor final : public Executor {
public:
    WorkerExecutor(std::string name, int niceValue) : m_name(std::move(name)), m_nice(niceValue) {}
    ~WorkerExecutor() override;
    WorkerExecutor(const WorkerExecutor&) = delete;
    WorkerExecutor& operator=(const WorkerExecutor&) = delete;

    void post(std::function<void()> task) override;
    void cancel() override;
    void drain() override;

private:
    void run();

    std::string m_name;
    int m_nice;
    std::mutex m_mutex;
    std::condition_variable m_cv;
    std::deque<std::function<void()>> m_tasks;
    int m_running = 0;
    bool m_stop = false;
    std::thread m_thread;
};

} // namespace trephine::net

#include "net/executor.h"

#include <pthread.h>
#include <sys/resource.h>
#include <sys/syscall.h>
#include <unistd.h>

namespace trephine::net {

WorkerExecutor::~WorkerExecutor() {
    {
        std::lock_guard lock(m_mutex);
        m_stop = true;
        m_tasks.clear();
    }
    m_cv.notify_all();
    if (m_thread.joinable())
        m_thread.join();
}

void WorkerExecutor::post(std::function<void()> task) {
    {
        std::lock_guard lock(m_mutex);
        m_tasks.push_back(std::move(task));
        if (!m_thread.joinable())
            m_thread = std::thread([this] { run(); });
    }
    m_cv.notify_all();
}

void WorkerExecutor::cancel() {
    std::unique_lock lock(m_mutex);
    m_tasks.clear();
    m_cv.wait(lock, [&] { return m_running == 0; });
}

void WorkerExecutor::drain() {
    std::unique_lock lock(m_mutex);
    m_cv.wait(lock, [&] { return m_tasks.empty() && m_running == 0; });
}

void WorkerExecutor::run() {
    pthread_setname_np(pthread_self(), m_name.substr(0, 15).c_str());
    setpriority(PRIO_PROCESS, id_t(syscall(SYS_gettid)), m_nice);
    std::unique_lock lock(m_mutex);
    for (;;) {
        m_cv.wait(lock, [&] { return m_stop || !m_tasks.empty(); });
        if (m_stop)
            return;
        std::function<void()> task = std::move(m_tasks.front());
        m_tasks.pop_front();
        ++m_running;
        lock.unlock();
        task();
        task = nullptr; // what it owns is freed here, not under the lock posts take
        lock.lock();
        --m_running;
        m_cv.notify_all();
    }
}

} // namespace trephine::net

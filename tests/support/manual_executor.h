// An executor that holds what is posted to it until the test runs it (run()) or lets it go
// (tasks.clear(), which frees what the tasks own).
#pragma once

#include "net/executor.h"

#include <functional>
#include <utility>
#include <vector>

namespace trephine::testing {

struct ManualExecutor final : net::Executor {
    std::vector<std::function<void()>> tasks;
    void post(std::function<void()> task) override { tasks.push_back(std::move(task)); }
    void cancel() override { tasks.clear(); }
    void drain() override {}
    void run() {
        auto now = std::move(tasks);
        tasks.clear();
        for (auto& task : now)
            task();
    }
};

} // namespace trephine::testing

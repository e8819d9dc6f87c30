// Modes whose issue has not landed yet. Each says so in one line and exits non-zero, so scripts
// never mistake a missing mode for a successful run.
#include "modes.h"

#include <cstdio>

namespace trephine::app {

void addPendingMode(CLI::App& root, int& exitCode, const char* name, const char* description,
                    const char* issue) {
    CLI::App* sub = root.add_subcommand(name, description);
    sub->allow_extras();
    sub->callback([&exitCode, name, issue] {
        std::fprintf(stderr, "trephine %s: not built yet (%s)\n", name, issue);
        exitCode = 2;
    });
}

} // namespace trephine::app

// trephine: one binary, many modes. Parses the mode and hands over; user errors become one line
// on stderr and a non-zero exit.
#include "modes.h"

#include "libsim/error.h"

#include <cstdio>
#include <exception>
#include <new>
#include <string>
#include <vector>

namespace {

// The first word that should name a mode (or a study) and names none: "unknown mode 'X' (modes:
// ...)", or, when the words stop before one is named, which ones there are; empty when all is
// well (or help is asked for). Options are skipped: no option of the top level or of a mode with
// subcommands takes a value.
std::string unknownModeMessage(const CLI::App& app, int argc, char** argv) {
    const CLI::App* at = &app;
    auto names = [&] {
        std::string list;
        for (const CLI::App* sub : at->get_subcommands([](const CLI::App*) { return true; }))
            list += (list.empty() ? "" : ", ") + sub->get_name();
        return list;
    };
    auto which = [&] { return at == &app ? std::string("modes") : at->get_name() + " has"; };
    for (int i = 1; i < argc; ++i) {
        const std::string word = argv[i];
        if (word == "-h" || word == "--help" || word == "--version")
            return {};
        if (word.empty() || word[0] == '-')
            continue;
        const std::vector<const CLI::App*> subs =
            at->get_subcommands([](const CLI::App*) { return true; });
        if (subs.empty())
            return {};
        const CLI::App* next = nullptr;
        for (const CLI::App* sub : subs)
            if (sub->check_name(word))
                next = sub;
        if (!next)
            return "unknown " + std::string(at == &app ? "mode" : "subcommand") + " '" + word +
                   "' (" + which() + ": " + names() + ")";
        at = next;
    }
    if (at->get_subcommands([](const CLI::App*) { return true; }).empty())
        return {};
    return std::string(at == &app ? "a mode" : "a subcommand") + " is required (" + which() + ": " +
           names() + ")";
}

} // namespace

int main(int argc, char** argv) {
    CLI::App app{"Trephine: a collaborative craniotomy-drilling trainer.\n"
                 "One server holds the voxel skull; trainee and instructor clients hold a "
                 "depth-buffered image of it.",
                 "trephine"};
    app.require_subcommand(1);
    app.set_version_flag("--version", "trephine 0.1.0");
    app.footer("Run `trephine MODE --help` for a mode's options.");

    int exitCode = 0;
    using namespace trephine::app;
    addServerMode(app, exitCode);
    addTraineeMode(app, exitCode);
    addInstructorMode(app, exitCode);
    addDemoMode(app, exitCode);
    addStudyMode(app, exitCode);
    addRenderMode(app, exitCode);
    addVolumeMode(app, exitCode);
    addDevicesMode(app, exitCode);
    addReplayMode(app, exitCode);

    // Parse errors on one line, like every other error (CLI11's own form is two, unprefixed).
    app.failure_message([](const CLI::App*, const CLI::Error& e) {
        return std::string("trephine: ") + e.what() + " (trephine --help)\n";
    });
    // A misspelt mode: CLI11 would say only that a subcommand is required.
    if (std::string unknown = unknownModeMessage(app, argc, argv); !unknown.empty()) {
        std::fprintf(stderr, "trephine: %s (trephine --help)\n", unknown.c_str());
        return 2;
    }
    try {
        app.parse(argc, argv);
    } catch (const CLI::ParseError& e) {
        return app.exit(e);
    } catch (const trephine::Error& e) {
        std::fprintf(stderr, "trephine: %s\n", e.what());
        return 1;
    } catch (const std::bad_alloc&) {
        std::fprintf(stderr, "trephine: out of memory (a volume or image too large for this "
                             "machine?)\n");
        return 1;
    } catch (const std::exception& e) {
        std::fprintf(stderr, "trephine: unexpected error: %s\n", e.what());
        return 1;
    }
    return exitCode;
}

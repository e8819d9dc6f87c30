// trephine: one binary, many modes. Parses the mode and hands over; user errors become one line
// on stderr and a non-zero exit.
#include "modes.h"

#include "libsim/error.h"

#include <cstdio>
#include <exception>
#include <new>

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

    // Parse errors on one line, like every other error (CLI11's own form is two, unprefixed).
    app.failure_message([](const CLI::App*, const CLI::Error& e) {
        return std::string("trephine: ") + e.what() + " (trephine --help)\n";
    });
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

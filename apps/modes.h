// The modes of `trephine`. Each mode file adds its CLI11 subcommand to the root app and, when the
// subcommand runs, stores the process exit code in `exitCode`. A mode is a few lines of wiring.
#pragma once

#include <CLI/CLI.hpp>

namespace trephine::app {

void addServerMode(CLI::App& root, int& exitCode);
void addTraineeMode(CLI::App& root, int& exitCode);
void addInstructorMode(CLI::App& root, int& exitCode);
void addDemoMode(CLI::App& root, int& exitCode);
void addStudyMode(CLI::App& root, int& exitCode);
void addRenderMode(CLI::App& root, int& exitCode);
void addVolumeMode(CLI::App& root, int& exitCode);
void addDevicesMode(CLI::App& root, int& exitCode);

// For modes whose issue has not landed yet: says so in one line and exits non-zero.
void addPendingMode(CLI::App& root, int& exitCode, const char* name, const char* description,
                    const char* issue);

} // namespace trephine::app

// The modes of `trephine`. Each mode file adds its CLI11 subcommand to the root app and, when the
// subcommand runs, stores the process exit code in `exitCode`. A mode is a few lines of wiring.
#pragma once

#include <CLI/CLI.hpp>

#include "libsim/error.h"
#include "libsim/replacing_file.h"
#include "net/protocol.h"
#include "net/secure_channel.h"

#include <cmath>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <unistd.h>

namespace trephine::app {

// The file a --volume spec opens: the whole spec when it names a file, else the part before its
// query (`s.nrrd?spacing=2,2,2`); "" for the built-in volumes and slice folders.
inline std::string volumeFileOf(const std::string& spec) {
    std::error_code ec;
    if (std::filesystem::is_regular_file(spec, ec))
        return spec;
    const size_t mark = spec.rfind('?');
    if (mark != std::string::npos && std::filesystem::is_regular_file(spec.substr(0, mark), ec))
        return spec.substr(0, mark);
    return {};
}

// CLI::Range compares, and NaN compares false with everything, so it lets `nan` through any
// range. For floating-point options: a finite number within [lo, hi], and one that stays finite
// as a float.
inline CLI::Validator finiteRange(double lo, double hi) {
    const std::string range =
        "[" + CLI::detail::to_string(lo) + " - " + CLI::detail::to_string(hi) + "]";
    return CLI::Validator(
        [lo, hi, range](std::string& text) -> std::string {
            double v = 0.0;
            size_t used = 0;
            try {
                v = std::stod(text, &used);
            } catch (const std::exception&) {
                return "Value " + text + " is not a number";
            }
            if (used != text.size() || !std::isfinite(float(v)))
                return "Value " + text + " is not a finite number";
            if (!(v >= lo && v <= hi))
                return "Value " + text + " not in range " + range;
            return {};
        },
        "FLOAT in " + range);
}

// For options naming a file to write: an empty value (`--save-on-exit "$UNSET"`) is not "not
// given", and a folder would fail only when the run is over. Both are refused as the command
// line is read.
inline CLI::Validator outputFile() {
    return CLI::Validator(
        [](std::string& path) -> std::string {
            if (path.empty())
                return "an empty path: name the file to write";
            std::error_code ec;
            if (std::filesystem::is_directory(path, ec))
                return path + " is a folder: name a file to write (in it, e.g. " +
                       (std::filesystem::path(path) / "NAME").string() + ")";
            return {};
        },
        "FILE");
}

// For --connect: HOST:PORT (or HOST, :PORT or PORT; 127.0.0.1 and 7777 by default) with a port a
// server can listen on (not 0, not over 65535), refused as the command line is read. The host is
// resolved when connecting.
inline CLI::Validator serverAddress() {
    return CLI::Validator(
        [](std::string& text) -> std::string {
            if (text.empty())
                return "an empty address: give HOST:PORT";
            const size_t colon = text.rfind(':');
            const bool digitsOnly = text.find_first_not_of("0123456789") == std::string::npos;
            const std::string port = colon != std::string::npos ? text.substr(colon + 1)
                                     : digitsOnly               ? text
                                                                : std::string("7777");
            if (colon != std::string::npos && text.find(':') != colon)
                return "'" + text + "' is not HOST:PORT";
            if (port.empty() || port.size() > 5 ||
                port.find_first_not_of("0123456789") != std::string::npos || std::stoul(port) < 1 ||
                std::stoul(port) > 65535)
                return "'" + text + "' is not HOST:PORT (the port must be a number 1-65535)";
            return {};
        },
        "HOST:PORT");
}

// Throws unless the folder `path` is to be written in exists and we may write there: for outputs
// written at the end of a run, checked before it starts (a typo found after a session wastes it).
inline void checkOutputFolder(const std::string& flag, const std::string& path) {
    const std::filesystem::path folder = std::filesystem::path(path).has_parent_path()
                                             ? std::filesystem::path(path).parent_path()
                                             : std::filesystem::path(".");
    std::error_code ec;
    if (!std::filesystem::is_directory(folder, ec) || ::access(folder.c_str(), W_OK) != 0)
        throw Error(flag + " " + path + ": cannot write there (no folder " + folder.string() +
                    " we may write to)");
}

// Whether two paths name one file, existing or not (`a/../s.nrrd` and `./s.nrrd` do): two outputs
// of one run that would overwrite each other.
inline bool samePath(const std::string& a, const std::string& b) {
    std::error_code ec1, ec2;
    const auto ca = std::filesystem::weakly_canonical(a, ec1);
    const auto cb = std::filesystem::weakly_canonical(b, ec2);
    if (ec1 || ec2)
        return std::filesystem::path(a).lexically_normal() ==
               std::filesystem::path(b).lexically_normal();
    return ca == cb;
}

// `handler` for every way a run is ended from outside: Ctrl-C, kill, Ctrl-\ (SIGQUIT) and a closed
// terminal or dropped ssh (SIGHUP), so the run can stop and keep what it made. Under nohup a
// hang-up is ignored, and stays so: a run started with `nohup ... &` over ssh outlives the logout.
inline void handleStopSignals(void (*handler)(int)) {
    for (int sig : {SIGINT, SIGTERM, SIGQUIT})
        std::signal(sig, handler);
    if (std::signal(SIGHUP, SIG_IGN) != SIG_IGN)
        std::signal(SIGHUP, handler);
}

// For --name: the server refuses a hello whose name is longer than the protocol carries, and the
// client would hear only "the server did not understand our hello".
inline CLI::Validator participantName() {
    return CLI::Validator(
        [](std::string& name) -> std::string {
            if (name.size() > net::kMaxNameLength)
                return "a name of " + std::to_string(name.size()) + " bytes is too long (at most " +
                       std::to_string(net::kMaxNameLength) + ")";
            return {};
        },
        "NAME");
}

// A role code (docs/security.md), checked when parsed: a typo in it is one line before anything
// connects.
inline CLI::Validator roleCode() {
    return CLI::Validator(
        [](std::string& c) -> std::string {
            try {
                net::normaliseCode(c);
            } catch (const Error& e) {
                return e.what();
            }
            return {};
        },
        "CODE");
}

// --code CODE for a client of `role`.
inline void addCodeOption(CLI::App* sub, std::string& code, const std::string& role) {
    sub->add_option("--code", code,
                    "The " + role + " code the server printed (leave out for an --open server)")
        ->check(roleCode());
}

void addServerMode(CLI::App& root, int& exitCode);
void addTraineeMode(CLI::App& root, int& exitCode);
void addInstructorMode(CLI::App& root, int& exitCode);
void addDemoMode(CLI::App& root, int& exitCode);
void addStudyMode(CLI::App& root, int& exitCode);
void addRenderMode(CLI::App& root, int& exitCode);
void addVolumeMode(CLI::App& root, int& exitCode);
void addDevicesMode(CLI::App& root, int& exitCode);
void addReplayMode(CLI::App& root, int& exitCode);

// For modes whose issue has not landed yet: says so in one line and exits non-zero.
void addPendingMode(CLI::App& root, int& exitCode, const char* name, const char* description,
                    const char* issue);

} // namespace trephine::app

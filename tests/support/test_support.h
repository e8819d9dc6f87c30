// Helpers shared by the test suites: a self-deleting temporary folder, whole-file reads, and
// running the built `trephine` binary (TREPHINE_BIN) as a user would.
#pragma once

#include "libsim/volume.h"

#include <atomic>
#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <optional>
#include <string>
#include <sys/wait.h>
#include <unistd.h>
#include <utility>

namespace trephine::testing {

// The bone voxels of `v` (bone material, density above zero): what drilling removes.
inline int64_t boneVoxels(const Volume& v) {
    int64_t n = 0;
    for (int z = 0; z < v.dims().z; ++z)
        for (int y = 0; y < v.dims().y; ++y)
            for (int x = 0; x < v.dims().x; ++x)
                n += isBone(v.material(x, y, z)) && v.density(x, y, z) > 0;
    return n;
}

// A fresh folder under the system temp dir, removed with everything in it on destruction.
struct TempDir {
    std::filesystem::path path;
    TempDir() {
        static std::atomic<int> counter{0};
        auto stamp = std::chrono::steady_clock::now().time_since_epoch().count();
        path = std::filesystem::temp_directory_path() /
               ("trephine_test_" + std::to_string(getpid()) + "_" + std::to_string(counter++) +
                "_" + std::to_string(stamp));
        std::filesystem::create_directories(path);
    }
    ~TempDir() {
        std::error_code ec;
        std::filesystem::remove_all(path, ec);
    }
    TempDir(const TempDir&) = delete;
    TempDir& operator=(const TempDir&) = delete;
    std::string operator/(const std::string& name) const { return (path / name).string(); }
};

// Sets (or, with no value, unsets) the environment variable `name` while it lives, then puts
// back what was there: TMPDIR pointed at a test's own folder, DISPLAY taken away.
class ScopedEnv {
public:
    ScopedEnv(std::string name, const std::optional<std::string>& value) : m_name(std::move(name)) {
        if (const char* old = std::getenv(m_name.c_str()))
            m_old = old;
        set(value);
    }
    ~ScopedEnv() { set(m_old); }
    ScopedEnv(const ScopedEnv&) = delete;
    ScopedEnv& operator=(const ScopedEnv&) = delete;

private:
    void set(const std::optional<std::string>& value) {
        if (value)
            ::setenv(m_name.c_str(), value->c_str(), 1);
        else
            ::unsetenv(m_name.c_str());
    }
    std::string m_name;
    std::optional<std::string> m_old;
};

inline std::string slurp(const std::string& path) {
    std::ifstream f(path, std::ios::binary);
    return std::string(std::istreambuf_iterator<char>(f), {});
}

// `s` as one shell word: single-quoted, a quote inside as '\''.
inline std::string shellQuote(const std::string& s) {
    std::string q = "'";
    for (char c : s)
        q += c == '\'' ? std::string("'\\''") : std::string(1, c);
    return q + "'";
}

struct CommandResult {
    int exitCode = -1;
    std::string out;
    std::string err;
};

#ifdef TREPHINE_BIN
// Runs `trephine ARGS` (ARGS already shell-quoted), capturing stdout and stderr in `dir`.
inline CommandResult runTrephine(const TempDir& dir, const std::string& args) {
    const std::string out = dir / "stdout.txt", err = dir / "stderr.txt";
    std::string cmd =
        shellQuote(TREPHINE_BIN) + " " + args + " >" + shellQuote(out) + " 2>" + shellQuote(err);
    int status = std::system(cmd.c_str());
    CommandResult r;
    r.exitCode = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    r.out = slurp(out);
    r.err = slurp(err);
    return r;
}
#endif

} // namespace trephine::testing

// An output file written through a temporary file beside it and renamed over it only once
// complete: reports, study CSVs, marks files. A failed run leaves an earlier file whole.
#pragma once

#include <cerrno>
#include <csignal>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <optional>
#include <string>
#include <unistd.h>

namespace trephine {

// Where a replacing write of `path` goes: the file a symbolic link names (the link stays), or
// `path`; nothing when `path` exists and is no regular file (a device: written in place).
inline std::optional<std::filesystem::path> replacementTarget(const std::string& path) {
    namespace fs = std::filesystem;
    std::error_code ec;
    fs::path target = path;
    if (fs::is_symlink(target, ec)) {
        const fs::path resolved = fs::weakly_canonical(target, ec);
        if (!ec)
            target = resolved;
    }
    if (fs::exists(target, ec) && !fs::is_regular_file(target, ec))
        return std::nullopt;
    return target;
}

// Temporary files a killed run left beside `target` (NAME.trephine-PID.tmp, and replaceVia's
// STEM.trephine-PID.tmp.EXT) whose process is gone: removed, so that Ctrl-C'd writes do not pile
// up (a signal ends a run before the writer's destructor can). A live process's are left alone.
inline void removeAbandonedTemps(const std::filesystem::path& target) {
    namespace fs = std::filesystem;
    std::error_code ec;
    const fs::path folder = target.has_parent_path() ? target.parent_path() : fs::path(".");
    const std::string prefixes[] = {target.filename().string() + ".trephine-",
                                    target.stem().string() + ".trephine-"};
    fs::directory_iterator it(folder, ec);
    for (; !ec && it != fs::directory_iterator(); it.increment(ec)) {
        const std::string name = it->path().filename().string();
        for (const std::string& prefix : prefixes) {
            if (name.rfind(prefix, 0) != 0)
                continue;
            const std::string rest = name.substr(prefix.size());
            const size_t digits = rest.find_first_not_of("0123456789");
            if (digits == 0 || digits == std::string::npos || rest.compare(digits, 4, ".tmp") != 0)
                continue;
            const long pid = std::strtol(rest.substr(0, digits).c_str(), nullptr, 10);
            if (pid > 0 && pid != ::getpid() && ::kill(pid_t(pid), 0) != 0 && errno == ESRCH) {
                std::error_code ignored;
                fs::remove(it->path(), ignored);
            }
            break;
        }
    }
}

// An output file written through a temporary file beside it, renamed over it only by commit():
// a run that fails before (a full disk, an error, Ctrl-C) leaves an earlier file of that name
// whole. A symbolic link is followed (the link stays);
// a path that is no regular file (a device such as /dev/full) is written directly.
class ReplacingFile {
public:
    explicit ReplacingFile(const std::string& path) : m_path(path) {
        const auto target = replacementTarget(path);
        if (!target) {
            m_stream.open(path, std::ios::binary);
            return;
        }
        m_target = target->string();
        removeAbandonedTemps(*target);
        m_temp = m_target + ".trephine-" + std::to_string(::getpid()) + ".tmp";
        m_stream.open(m_temp, std::ios::binary);
    }
    ~ReplacingFile() {
        if (!m_temp.empty() && !m_committed) {
            m_stream.close();
            std::error_code ec;
            std::filesystem::remove(m_temp, ec);
        }
    }
    ReplacingFile(const ReplacingFile&) = delete;
    ReplacingFile& operator=(const ReplacingFile&) = delete;

    std::ofstream& stream() { return m_stream; }
    bool good() const { return bool(m_stream); }
    // Flushes, closes and puts the file in place; false (the earlier file untouched) on failure.
    bool commit() {
        m_stream.close();
        if (!m_stream)
            return false;
        if (m_temp.empty())
            return true;
        if (std::rename(m_temp.c_str(), m_target.c_str()) != 0)
            return false;
        m_committed = true;
        return true;
    }

private:
    std::string m_path, m_target, m_temp;
    std::ofstream m_stream;
    bool m_committed = false;
};

// `text` into `path` through a ReplacingFile; false when it could not be written.
inline bool writeReplacing(const std::string& path, const std::string& text) {
    ReplacingFile f(path);
    f.stream() << text;
    return f.commit();
}

// The same for writers that take a file name (OpenImageIO picks the format by its extension):
// `write` is called with a temporary name beside `path` that keeps its extension
// (NAME.trephine-PID.tmp.EXT), and the result is renamed over `path` once `write` returns; if it
// throws, the temporary file is removed and the exception goes on. A symbolic link is followed; a
// path that is no regular file (a device) is handed to `write` as it is. Throws trephine::Error
// (through `fail`, one line naming `path`) when the rename fails.
inline void replaceVia(const std::string& path,
                       const std::function<void(const std::string&)>& write,
                       const std::function<void(const std::string&)>& fail) {
    namespace fs = std::filesystem;
    const auto resolved = replacementTarget(path);
    if (!resolved) {
        write(path);
        return;
    }
    const fs::path target = *resolved;
    removeAbandonedTemps(target);
    std::error_code ec;
    fs::path temp = target;
    temp.replace_filename(target.stem().string() + ".trephine-" + std::to_string(::getpid()) +
                          ".tmp" + target.extension().string());
    try {
        write(temp.string());
    } catch (...) {
        fs::remove(temp, ec);
        throw;
    }
    fs::rename(temp, target, ec);
    if (ec) {
        std::error_code ignored;
        fs::remove(temp, ignored);
        fail(ec.message());
    }
}

} // namespace trephine

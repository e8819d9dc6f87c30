// The one check that a file given to be read (a volume, a session log) is a plain file: a
// folder fails late, a device may never end, and a FIFO blocks on opening with no message.
#pragma once

#include "libsim/error.h"

#include <filesystem>
#include <string>

namespace trephine {

// Throws Error ("NAME: is a folder, not a file", or "NAME: is not a regular file (a device, pipe
// or socket): WHY") when `path` is there and is no regular file. A path that is not there passes:
// opening it says so. `why` says what the file should be, e.g. "volumes are read from files".
inline void requireRegularFile(const std::string& path, const std::string& name,
                               const std::string& why) {
    namespace fs = std::filesystem;
    std::error_code ec;
    const fs::file_status st = fs::status(path, ec);
    if (fs::is_directory(st))
        throw Error(name + ": is a folder, not a file");
    if (fs::exists(st) && !fs::is_regular_file(st))
        throw Error(name + ": is not a regular file (a device, pipe or socket): " + why);
}

} // namespace trephine

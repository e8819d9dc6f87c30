#include "output.h"

#include "libsim/error.h"
#include "libsim/replacing_file.h"

#include <cerrno>
#include <cstring>
#include <fcntl.h>
#include <unistd.h>

namespace trephine::study {

std::string makeOutDir(const std::string& out) {
    if (out.empty())
        throw Error("--out: an empty path (give the folder to write into)");
    std::error_code ec;
    std::filesystem::create_directories(out, ec);
    if (ec || !std::filesystem::is_directory(out))
        throw Error("cannot create --out folder " + out + ": " +
                    (ec ? ec.message() : std::string("a file is there")));
    // A file made and removed: the folder's permissions do not tell for root, or for /sys.
    const std::string probe =
        (std::filesystem::path(out) / (".trephine-probe-" + std::to_string(::getpid()))).string();
    const int fd = ::open(probe.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0600);
    if (fd < 0)
        throw Error("--out " + out + ": cannot write into it (" + std::strerror(errno) + ")");
    ::close(fd);
    ::unlink(probe.c_str());
    return out;
}

void writeText(const std::filesystem::path& path, const std::string& text) {
    if (!writeReplacing(path.string(), text))
        throw Error("cannot write " + path.string() + ": check that --out is a writable folder");
}

net::LinkConditions studyLink(const std::string& text) {
    const net::LinkConditions c = net::LinkConditions::parse(text);
    if (!(c.lossPercent < 100.0))
        throw Error("--link " + text + ": a loss of 100 % lets no update through; give under 100");
    return c;
}

} // namespace trephine::study

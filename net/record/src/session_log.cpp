#include "net/session_log.h"

#include "libsim/error.h"
#include "libsim/regular_file.h"
#include "libsim/replacing_file.h"
#include "net/scene.h"

#include <fmt/format.h>
#include <zlib.h>
#include <zstd.h>

#include <atomic>
#include <cassert>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <fcntl.h>
#include <filesystem>
#include <fstream>
#include <sys/stat.h>
#include <unistd.h>

namespace trephine::net {

namespace {

uint32_t crcOf(const uint8_t* data, size_t n, uint32_t crc = 0) {
    // zlib's crc32 takes a uInt length: long buffers go in pieces.
    while (n > 0) {
        const uInt piece = uInt(std::min<size_t>(n, size_t(1) << 30));
        crc = uint32_t(crc32(crc, data, piece));
        data += piece;
        n -= piece;
    }
    return crc;
}

void putU32(std::vector<uint8_t>& out, size_t at, uint32_t v) {
    for (int i = 0; i < 4; ++i)
        out[at + i] = uint8_t(v >> (8 * i));
}

uint32_t getU32(const uint8_t* p) {
    return uint32_t(p[0]) | uint32_t(p[1]) << 8 | uint32_t(p[2]) << 16 | uint32_t(p[3]) << 24;
}

// Appends one frame: length, CRC-32 of the length's bytes and the payload, then the payload (a
// record starts with its kind). False when a field is out of range.
template <typename T>
bool appendFrame(std::vector<uint8_t>& out, T& value, uint32_t version = kLogVersion) {
    const size_t at = out.size();
    out.resize(at + kLogFrameBytes);
    WriteStream w(out);
    if (!value.serialize(w, version) || out.size() - at - kLogFrameBytes > kMaxLogRecordBytes) {
        out.resize(at);
        return false;
    }
    const uint32_t length = uint32_t(out.size() - at - kLogFrameBytes);
    putU32(out, at, length);
    putU32(out, at + 4, crcOf(out.data() + at + kLogFrameBytes, length, crcOf(out.data() + at, 4)));
    return true;
}

std::string errnoText() {
    return std::strerror(errno);
}

} // namespace

// [SECTION] the starting volume

LogHeader logHeaderOf(const Volume& volume, const std::string& volumeSpec, bool embed,
                      uint64_t startUnixUs) {
    LogHeader h;
    h.startUnixUs = startUnixUs;
    h.volumeSpec = volumeSpec;
    h.dims = volume.dims();
    h.spacing = volume.spacing();
    h.densityCrc = crcOf(volume.densityData(), volume.voxelCount());
    h.materialCrc = crcOf(volume.materialData(), volume.voxelCount());
    if (embed) {
        std::vector<uint8_t> raw(volume.voxelCount() * 2);
        std::memcpy(raw.data(), volume.densityData(), volume.voxelCount());
        std::memcpy(raw.data() + volume.voxelCount(), volume.materialData(), volume.voxelCount());
        h.embedded.resize(ZSTD_compressBound(raw.size()));
        const size_t n =
            ZSTD_compress(h.embedded.data(), h.embedded.size(), raw.data(), raw.size(), 3);
        if (ZSTD_isError(n))
            throw Error(std::string("session log: cannot compress the volume: ") +
                        ZSTD_getErrorName(n));
        h.embedded.resize(n);
        if (h.embedded.size() > kMaxLogRecordBytes / 2)
            throw Error("session log: the volume does not fit a log record even compressed");
    }
    return h;
}

Volume logStartVolume(const LogHeader& h, const std::function<Volume(const std::string&)>& open) {
    const size_t count = size_t(h.dims.x) * size_t(h.dims.y) * size_t(h.dims.z);
    Volume v;
    if (!h.embedded.empty()) {
        std::vector<uint8_t> raw(count * 2);
        const size_t n =
            ZSTD_decompress(raw.data(), raw.size(), h.embedded.data(), h.embedded.size());
        if (ZSTD_isError(n) || n != raw.size())
            throw Error("session log: the embedded volume does not decompress to " +
                        std::to_string(raw.size()) + " bytes");
        std::vector<uint8_t> density(raw.begin(), raw.begin() + ptrdiff_t(count));
        std::vector<uint8_t> material(raw.begin() + ptrdiff_t(count), raw.end());
        for (uint8_t m : material)
            if (m >= uint8_t(kMaterialCount))
                throw Error("session log: the embedded volume has an unknown material label");
        v = Volume(h.dims, h.spacing, std::move(density), std::move(material));
    } else {
        v = open(h.volumeSpec);
    }
    if (v.dims() != h.dims || v.spacing() != h.spacing ||
        crcOf(v.densityData(), v.voxelCount()) != h.densityCrc ||
        crcOf(v.materialData(), v.voxelCount()) != h.materialCrc)
        throw Error("session log: the volume '" + h.volumeSpec +
                    "' is not the one recorded (its size or content hash differs; was it made by "
                    "another version, or the file changed?)");
    return v;
}

// [SECTION] writing

SessionRecorder::SessionRecorder(std::string path, int fd, uint64_t bytes, int syncIntervalMs,
                                 uint32_t version, std::unique_ptr<Executor> syncer)
    : m_path(std::move(path)), m_fd(fd),
      m_syncIntervalUs(uint64_t(std::max(1, syncIntervalMs)) * 1000), m_version(version),
      m_bytes(bytes), m_synced(bytes), m_writtenBack(bytes & ~uint64_t(4095)),
      m_syncer(syncer ? std::move(syncer) : std::make_unique<WorkerExecutor>("trephine-sync", 0)) {}

std::unique_ptr<SessionRecorder> SessionRecorder::create(const std::string& path, LogHeader header,
                                                         int syncIntervalMs,
                                                         std::unique_ptr<Executor> syncer) {
    std::vector<uint8_t> start(kLogMagic, kLogMagic + 8);
    start.resize(kLogPreambleBytes);
    putU32(start, 8, kLogVersion);
    if (!appendFrame(start, header))
        throw Error("--record " + path + ": the session's start does not fit the log's format");
    requireRegularFile(path, "--record " + path, "session logs are kept in files");
    const int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_APPEND | O_CLOEXEC, 0644);
    if (fd < 0)
        throw Error("--record " + path + ": " +
                    (errno == EEXIST ? std::string("a file is there already (--resume continues a "
                                                   "log; give a new name to start one)")
                                     : "cannot create it: " + errnoText()));
    std::unique_ptr<SessionRecorder> r(
        new SessionRecorder(path, fd, 0, syncIntervalMs, kLogVersion, std::move(syncer)));
    if (!r->writeAll(start.data(), start.size()) || ::fdatasync(fd) != 0)
        throw Error("--record " + path + ": cannot write it: " + errnoText());
    r->m_bytes = r->m_synced = start.size();
    return r;
}

std::unique_ptr<SessionRecorder> SessionRecorder::append(const std::string& path,
                                                         uint64_t intactBytes, uint32_t version,
                                                         int syncIntervalMs,
                                                         std::unique_ptr<Executor> syncer) {
    if (version == 0 || version > kLogVersion)
        throw Error(fmt::format("--resume {}: cannot append to a log of format {}", path, version));
    const int fd = ::open(path.c_str(), O_WRONLY | O_APPEND | O_CLOEXEC);
    if (fd < 0)
        throw Error("--resume " + path + ": cannot open it to append: " + errnoText());
    // Appending after damage would bury it mid-file; cutting it off would lose what was there.
    struct stat st {};
    if (::fstat(fd, &st) != 0 || uint64_t(st.st_size) != intactBytes) {
        ::close(fd);
        throw Error(fmt::format("--resume {}: it is {} bytes, not the {} intact ones read (damaged "
                                "past them, or written since)",
                                path, uint64_t(st.st_size), intactBytes));
    }
    return std::unique_ptr<SessionRecorder>(
        new SessionRecorder(path, fd, intactBytes, syncIntervalMs, version, std::move(syncer)));
}

SessionRecorder::~SessionRecorder() {
    m_syncer->cancel(); // nothing posted touches the file once it closes
    if (m_fd >= 0) {
        ::fdatasync(m_fd);
        ::close(m_fd);
    }
}

bool SessionRecorder::writeAll(const uint8_t* data, size_t n) {
    while (n > 0) {
        const ssize_t done = ::write(m_fd, data, n);
        if (done < 0 && errno == EINTR)
            continue;
        if (done <= 0)
            return false;
        data += done;
        n -= size_t(done);
    }
    return true;
}

bool SessionRecorder::write(std::span<const LogRecord> records) {
    if (records.empty())
        return true;
    std::lock_guard lock(m_mutex);
    if (!m_error.empty())
        return false;
    m_buffer.clear();
    for (const LogRecord& r : records) {
        LogRecord copy = r; // serialize is one function for write and read: not const
        if (!appendFrame(m_buffer, copy, m_version) && m_error.empty())
            m_error = fmt::format("a record of kind {} does not fit the format", int(r.kind()));
    }
    // A record that did not fit is a programmer mistake; the others still go.
    if (!writeAll(m_buffer.data(), m_buffer.size())) {
        m_error = "cannot write: " + errnoText();
        std::fprintf(stderr, "trephine server: --record %s: %s; the session goes on unrecorded\n",
                     m_path.c_str(), m_error.c_str());
        return false;
    }
    m_bytes += m_buffer.size();
    m_records += records.size();
    return true;
}

void SessionRecorder::sync() {
    uint64_t written;
    {
        std::lock_guard lock(m_mutex);
        written = m_bytes;
    }
    if (::fdatasync(m_fd) == 0) {
        std::lock_guard lock(m_mutex);
        m_synced = std::max(m_synced, written);
        ++m_syncs;
    }
}

// Full pages only: the page appends go to is left alone, so no append waits for its writeback.
void SessionRecorder::writeBack(uint64_t written) {
    const uint64_t end = written & ~uint64_t(4095);
    if (end <= m_writtenBack)
        return;
    if (::sync_file_range(m_fd, off_t(m_writtenBack), off_t(end - m_writtenBack),
                          SYNC_FILE_RANGE_WAIT_BEFORE | SYNC_FILE_RANGE_WRITE |
                              SYNC_FILE_RANGE_WAIT_AFTER) == 0) {
        m_writtenBack = end;
        std::lock_guard lock(m_mutex);
        ++m_writebacks;
    }
}

void SessionRecorder::tick(uint64_t nowUs) {
    if (m_nextSyncUs == 0) {
        m_nextSyncUs = nowUs + m_syncIntervalUs;
        m_nextWritebackUs = nowUs + uint64_t(kWritebackIntervalMs) * 1000;
        return;
    }
    if (nowUs < m_nextWritebackUs && nowUs < m_nextSyncUs)
        return;
    uint64_t written;
    {
        std::lock_guard lock(m_mutex);
        if (m_bytes == m_synced)
            return;
        written = m_bytes;
    }
    // One task at a time: a disk slower than the cadence gets the next one when it is done.
    if (m_posted.exchange(true))
        return;
    const bool syncNow = nowUs >= m_nextSyncUs;
    if (syncNow)
        m_nextSyncUs = nowUs + m_syncIntervalUs;
    m_nextWritebackUs = nowUs + uint64_t(kWritebackIntervalMs) * 1000;
    m_syncer->post([this, syncNow, written] {
        if (syncNow)
            sync();
        else
            writeBack(written);
        m_posted.store(false);
    });
}

std::string SessionRecorder::error() const {
    std::lock_guard lock(m_mutex);
    return m_error;
}

uint64_t SessionRecorder::bytes() const {
    std::lock_guard lock(m_mutex);
    return m_bytes;
}

uint64_t SessionRecorder::records() const {
    std::lock_guard lock(m_mutex);
    return m_records;
}

uint64_t SessionRecorder::syncs() const {
    std::lock_guard lock(m_mutex);
    return m_syncs;
}

uint64_t SessionRecorder::writebacks() const {
    std::lock_guard lock(m_mutex);
    return m_writebacks;
}

// [SECTION] reading

namespace {

// The frame at `at`: its payload, or why there is none (torn, or a length out of range). The CRC
// is checked by the caller.
std::string frameAt(std::span<const uint8_t> bytes, size_t at, std::span<const uint8_t>& payload) {
    if (bytes.size() - at < kLogFrameBytes)
        return fmt::format("torn: {} bytes of a record's {}-byte frame", bytes.size() - at,
                           kLogFrameBytes);
    const uint32_t length = getU32(bytes.data() + at);
    if (length > kMaxLogRecordBytes)
        return fmt::format("corrupt: a record length of {} bytes", length);
    if (bytes.size() - at - kLogFrameBytes < length)
        return fmt::format("torn: the record says {} bytes, {} are there", length,
                           bytes.size() - at - kLogFrameBytes);
    payload = bytes.subspan(at + kLogFrameBytes, length);
    return {};
}

bool crcMatches(std::span<const uint8_t> bytes, size_t at, std::span<const uint8_t> payload) {
    return crcOf(payload.data(), payload.size(), crcOf(bytes.data() + at, 4)) ==
           getU32(bytes.data() + at + 4);
}

// The record framed at `at` ("" when intact: `rec` holds it, `next` is past it), or why not. Its
// fields are read before its CRC is computed: while scanning past damage, almost every offset's
// "payload" fails to read within a few bytes, where a CRC would cost its whole claimed length.
std::string recordAt(std::span<const uint8_t> bytes, size_t at, uint32_t version, LogRecord& rec,
                     size_t& next) {
    std::span<const uint8_t> payload;
    std::string why = frameAt(bytes, at, payload);
    if (!why.empty())
        return why;
    ReadStream r(payload);
    if (!rec.serialize(r, version) || !r.atEnd())
        return "corrupt: its fields do not read";
    if (!crcMatches(bytes, at, payload))
        return "corrupt: its checksum does not match";
    next = at + kLogFrameBytes + payload.size();
    return {};
}

// How many records the damaged stretch [at, end) holds, as their length fields chain through it
// to exactly `end`; 0 when they do not (a damaged length, or zeros: no record is that short).
size_t framesChained(std::span<const uint8_t> bytes, size_t at, size_t end) {
    constexpr uint64_t kShortestRecord = 9; // its kind and time
    size_t count = 0;
    while (end - at >= kLogFrameBytes) {
        const uint64_t length = getU32(bytes.data() + at);
        if (length < kShortestRecord || length > end - at - kLogFrameBytes)
            return 0;
        at += kLogFrameBytes + size_t(length);
        ++count;
    }
    return at == end ? count : 0;
}

// One line for each damaged stretch of `c`.
std::string damageText(const LogContents& c, const std::string& name) {
    std::string text;
    for (size_t i = 0; i < c.damage.size(); ++i) {
        const LogDamage& d = c.damage[i];
        if (!text.empty())
            text += '\n';
        if (d.tail) {
            text += fmt::format("{}: kept {} records ({} bytes); dropped the tail at byte {} "
                                "({} bytes), {}",
                                name, c.records.size(), c.intactBytes, d.offset, d.bytes, d.why);
            continue;
        }
        const std::string which = d.records == 0   ? std::string("one or more records")
                                  : d.records == 1 ? std::string("1 record")
                                                   : fmt::format("{} records", d.records);
        const size_t after =
            (i + 1 < c.damage.size() ? c.damage[i + 1].recordsBefore : c.records.size()) -
            d.recordsBefore;
        text += fmt::format("{}: skipped {} damaged bytes at byte {} ({}, {}); kept {} record{} "
                            "after it",
                            name, d.bytes, d.offset, which, d.why, after, after == 1 ? "" : "s");
    }
    return text;
}

} // namespace

LogContents parseSessionLog(std::span<const uint8_t> bytes, const std::string& name) {
    LogContents c;
    c.fileBytes = bytes.size();
    if (bytes.size() < kLogPreambleBytes || std::memcmp(bytes.data(), kLogMagic, 8) != 0)
        throw Error(name + ": not a Trephine session log (it does not start with TREPHLOG)");
    c.version = getU32(bytes.data() + 8);
    if (c.version == 0 || c.version > kLogVersion)
        throw Error(fmt::format("{}: a session log of format {}; this Trephine reads format {}",
                                name, c.version, kLogVersion));
    size_t at = kLogPreambleBytes;
    std::span<const uint8_t> payload;
    std::string why = frameAt(bytes, at, payload);
    if (why.empty() && !crcMatches(bytes, at, payload))
        why = "corrupt: its checksum does not match";
    if (why.empty()) {
        ReadStream r(payload);
        if (!c.header.serialize(r, c.version) || !r.atEnd())
            why = "corrupt: its fields do not read";
    }
    if (!why.empty())
        throw Error(name + ": the session's start (at byte 12) cannot be read: " + why);
    at += kLogFrameBytes + payload.size();
    c.intactBytes = at;
    while (at < bytes.size()) {
        LogRecord rec;
        size_t next = 0;
        why = recordAt(bytes, at, c.version, rec, next);
        if (why.empty()) {
            c.records.push_back(std::move(rec));
            c.intactBytes += next - at;
            at = next;
            continue;
        }
        // Resynchronise: the next offset where an intact record starts, or the end.
        size_t resume = at + 1;
        for (; resume < bytes.size(); ++resume) {
            LogRecord probe;
            if (recordAt(bytes, resume, c.version, probe, next).empty())
                break;
        }
        const bool tail = resume == bytes.size();
        // A length past the end is a torn write only at the end; with records after it, the
        // length itself is damaged.
        if (!tail && why.starts_with("torn: "))
            why = "corrupt: " + why.substr(6);
        c.damage.push_back({at, resume - at, c.records.size(),
                            tail ? 0 : framesChained(bytes, at, resume), why, tail});
        at = resume;
    }
    c.stopped = damageText(c, name);
    return c;
}

LogContents readSessionLog(const std::string& path) {
    requireRegularFile(path, path, "session logs are read from files");
    std::ifstream in(path, std::ios::binary | std::ios::ate);
    if (!in)
        throw Error(path + ": cannot open the session log");
    std::vector<uint8_t> bytes(size_t(std::max<std::streamoff>(0, in.tellg())));
    in.seekg(0);
    if (!in.read(reinterpret_cast<char*>(bytes.data()), std::streamsize(bytes.size())))
        throw Error(path + ": cannot read the session log");
    return parseSessionLog(bytes, path);
}

// [SECTION] repairing

namespace {

// `bytes` into a new file at `path` (refused when something is there), synced. False: errno says.
bool writeNewFile(const std::string& path, std::span<const uint8_t> bytes) {
    const int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0644);
    if (fd < 0)
        return false;
    const uint8_t* p = bytes.data();
    size_t left = bytes.size();
    while (left > 0) {
        const ssize_t done = ::write(fd, p, left);
        if (done < 0 && errno == EINTR)
            continue;
        if (done <= 0) {
            const int saved = errno;
            ::close(fd);
            ::unlink(path.c_str());
            errno = done == 0 ? EIO : saved;
            return false;
        }
        p += done;
        left -= size_t(done);
    }
    if (::fdatasync(fd) != 0) {
        const int saved = errno;
        ::close(fd);
        ::unlink(path.c_str());
        errno = saved;
        return false;
    }
    return ::close(fd) == 0;
}

} // namespace

namespace {

// Makes the names in `file`'s folder (a new file, a rename) durable.
void syncFolderOf(const std::string& file) {
    const std::filesystem::path folder = std::filesystem::path(file).parent_path();
    const int dir = ::open(folder.empty() ? "." : folder.c_str(), O_RDONLY | O_DIRECTORY);
    if (dir >= 0) {
        ::fsync(dir);
        ::close(dir);
    }
}

} // namespace

std::string repairSessionLog(const std::string& path, const LogContents& log) {
    if (log.damage.empty())
        return {};
    // A symbolic link stays one: what it names is repaired.
    const std::string target = replacementTarget(path).value_or(path).string();
    std::vector<uint8_t> bytes;
    {
        std::ifstream in(target, std::ios::binary);
        bytes.assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
        if (!in.eof() && in.fail())
            throw Error("--resume " + path + ": cannot read it again to repair it");
    }
    if (bytes.size() != log.fileBytes)
        throw Error(fmt::format("--resume {}: it changed while being read ({} bytes, then {})",
                                path, log.fileBytes, bytes.size()));
    // First the whole file, byte for byte, under a name nothing else has.
    std::string aside;
    for (int n = 1;; ++n) {
        aside = target + ".damaged-" + std::to_string(n);
        if (writeNewFile(aside, bytes))
            break;
        if (errno != EEXIST || n == 1000)
            throw Error("--resume " + path + ": cannot keep the damaged log aside as " + aside +
                        ": " + errnoText());
    }
    syncFolderOf(target); // the copy's name, durable before the log's name moves
    // Then its intact frames, put in its place by a rename: at every moment the log's name holds
    // the damaged file or the repaired one, and the damaged one is kept.
    std::vector<uint8_t> intact;
    intact.reserve(size_t(log.intactBytes));
    size_t from = 0;
    for (const LogDamage& d : log.damage) {
        intact.insert(intact.end(), bytes.begin() + ptrdiff_t(from),
                      bytes.begin() + ptrdiff_t(d.offset));
        from = size_t(d.offset + d.bytes);
    }
    intact.insert(intact.end(), bytes.begin() + ptrdiff_t(from), bytes.end());
    assert(intact.size() == log.intactBytes && "repairSessionLog: `log` is not this file's");
    const std::string temp = target + ".trephine-" + std::to_string(::getpid()) + ".tmp";
    ::unlink(temp.c_str()); // a killed run's of this pid
    if (!writeNewFile(temp, intact) || std::rename(temp.c_str(), target.c_str()) != 0) {
        const std::string why = errnoText();
        ::unlink(temp.c_str());
        throw Error("--resume " + path +
                    ": cannot write its intact records (the damaged log is "
                    "kept whole as " +
                    aside + "): " + why);
    }
    syncFolderOf(target); // the rename, durable before anything is appended
    return aside;
}

} // namespace trephine::net

// The session log (net/session_log.h) and its replay (net/session_replay.h): records round-trip;
// a log cut at every byte of its last records, or with a byte flipped, keeps what is intact and
// says where and why it stopped; a recorded session (two trainees, an instructor's marks and
// take-over, a design switch) replays to the server's own --save-on-exit byte for byte, and so
// does one resumed from its log; trajectories export what the simulation applied; the
// participants' assessment metrics recomputed from the log equal the live report's.
#include "net/replay_feed.h"
#include "net/session_log.h"
#include "net/session_replay.h"

#include "net/executor.h"

#include "net/session_client.h"
#include "net/session_server.h"
#include "net/view.h"

#include "libsim/error.h"
#include "libsim/skull.h"
#include "libsim/volume_io.h"

#include "loopback.h"
#include "test_support.h"

#include <fmt/format.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <zlib.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <unistd.h>
#include <vector>

using namespace trephine;
using namespace trephine::net;

using trephine::testing::burrState;
using trephine::testing::loopback;
using trephine::testing::loopbackServerConfig;
using trephine::testing::namedClientConfig;
using trephine::testing::pollAll;
using trephine::testing::Pumped;
using trephine::testing::pumpUntil;
using trephine::testing::TempDir;

namespace {

constexpr int kN = 48;

// In one folder for the whole run, removed at its end with the marks and scene files beside
// each saved volume.
std::string tempPath(const std::string& name) {
    static const TempDir dir;
    const std::string p = dir / name;
    std::filesystem::remove(p);
    return p;
}

std::vector<uint8_t> fileBytes(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

// One record of every kind, with fields that differ from the defaults.
std::vector<LogRecord> everyKind() {
    std::vector<LogRecord> list;
    auto add = [&](Event e) -> Event& {
        const uint16_t n = uint16_t(list.size() + 1);
        LogRecord& r = list.emplace_back(LogRecord{1000 + n * 17u, std::move(e)});
        std::visit(
            [&](auto& v) {
                if constexpr (requires { v.client; })
                    v.client = n;
            },
            r.event);
        return r.event;
    };
    add(HelloEvent{0, Role::Trainee, "Ada"});
    JoinEvent join{.codec = Codec::Zstd, .sync = Sync::Volume, .volumeCodec = Codec::Lz4};
    join.view.eye = {1, 2, 300};
    join.view.width = 77;
    add(join);
    ViewEvent view{0, {}, 9};
    view.view.fovYDeg = 33.0f;
    add(view);
    ToolEvent tool;
    tool.tool.sequence = 42;
    tool.tool.clientTimeUs = 123456789;
    tool.tool.position = {1.5f, -2.25f, 30.0f};
    tool.tool.speed = 0.75f;
    tool.tool.drilling = true;
    add(tool);
    add(LeaveEvent{});
    add(CutEvent{Box3i::fromMinMax({1, 2, 3}, {4, 5, 6})});
    add(SyncEvent{0, Sync::Volume, Codec::Zstd});
    add(VoxelsEvent{Box3i::fromMinMax({0, 0, 0}, {2, 1, 1}), {200, 0}, {1, 0}});
    add(MarkEvent{Annotate::Op::Add, {3, 2, {1, 2, 3}, "here"}});
    add(MarkEvent{Annotate::Op::Clear, {}});
    add(HoldEvent{0, 1});
    add(ReleaseEvent{});
    add(ResumeEvent{1700000000000000ull});
    return list;
}

LogHeader sphereHeader(const Volume& v) {
    ServerConfig c = loopbackServerConfig("sphere:48");
    c.marks = {{0, 0, {0, 0, 24}, "start"}};
    return makeLogHeader(v, c, "sphere:48", false, 1);
}

// A log of `records` on the 48^3 sphere; its bytes, and where each record starts.
std::vector<uint8_t> writeLog(const std::string& path, const std::vector<LogRecord>& records,
                              std::vector<size_t>& starts) {
    const Volume sphere = makeSphere(kN);
    {
        auto recorder = SessionRecorder::create(path, sphereHeader(sphere));
        for (const LogRecord& r : records) {
            starts.push_back(recorder->bytes());
            EXPECT_TRUE(recorder->write({&r, 1}));
        }
    }
    return fileBytes(path);
}

void expectSame(const LogRecord& a, const LogRecord& b) {
    LogRecord x = a, y = b;
    std::vector<uint8_t> ea, eb;
    WriteStream wa(ea), wb(eb);
    ASSERT_TRUE(x.serialize(wa));
    ASSERT_TRUE(y.serialize(wb));
    EXPECT_EQ(ea, eb) << "kind " << int(a.kind());
}

} // namespace

// [SECTION] the format

TEST(SessionLog, EveryKindOfRecordRoundTrips) {
    const std::string path = tempPath("kinds.log");
    const std::vector<LogRecord> records = everyKind();
    std::vector<size_t> starts;
    writeLog(path, records, starts);
    const LogContents log = readSessionLog(path);
    EXPECT_EQ(log.version, kLogVersion);
    EXPECT_TRUE(log.stopped.empty()) << log.stopped;
    EXPECT_EQ(log.intactBytes, log.fileBytes);
    ASSERT_EQ(log.records.size(), records.size());
    for (size_t i = 0; i < records.size(); ++i)
        expectSame(log.records[i], records[i]);
    EXPECT_EQ(log.records[3].as<ToolEvent>()->tool.position,
              records[3].as<ToolEvent>()->tool.position);
    EXPECT_EQ(log.header.volumeSpec, "sphere:48");
    ASSERT_EQ(log.header.marks.size(), 1u);
    EXPECT_EQ(log.header.marks[0].label, "start");
    EXPECT_TRUE(log.header.embedded.empty()) << "a built-in volume travels as its spec and hash";
    const Volume v = logStartVolume(log.header, loadVolume);
    EXPECT_EQ(v.dims(), glm::ivec3(kN));
    std::filesystem::remove(path);
}

// The bytes each kind of record had before the events were types of their own (formats 2 and 1:
// a v1 Tool has no force). A log written by any earlier Trephine reads the same.
TEST(SessionLog, EveryKindOfRecordKeepsTheBytesItHadInBothFormats) {
    std::vector<LogRecord> list;
    auto add = [&](Event e) {
        const uint16_t n = uint16_t(list.size() + 1);
        LogRecord& r = list.emplace_back(LogRecord{1000 + n * 17u, std::move(e)});
        std::visit(
            [&](auto& v) {
                if constexpr (requires { v.client; })
                    v.client = n;
            },
            r.event);
    };
    add(HelloEvent{0, Role::Trainee, "Ada"});
    JoinEvent join{.codec = Codec::Zstd, .sync = Sync::Volume, .volumeCodec = Codec::Lz4};
    join.view.eye = {1, 2, 300};
    join.view.width = 77;
    join.name = "not logged"; // the hello's
    add(join);
    ViewEvent view{0, {}, 9};
    view.view.fovYDeg = 33.0f;
    add(view);
    ToolEvent tool{0, {}, 2.5f};
    tool.tool.sequence = 42;
    tool.tool.clientTimeUs = 123456789;
    tool.tool.position = {1.5f, -2.25f, 30.0f};
    tool.tool.speed = 0.75f;
    tool.tool.drilling = true;
    add(tool);
    add(LeaveEvent{});
    add(CutEvent{Box3i::fromMinMax({1, 2, 3}, {4, 5, 6})});
    add(SyncEvent{0, Sync::Volume, Codec::Zstd});
    add(VoxelsEvent{Box3i::fromMinMax({0, 0, 0}, {2, 1, 1}), {200, 0}, {1, 0}});
    add(MarkEvent{Annotate::Op::Add, {3, 2, {1, 2, 3}, "here"}});
    MarkEvent removed{Annotate::Op::Remove, {}};
    removed.mark.id = 3;
    add(removed);
    add(MarkEvent{Annotate::Op::Clear, {}});
    add(HelloEvent{0, Role::Instructor, "Ben"});
    add(HoldEvent{0, 1});
    add(ReleaseEvent{});
    add(ResumeEvent{1700000000000000ull});
    const std::vector<std::string> v2 = {
        "08f9030000000000000100000300416461",
        "010a0400000000000002000000803f0000004000009643000000000000000000000000000000000000803f0000"
        "0000000070420000204100007a444d00f401020101",
        "021b040000000000000300000000000000000000009643000000000000000000000000000000000000803f0000"
        "0000000004420000204100007a44f401f40109000000",
        "032c0400000000000004002a00000015cd5b070000000000000080400000c03f000010c00000f0410000803f00"
        "00000000000000000000000000403f0100002040",
        "043d040000000000000500",
        "054e04000000000000010000000200000003000000040000000500000006000000",
        "065f0400000000000007000102",
        "07700400000000000000000000000000000000000002000000010000000100000002000000c80002000000010"
        "0",
        "098104000000000000000300000002000000803f0000004000004040040068657265",
        "099204000000000000010300000000000000000000000000000000000000",
        "09a30400000000000002",
        "08b4040000000000000c0001030042656e",
        "0ac5040000000000000d000100",
        "0bd6040000000000000e00",
        "0ce70400000000000000401e18240a0600",
    };
    ASSERT_EQ(list.size(), v2.size());
    auto hex = [](std::vector<uint8_t> bytes) {
        std::string h;
        for (uint8_t b : bytes)
            h += fmt::format("{:02x}", b);
        return h;
    };
    for (size_t i = 0; i < list.size(); ++i) {
        for (uint32_t version : {2u, 1u}) {
            LogRecord r = list[i];
            std::vector<uint8_t> bytes;
            WriteStream w(bytes);
            ASSERT_TRUE(r.serialize(w, version));
            std::string expected = v2[i];
            if (version == 1 && r.is<ToolEvent>())
                expected.resize(expected.size() - 8); // no force
            EXPECT_EQ(hex(bytes), expected) << "record " << i << ", format " << version;
            LogRecord back;
            ReadStream in(bytes);
            ASSERT_TRUE(back.serialize(in, version));
            EXPECT_TRUE(in.atEnd());
            EXPECT_EQ(back.kind(), r.kind());
            EXPECT_EQ(back.timeUs, r.timeUs);
        }
    }
    // A kind past the last one, or none, reads as nothing.
    for (uint8_t kind : {uint8_t(0), uint8_t(13)}) {
        std::vector<uint8_t> bytes(11, 0);
        bytes[0] = kind;
        ReadStream in(bytes);
        LogRecord r;
        EXPECT_FALSE(r.serialize(in)) << int(kind);
    }
}

TEST(SessionLog, AVolumeNoSpecRegeneratesTravelsInTheLogAndAWrongOneIsRefused) {
    Volume v = makeSphere(kN);
    v.fill(Box3i::fromMinMax({20, 20, 20}, {28, 28, 28}), 0, Material::Air);
    ServerConfig c = loopbackServerConfig("cut.nrrd");
    const LogHeader embedded = makeLogHeader(v, c, "cut.nrrd", true, 0);
    ASSERT_FALSE(embedded.embedded.empty());
    auto never = [](const std::string&) -> Volume {
        ADD_FAILURE() << "an embedded volume is not opened from its spec";
        return {};
    };
    const Volume back = logStartVolume(embedded, never);
    EXPECT_TRUE(
        std::equal(back.densityData(), back.densityData() + back.voxelCount(), v.densityData()));
    // The spec regenerates another volume than the one recorded: said, not replayed wrongly.
    const LogHeader bySpec = makeLogHeader(v, c, "sphere:48", false, 0);
    EXPECT_THROW(logStartVolume(bySpec, loadVolume), Error);
}

TEST(SessionLog, ALogCutAtEveryByteOfItsLastRecordsKeepsWhatIsIntact) {
    const std::string path = tempPath("cut.log");
    std::vector<size_t> starts;
    const std::vector<LogRecord> records = everyKind();
    const std::vector<uint8_t> bytes = writeLog(path, records, starts);
    starts.push_back(bytes.size());
    // Every byte offset from the start of the fourth-last record to the end.
    const size_t from = starts[records.size() - 4];
    for (size_t cut = from; cut <= bytes.size(); ++cut) {
        const LogContents log =
            parseSessionLog(std::span(bytes.data(), cut), "cut at " + std::to_string(cut));
        size_t whole = 0;
        while (whole < records.size() && starts[whole + 1] <= cut)
            ++whole;
        ASSERT_EQ(log.records.size(), whole) << "cut at " << cut;
        EXPECT_EQ(log.intactBytes, starts[whole]) << "cut at " << cut;
        if (cut == starts[whole]) {
            EXPECT_TRUE(log.stopped.empty()) << log.stopped;
        } else {
            EXPECT_NE(log.stopped.find("torn"), std::string::npos) << log.stopped;
            EXPECT_NE(log.stopped.find("at byte " + std::to_string(starts[whole])),
                      std::string::npos)
                << log.stopped;
            EXPECT_EQ(log.stopped.find('\n'), std::string::npos) << "one line";
        }
    }
    std::filesystem::remove(path);
}

TEST(SessionLog, AFlippedByteSkipsTheRecordItCorruptsAndKeepsEveryLaterOne) {
    const std::string path = tempPath("flip.log");
    std::vector<size_t> starts;
    const std::vector<LogRecord> records = everyKind();
    std::vector<uint8_t> bytes = writeLog(path, records, starts);
    starts.push_back(bytes.size());
    for (size_t at = starts[0]; at < bytes.size(); ++at) {
        bytes[at] ^= 0x20;
        const LogContents log = parseSessionLog(bytes, "flipped");
        size_t hit = 0;
        while (starts[hit + 1] <= at)
            ++hit;
        SCOPED_TRACE("byte " + std::to_string(at) + " flipped, in record " + std::to_string(hit));
        // Exactly the record hit is gone; every other one is there, in order.
        ASSERT_EQ(log.records.size(), records.size() - 1) << log.stopped;
        for (size_t i = 0, j = 0; i < records.size(); ++i)
            if (i != hit)
                expectSame(log.records[j++], records[i]);
        ASSERT_EQ(log.damage.size(), 1u);
        const LogDamage& d = log.damage[0];
        EXPECT_EQ(d.offset, starts[hit]);
        EXPECT_EQ(d.bytes, starts[hit + 1] - starts[hit]);
        EXPECT_EQ(d.recordsBefore, hit);
        EXPECT_EQ(d.tail, hit + 1 == records.size());
        EXPECT_EQ(log.intactBytes, bytes.size() - d.bytes);
        EXPECT_EQ(log.stopped.find('\n'), std::string::npos) << "one line";
        EXPECT_NE(log.stopped.find("at byte " + std::to_string(starts[hit])), std::string::npos)
            << log.stopped;
        // In the last record a flipped length looks like a torn write: either is said.
        EXPECT_TRUE(log.stopped.find("corrupt") != std::string::npos ||
                    (d.tail && log.stopped.find("torn") != std::string::npos))
            << log.stopped;
        if (!d.tail) {
            // A flipped length breaks the chain of lengths: how many records it was is unknown.
            const bool inLength = at < starts[hit] + 4;
            EXPECT_EQ(d.records, inLength ? 0u : 1u);
            EXPECT_NE(log.stopped.find("skipped " + std::to_string(d.bytes) +
                                       " damaged bytes at byte " + std::to_string(d.offset) +
                                       (inLength ? " (one or more records, " : " (1 record, ")),
                      std::string::npos)
                << log.stopped;
            const size_t after = records.size() - hit - 1;
            EXPECT_NE(log.stopped.find("; kept " + std::to_string(after) +
                                       (after == 1 ? " record" : " records") + " after it"),
                      std::string::npos)
                << log.stopped;
        }
        bytes[at] ^= 0x20;
    }
    EXPECT_TRUE(parseSessionLog(bytes, "restored").stopped.empty());
    std::filesystem::remove(path);
}

TEST(SessionLog, EachDamagedStretchIsSkippedAndSaidInItsOwnLine) {
    const std::string path = tempPath("two-flips.log");
    std::vector<size_t> starts;
    const std::vector<LogRecord> records = everyKind();
    std::vector<uint8_t> bytes = writeLog(path, records, starts);
    starts.push_back(bytes.size());
    // Records 3 and 4 (one stretch, two records whose lengths still chain), and record 9.
    bytes[starts[2] + 9] ^= 0x01; // a time's byte: the fields read, the CRC does not match
    bytes[starts[3] + 10] ^= 0x80;
    bytes[starts[8] + 11] ^= 0x04;
    const LogContents log = parseSessionLog(bytes, "x.log");
    ASSERT_EQ(log.records.size(), records.size() - 3) << log.stopped;
    ASSERT_EQ(log.damage.size(), 2u);
    EXPECT_EQ(log.damage[0].records, 2u);
    EXPECT_EQ(log.damage[0].bytes, starts[4] - starts[2]);
    EXPECT_EQ(log.damage[1].recordsBefore, 6u);
    EXPECT_EQ(log.damage[1].records, 1u);
    expectSame(log.records[2], records[4]);
    expectSame(log.records.back(), records.back());
    auto n = [](size_t v) { return std::to_string(v); };
    EXPECT_EQ(log.stopped, "x.log: skipped " + n(starts[4] - starts[2]) +
                               " damaged bytes at byte " + n(starts[2]) +
                               " (2 records, corrupt: its checksum does not match); kept 4 "
                               "records after it\nx.log: skipped " +
                               n(starts[9] - starts[8]) + " damaged bytes at byte " + n(starts[8]) +
                               " (1 record, corrupt: its checksum does not match); kept " +
                               n(records.size() - 9) + " records after it");
    std::filesystem::remove(path);
}

TEST(SessionLog, AFileThatIsNoLogOrWhoseStartIsDamagedIsRefusedInOneLine) {
    const std::string path = tempPath("head.log");
    std::vector<size_t> starts;
    std::vector<uint8_t> bytes = writeLog(path, everyKind(), starts);
    auto refusal = [](std::span<const uint8_t> b) {
        try {
            parseSessionLog(b, "x.log");
        } catch (const Error& e) {
            return std::string(e.what());
        }
        return std::string("accepted");
    };
    std::vector<uint8_t> other = bytes;
    other[0] = 'X';
    EXPECT_NE(refusal(other).find("not a Trephine session log"), std::string::npos);
    other = bytes;
    other[8] = 99;
    EXPECT_NE(refusal(other).find("format 99"), std::string::npos) << refusal(other);
    other = bytes;
    other[kLogPreambleBytes + kLogFrameBytes + 3] ^= 1;
    EXPECT_NE(refusal(other).find("session's start"), std::string::npos) << refusal(other);
    EXPECT_NE(refusal(std::span(bytes.data(), 20)).find("torn"), std::string::npos);
    // A log is never overwritten by a new one.
    EXPECT_THROW(SessionRecorder::create(path, sphereHeader(makeSphere(kN))), Error);
    std::filesystem::remove(path);
}

TEST(SessionLog, ResumingATornLogKeepsItAsideWholeAndAppendsAfterItsIntactRecords) {
    const std::string path = tempPath("append.log");
    std::vector<size_t> starts;
    std::vector<LogRecord> records = everyKind();
    std::vector<uint8_t> bytes = writeLog(path, records, starts);
    std::filesystem::resize_file(path, bytes.size() - 3); // killed mid-write
    bytes.resize(bytes.size() - 3);
    LogContents log = readSessionLog(path);
    ASSERT_EQ(log.records.size(), records.size() - 1);
    // Nothing cuts a damaged file: appending is refused until it is repaired.
    EXPECT_THROW(SessionRecorder::append(path, log.intactBytes), Error);
    EXPECT_EQ(fileBytes(path), bytes);
    // Something is already there under the first name: never overwritten.
    const std::string taken = path + ".damaged-1";
    std::ofstream(taken) << "someone else's\n";
    const std::string aside = repairSessionLog(path, log);
    EXPECT_EQ(aside, path + ".damaged-2");
    EXPECT_EQ(fileBytes(taken), std::vector<uint8_t>({'s', 'o', 'm', 'e', 'o', 'n', 'e', ' ', 'e',
                                                      'l', 's', 'e', '\'', 's', '\n'}));
    EXPECT_EQ(fileBytes(aside), bytes) << "the torn log, byte for byte";
    EXPECT_EQ(std::filesystem::file_size(path), log.intactBytes);
    EXPECT_EQ(repairSessionLog(path, readSessionLog(path)), "") << "a whole log is left alone";
    {
        auto recorder = SessionRecorder::append(path, log.intactBytes);
        ASSERT_TRUE(recorder->write({&records[0], 1}));
        recorder->sync();
        EXPECT_GE(recorder->syncs(), 1u);
    }
    log = readSessionLog(path);
    EXPECT_TRUE(log.stopped.empty()) << log.stopped;
    ASSERT_EQ(log.records.size(), records.size());
    expectSame(log.records.back(), records[0]);
    for (const std::string& p : {path, taken, aside})
        std::filesystem::remove(p);
}

// [SECTION] the recorder's syncs

namespace {

// Holds what is posted until the test runs it: a sync still under way. The tasks outlive it.
struct HeldExecutor final : Executor {
    using Tasks = std::vector<std::function<void()>>;
    std::shared_ptr<Tasks> tasks = std::make_shared<Tasks>();
    void post(std::function<void()> task) override { tasks->push_back(std::move(task)); }
    void cancel() override { tasks->clear(); }
    void drain() override {
        for (auto& t : std::exchange(*tasks, {}))
            t();
    }
};

// Enough voxels that the record fills whole pages (a writeback covers full pages only).
LogRecord pageOfVoxels(uint64_t timeUs) {
    const Box3i box = Box3i::fromMinMax({0, 0, 0}, {32, 32, 8});
    const size_t n = size_t(box.count());
    return {timeUs, VoxelsEvent{box, std::vector<uint8_t>(n, 7), std::vector<uint8_t>(n, 1)}};
}

} // namespace

TEST(SessionRecorder, TickWritesBackEvery100MsAndSyncsEverySecondWhenSomethingWasWritten) {
    const std::string path = tempPath("tick.log");
    auto recorder = SessionRecorder::create(path, sphereHeader(makeSphere(kN)),
                                            SessionRecorder::kDefaultSyncIntervalMs,
                                            std::make_unique<InlineExecutor>());
    const uint64_t t0 = 5'000'000;
    recorder->tick(t0); // the cadence starts
    const LogRecord voxels = pageOfVoxels(1);
    ASSERT_TRUE(recorder->write({&voxels, 1}));
    recorder->tick(t0 + 99'999);
    EXPECT_EQ(recorder->writebacks(), 0u);
    EXPECT_EQ(recorder->syncs(), 0u);
    recorder->tick(t0 + 100'000);
    EXPECT_EQ(recorder->writebacks(), 1u) << "the full pages, without a journal commit";
    EXPECT_EQ(recorder->syncs(), 0u);
    recorder->tick(t0 + 150'000);
    EXPECT_EQ(recorder->writebacks(), 1u) << "not due again yet";
    recorder->tick(t0 + 1'000'000);
    EXPECT_EQ(recorder->syncs(), 1u) << "a second after the start";
    recorder->tick(t0 + 1'500'000);
    recorder->tick(t0 + 2'000'000);
    EXPECT_EQ(recorder->syncs(), 1u) << "nothing written since";
    EXPECT_EQ(recorder->writebacks(), 1u);
    ASSERT_TRUE(recorder->write({&voxels, 1}));
    recorder->tick(t0 + 2'000'001);
    EXPECT_EQ(recorder->syncs(), 2u) << "the sync was due: the next tick after a write does it";
    recorder.reset();
    const LogContents log = readSessionLog(path);
    EXPECT_EQ(log.records.size(), 2u);
    std::filesystem::remove(path);
}

TEST(SessionRecorder, ASyncStillUnderWayIsNotPostedAgainAndCancelledOnesNeverRun) {
    const std::string path = tempPath("held.log");
    auto held = std::make_unique<HeldExecutor>();
    HeldExecutor& executor = *held;
    const std::shared_ptr<HeldExecutor::Tasks> tasks = held->tasks;
    auto recorder =
        SessionRecorder::create(path, sphereHeader(makeSphere(kN)), 1000, std::move(held));
    recorder->tick(0);
    const LogRecord voxels = pageOfVoxels(1);
    ASSERT_TRUE(recorder->write({&voxels, 1}));
    recorder->tick(1'000'000);
    ASSERT_EQ(tasks->size(), 1u);
    recorder->tick(2'000'000);
    recorder->tick(3'000'000);
    EXPECT_EQ(tasks->size(), 1u) << "the disk is slow: the one posted is enough";
    executor.drain();
    EXPECT_EQ(recorder->syncs(), 1u);
    ASSERT_TRUE(recorder->write({&voxels, 1}));
    recorder->tick(4'000'000);
    EXPECT_EQ(tasks->size(), 1u);
    recorder.reset(); // cancels the one waiting: nothing runs on a closed file
    EXPECT_TRUE(tasks->empty());
    std::filesystem::remove(path);
}

// [SECTION] a recorded session

namespace {

// Two trainees and an instructor on a 48^3 sphere, recorded, the server pumped by the test's
// thread; strokes are waited for until the server has applied them.
struct RecordedSession {
    Volume sphere = makeSphere(kN);
    std::string log, saved;
    SessionServer server;
    Pumped pumped{server};
    SessionClient ada{namedClientConfig(sphere, "Ada", Role::Trainee, 32)};
    SessionClient ben{namedClientConfig(sphere, "Ben", Role::Trainee, 40)};
    SessionClient cho{namedClientConfig(sphere, "Dr. Cho", Role::Instructor, 32)};
    std::vector<SessionClient*> all{&ada, &ben, &cho};
    uint64_t applied = 0;
    std::map<const SessionClient*, uint32_t> sequence;

    static ServerConfig config(const Volume& v, const std::string& log, const std::string& saved,
                               ServerConfig c) {
        c.saveOnExit = saved;
        if (!c.recorder)
            c.recorder = SessionRecorder::create(log, makeLogHeader(v, c, "sphere:48", false, 1));
        return c;
    }
    RecordedSession(const std::string& name, ServerConfig c = loopbackServerConfig("sphere:48"),
                    Volume start = {})
        : log(tempPath(name + ".log")), saved(tempPath(name + ".nrrd")),
          server(start.empty() ? sphere : start,
                 config(start.empty() ? sphere : start, log, saved, std::move(c))) {}

    bool joined() {
        for (SessionClient* c : all)
            c->connect(loopback(server.port()));
        return pumpUntil(all, [&] {
            return ada.hasFullImage() && ben.hasFullImage() && cho.hasFullImage() &&
                   ada.participants().size() == 3 && ben.participants().size() == 3 &&
                   cho.participants().size() == 3;
        });
    }
    void stroke(SessionClient& who, float degrees, int states = 10) {
        const float a = glm::radians(degrees);
        const glm::vec3 normal(std::sin(a), 0.0f, std::cos(a));
        const SurfaceSite site{normal * sphereRadiusMm(kN), normal};
        for (int i = 0; i < states; ++i) {
            ToolState t = burrState(site, i, states, 1000000 + applied * 10000);
            t.sequence = ++sequence[&who];
            who.sendToolState(t);
            pollAll(all);
        }
        applied += uint64_t(states);
        EXPECT_TRUE(pumpUntil(all, [&] { return server.toolStatesApplied() >= applied; }));
    }
};

Volume replayed(const std::string& path) {
    const LogContents log = readSessionLog(path);
    EXPECT_TRUE(log.stopped.empty()) << log.stopped;
    SessionReplay replay(log.header, logStartVolume(log.header, loadVolume));
    replay.applyAll(log.records);
    return replay.volume();
}

} // namespace

TEST(SessionLog, TwoTraineesMarksAndATakeOverReplayToTheSavedVolumeByteForByte) {
    RecordedSession s("two");
    ASSERT_TRUE(s.joined());
    const uint16_t ada = s.ada.welcome().clientId;
    s.stroke(s.ada, 0);
    s.stroke(s.ben, 40);
    Annotate mark;
    mark.position = {0, 0, 24};
    mark.label = "entry";
    s.cho.annotate(mark);
    mark.label = "second";
    s.cho.annotate(mark);
    ASSERT_TRUE(pumpUntil(s.all, [&] { return s.ada.annotations().size() == 2; }));
    Annotate remove;
    remove.op = Annotate::Op::Remove;
    remove.id = s.ada.annotations()[1].id;
    s.cho.annotate(remove);
    s.cho.takeOver(ada);
    ASSERT_TRUE(pumpUntil(s.all, [&] {
        return s.ada.annotations().size() == 1 &&
               s.ada.participants().at(ada).takenOverBy == s.cho.welcome().clientId;
    }));
    s.stroke(s.ada, -30); // paused: cuts nothing
    s.stroke(s.cho, -30);
    s.cho.takeOver(0);
    ASSERT_TRUE(pumpUntil(s.all, [&] { return s.ada.participants().at(ada).takenOverBy == 0; }));
    s.ben.requestSync(Sync::Volume); // a design switch mid-session
    ASSERT_TRUE(pumpUntil(s.all, [&] { return s.ben.sync() == Sync::Volume; }));
    s.stroke(s.ben, 60);
    s.stroke(s.ada, -60);
    s.server.stop();
    ASSERT_EQ(s.server.savedTo(), s.saved) << s.server.saveError();

    const LogContents log = readSessionLog(s.log);
    ASSERT_TRUE(log.stopped.empty()) << log.stopped;
    SessionReplay replay(log.header, logStartVolume(log.header, loadVolume));
    replay.applyAll(log.records);
    EXPECT_EQ(replay.toolStatesApplied(), s.server.toolStatesApplied());
    ASSERT_EQ(replay.marks().size(), 1u);
    EXPECT_EQ(replay.marks().begin()->second.label, "entry");
    // Everyone left as the server stopped; the log said who they were.
    size_t hellos = 0, holds = 0, releases = 0, syncs = 0;
    for (const LogRecord& r : log.records) {
        hellos += r.is<HelloEvent>();
        holds += r.is<HoldEvent>();
        releases += r.is<ReleaseEvent>();
        syncs += r.is<SyncEvent>();
    }
    EXPECT_EQ(hellos, 3u);
    EXPECT_EQ(holds, 1u);
    EXPECT_EQ(releases, 1u);
    EXPECT_EQ(syncs, 1u);
    const std::string again = tempPath("two-replayed.nrrd");
    saveVolume(replay.volume(), again);
    const std::vector<uint8_t> original = fileBytes(s.saved), replayedBytes = fileBytes(again);
    ASSERT_FALSE(original.empty());
    EXPECT_TRUE(original == replayedBytes) << "the replayed volume's file differs from the save";
    const Volume start = makeSphere(kN);
    EXPECT_FALSE(std::equal(start.densityData(), start.densityData() + start.voxelCount(),
                            replay.volume().densityData()))
        << "the session drilled something";

    // Each participant's path, as the simulation applied it.
    const std::vector<Trajectory> paths = trajectoriesOf(log.records);
    ASSERT_EQ(paths.size(), 3u);
    std::map<std::string, Trajectory> byName;
    for (const Trajectory& t : paths)
        byName[t.name] = t;
    ASSERT_EQ(byName.size(), 3u);
    EXPECT_EQ(byName["Ada"].states.size(), 30u);
    EXPECT_EQ(byName["Ben"].states.size(), 20u);
    EXPECT_EQ(byName["Dr. Cho"].role, Role::Instructor);
    EXPECT_EQ(byName["Dr. Cho"].states.size(), 10u);
    const std::string csv = trajectoryCsv(byName["Ada"]);
    EXPECT_EQ(csv.rfind("time_s,x,y,z,qw,qx,qy,qz,speed,tool\n# Ada (trainee", 0), 0u) << csv;
    EXPECT_NE(csv.find(" tool states\n0.000000,"), std::string::npos);
    EXPECT_EQ(std::count(csv.begin(), csv.end(), '\n'), 32);
    EXPECT_NE(csv.find(",0,burr:5\n"), std::string::npos) << "paused states cut nothing";
    EXPECT_EQ(trajectoryFileName(byName["Dr. Cho"]),
              fmt::format("0{}-Dr__Cho-instructor.csv", byName["Dr. Cho"].ordinal));
    for (const std::string& p : {s.log, s.saved, again})
        std::filesystem::remove(p);
}

TEST(SessionLog, AResumedSessionKeepsAppendingAndReplaysToItsSave) {
    std::string logPath;
    {
        RecordedSession first("resume-a");
        logPath = first.log;
        ASSERT_TRUE(first.joined());
        Annotate mark;
        mark.position = {0, 0, 24};
        mark.label = "kept";
        first.cho.annotate(mark);
        ASSERT_TRUE(pumpUntil(first.all, [&] { return first.ada.annotations().size() == 1; }));
        first.stroke(first.ada, 10);
        first.stroke(first.ben, -20);
        first.server.stop();
    }
    ServerConfig c = loopbackServerConfig("ignored");
    const Resumed resumed = resumeSession(logPath, c, loadVolume, 2);
    EXPECT_TRUE(resumed.stopped.empty());
    EXPECT_EQ(resumed.toolStates, 20u);
    ASSERT_EQ(c.marks.size(), 1u);
    EXPECT_EQ(c.marks[0].label, "kept");
    EXPECT_EQ(c.volumeName, "sphere:48");
    ASSERT_TRUE(c.recorder);
    RecordedSession second("resume-b", c, resumed.volume);
    ASSERT_TRUE(second.joined());
    EXPECT_EQ(second.ada.annotations().size(), 1u) << "the marks came back";
    second.stroke(second.ada, 30);
    second.stroke(second.cho, 50); // holds nobody: cuts nothing
    second.server.stop();
    ASSERT_EQ(second.server.savedTo(), second.saved);
    c.recorder.reset();

    const std::string again = tempPath("resume-replayed.nrrd");
    saveVolume(replayed(logPath), again);
    EXPECT_TRUE(fileBytes(second.saved) == fileBytes(again))
        << "the whole log, across the resume, replays to the resumed server's save";
    std::filesystem::remove(logPath);
    std::filesystem::remove(second.log);
    std::filesystem::remove(second.saved);
    std::filesystem::remove(again);
}

namespace {

// Where each record of the log `bytes` starts, by walking the frames' lengths (the header first).
std::vector<size_t> recordStarts(const std::vector<uint8_t>& bytes) {
    std::vector<size_t> starts;
    size_t at = kLogPreambleBytes;
    for (bool header = true; at + kLogFrameBytes <= bytes.size(); header = false) {
        if (!header)
            starts.push_back(at);
        const uint32_t length = uint32_t(bytes[at]) | uint32_t(bytes[at + 1]) << 8 |
                                uint32_t(bytes[at + 2]) << 16 | uint32_t(bytes[at + 3]) << 24;
        at += kLogFrameBytes + length;
    }
    return starts;
}

void writeFile(const std::string& path, const std::vector<uint8_t>& bytes) {
    std::ofstream(path, std::ios::binary | std::ios::trunc)
        .write(reinterpret_cast<const char*>(bytes.data()), std::streamsize(bytes.size()));
}

} // namespace

TEST(SessionLog, ResumingALogDamagedMidwayKeepsItAsideWholeAndGoesOnFromEveryIntactRecord) {
    std::string logPath;
    {
        RecordedSession first("mid-a");
        logPath = first.log;
        ASSERT_TRUE(first.joined());
        first.stroke(first.ada, 10);
        first.stroke(first.ben, -20);
        first.server.stop();
    }
    const LogContents clean = readSessionLog(logPath);
    ASSERT_TRUE(clean.stopped.empty()) << clean.stopped;
    // A byte flipped in the payload of a tool state in the middle of Ben's stroke.
    std::vector<uint8_t> bytes = fileBytes(logPath);
    const std::vector<size_t> starts = recordStarts(bytes);
    ASSERT_EQ(starts.size(), clean.records.size());
    size_t hit = 0, tools = 0;
    for (size_t i = 0; i < clean.records.size() && tools < 15; ++i)
        if (clean.records[i].is<ToolEvent>() && ++tools == 15)
            hit = i;
    ASSERT_GT(hit, 0u);
    bytes[starts[hit] + 20] ^= 0x10;
    writeFile(logPath, bytes);
    std::vector<LogRecord> intact = clean.records;
    intact.erase(intact.begin() + ptrdiff_t(hit));

    ServerConfig c = loopbackServerConfig("ignored");
    const Resumed resumed = resumeSession(logPath, c, loadVolume, 2);
    EXPECT_NE(resumed.stopped.find("skipped " + std::to_string(starts[hit + 1] - starts[hit]) +
                                   " damaged bytes at byte " + std::to_string(starts[hit]) +
                                   " (1 record, corrupt"),
              std::string::npos)
        << resumed.stopped;
    EXPECT_NE(
        resumed.stopped.find("kept " + std::to_string(intact.size() - hit) + " records after it"),
        std::string::npos)
        << resumed.stopped;
    EXPECT_EQ(resumed.records, intact.size());
    EXPECT_EQ(resumed.keptAside, logPath + ".damaged-1");
    EXPECT_TRUE(fileBytes(resumed.keptAside) == bytes) << "the damaged log, byte for byte";
    // The resumed server starts from every intact record: the volume a replay of them gives.
    SessionReplay expected(clean.header, logStartVolume(clean.header, loadVolume));
    expected.applyAll(intact);
    EXPECT_TRUE(std::equal(expected.volume().densityData(),
                           expected.volume().densityData() + expected.volume().voxelCount(),
                           resumed.volume.densityData()));

    RecordedSession second("mid-b", c, resumed.volume);
    ASSERT_TRUE(second.joined());
    second.stroke(second.ada, 30);
    second.server.stop();
    ASSERT_EQ(second.server.savedTo(), second.saved);
    c.recorder.reset();
    // The log now reads whole: the intact records, the Resume and what came after it.
    const LogContents after = readSessionLog(logPath);
    EXPECT_TRUE(after.stopped.empty()) << after.stopped;
    ASSERT_GT(after.records.size(), intact.size());
    for (size_t i = 0; i < intact.size(); ++i)
        expectSame(after.records[i], intact[i]);
    EXPECT_TRUE(after.records[intact.size()].is<ResumeEvent>());
    const std::string again = tempPath("mid-replayed.nrrd");
    saveVolume(replayed(logPath), again);
    EXPECT_TRUE(fileBytes(second.saved) == fileBytes(again))
        << "the repaired log, across the resume, replays to the resumed server's save";
    for (const std::string& p : {logPath, resumed.keptAside, second.log, second.saved, again})
        std::filesystem::remove(p);
}

TEST(SessionLog, ASessionReplaysWithAnyOneOfItsRecordsLost) {
    // What a skipped record leaves behind (a tool state of someone whose join was lost, a hold of
    // a trainee never greeted, a leave of no one) replays without failing.
    RecordedSession s("lose-one");
    ASSERT_TRUE(s.joined());
    const uint16_t ada = s.ada.welcome().clientId;
    s.stroke(s.ada, 0, 4);
    Annotate mark;
    mark.position = {0, 0, 24};
    mark.label = "entry";
    s.cho.annotate(mark);
    s.cho.takeOver(ada);
    ASSERT_TRUE(pumpUntil(s.all, [&] {
        return s.ada.annotations().size() == 1 &&
               s.ada.participants().at(ada).takenOverBy == s.cho.welcome().clientId;
    }));
    s.stroke(s.cho, -30, 4);
    s.cho.takeOver(0);
    s.ben.requestSync(Sync::Volume);
    ASSERT_TRUE(pumpUntil(s.all, [&] { return s.ben.sync() == Sync::Volume; }));
    s.stroke(s.ben, 60, 4);
    s.server.stop();
    const LogContents log = readSessionLog(s.log);
    ASSERT_TRUE(log.stopped.empty()) << log.stopped;
    const Volume start = logStartVolume(log.header, loadVolume);
    for (size_t lost = 0; lost < log.records.size(); ++lost) {
        std::vector<LogRecord> rest = log.records;
        rest.erase(rest.begin() + ptrdiff_t(lost));
        SessionReplay replay(log.header, start);
        replay.applyAll(rest);
        EXPECT_LE(replay.toolStatesApplied(), s.server.toolStatesApplied()) << "lost " << lost;
        EXPECT_NO_THROW(replayReportText(replay, log, s.log)) << "lost " << lost;
    }
    for (const std::string& p : {s.log, s.saved})
        std::filesystem::remove(p);
}

// [SECTION] the assessment, replayed

namespace {

// The 48^3 sphere with dura from 3 mm under its surface inwards: a critical structure that the
// strokes (burrState: 5 mm burr, down to 2.5 mm deep) come near and touch.
Volume sphereOverDura() {
    Volume v = makeSphere(kN);
    const float r = sphereRadiusMm(kN) - 3.0f;
    for (int z = 0; z < kN; ++z)
        for (int y = 0; y < kN; ++y)
            for (int x = 0; x < kN; ++x)
                if (glm::length(v.voxelCenter({x, y, z})) < r)
                    v.set(x, y, z, 255, Material::Dura);
    return v;
}

const nlohmann::json& byName(const nlohmann::json& participants, const std::string& name) {
    for (const nlohmann::json& p : participants)
        if (p.at("name") == name)
            return p;
    throw std::runtime_error("no participant " + name);
}

} // namespace

TEST(SessionLog, MetricsRecomputedFromTheLogEqualTheLiveReportsAssessment) {
    const Volume start = sphereOverDura();
    const std::string logPath = tempPath("metrics-own.log");
    ServerConfig c = loopbackServerConfig("dura sphere");
    // Not the defaults: the replay must take the zones from the log.
    c.cautionMm = 4.0f;
    c.dangerMm = 2.0f;
    c.recorder = SessionRecorder::create(logPath, makeLogHeader(start, c, "", true, 1));
    nlohmann::json live;
    {
        RecordedSession s("metrics", c, start);
        ASSERT_TRUE(s.joined());
        const uint16_t ada = s.ada.welcome().clientId;
        s.stroke(s.ada, 0);
        s.stroke(s.ben, 40);
        s.cho.takeOver(ada);
        ASSERT_TRUE(pumpUntil(s.all, [&] {
            return s.ada.participants().at(ada).takenOverBy == s.cho.welcome().clientId;
        }));
        s.stroke(s.ada, -30); // paused: no drilling time, no cut
        s.stroke(s.cho, -30); // the instructor cuts in the trainee's place
        s.cho.takeOver(0);
        ASSERT_TRUE(
            pumpUntil(s.all, [&] { return s.ada.participants().at(ada).takenOverBy == 0; }));
        s.stroke(s.ben, 60, 25);
        s.stroke(s.ada, -60, 15);
        s.server.stop();
        live = nlohmann::json::parse(s.server.reportJson());
    }
    c.recorder.reset();

    const LogContents log = readSessionLog(logPath);
    ASSERT_TRUE(log.stopped.empty()) << log.stopped;
    EXPECT_EQ(log.version, kLogVersion);
    SessionReplay replay(log.header, logStartVolume(log.header, loadVolume));
    replay.applyAll(log.records);
    const nlohmann::json again = nlohmann::json::parse(replayReportText(replay, log, logPath));
    EXPECT_EQ(again.at("log"), logPath);
    EXPECT_EQ(again.at("records"), log.records.size());

    // The settings and structures as the server had them (its field build time is its own).
    for (const char* key : {"structures", "caution_mm", "danger_mm", "field_clamp_mm"})
        EXPECT_EQ(again.at("assessment").at(key), live.at("assessment").at(key)) << key;
    EXPECT_EQ(again.at("assessment").at("caution_mm"), 4.0);
    EXPECT_EQ(again.at("assessment").at("structures"), nlohmann::json::array({"dura"}));

    // Every participant's metrics, figure for figure (JSON numbers compared exactly).
    ASSERT_EQ(live.at("participants").size(), 3u);
    EXPECT_EQ(again.at("participants"), live.at("participants"))
        << "live:\n"
        << live.at("participants").dump(1) << "\nreplayed:\n"
        << again.at("participants").dump(1);

    // ... and they are not trivially equal: the strokes drilled, came near the dura and touched
    // it, with forces, over time.
    const nlohmann::json& a = byName(live.at("participants"), "Ada").at("metrics");
    const nlohmann::json& b = byName(live.at("participants"), "Ben").at("metrics");
    const nlohmann::json& cho = byName(live.at("participants"), "Dr. Cho");
    EXPECT_EQ(cho.at("role"), "instructor");
    for (const nlohmann::json* m : {&a, &b}) {
        EXPECT_GT(m->at("bone_removed_mm3").at("cortical").get<double>(), 0.0);
        EXPECT_GE(m->at("warnings").get<int>(), 1);
        EXPECT_GE(m->at("contacts").at("dura").get<int>(), 1);
        EXPECT_LE(m->at("closest_mm").at("dura").get<double>(), 0.0);
        EXPECT_GT(m->at("max_force_n").get<double>(), 0.0) << "forces travel in the log";
        EXPECT_GT(m->at("path_length_mm").get<double>(), 0.0);
        EXPECT_GT(m->at("zone_time_s").at("violation").get<double>(), 0.0);
        EXPECT_GT(m->at("session_time_s").get<double>(), 0.0);
        EXPECT_GT(m->at("drilling_time_s").get<double>(), 0.0);
    }
    EXPECT_NE(a.at("drilling_time_s"), b.at("drilling_time_s"));
    EXPECT_GT(cho.at("metrics").at("drilling_time_s").get<double>(), 0.0) << "holding Ada, cuts";
    std::filesystem::remove(logPath);
}

TEST(SessionLog, AFormat1LogReadsWithTheDefaultZonesAndNoForces) {
    // A v1 log, written as the first format did: no zones in the header, no force in a Tool.
    const Volume sphere = makeSphere(kN);
    LogHeader header = sphereHeader(sphere);
    header.cautionMm = 7.0f; // not written in v1: read back as the default
    std::vector<uint8_t> bytes(kLogMagic, kLogMagic + 8);
    for (uint8_t b : {1, 0, 0, 0}) // the format version, little-endian
        bytes.push_back(b);
    // zlib's CRC-32, as the log frames records (docs/recording.md).
    auto crc32 = [](const uint8_t* p, size_t n, uint32_t crc) {
        return uint32_t(::crc32(crc, p, uInt(n)));
    };
    auto frame = [&](auto& value) {
        std::vector<uint8_t> payload;
        WriteStream w(payload);
        ASSERT_TRUE(value.serialize(w, 1));
        uint8_t head[8];
        for (int i = 0; i < 4; ++i)
            head[i] = uint8_t(payload.size() >> (8 * i));
        const uint32_t crc = crc32(payload.data(), payload.size(), crc32(head, 4, 0));
        for (int i = 0; i < 4; ++i)
            head[4 + i] = uint8_t(crc >> (8 * i));
        bytes.insert(bytes.end(), head, head + 8);
        bytes.insert(bytes.end(), payload.begin(), payload.end());
    };
    frame(header);
    std::vector<LogRecord> records;
    records.push_back({100, HelloEvent{1, Role::Trainee, "Ada"}});
    records.push_back(
        {100, JoinEvent{.client = 1, .view = toViewSpec(cameraPreset("top", sphere, {32, 32}))}});
    const SurfaceSite site = trephine::testing::sphereTop(kN);
    for (int i = 0; i < 10; ++i) {
        // The force is not written in v1.
        records.push_back(
            {200 + uint64_t(i) * 10000, ToolEvent{1, burrState(site, i, 10, 1000000), 3.0f}});
    }
    for (LogRecord& r : records)
        frame(r);
    const std::string path = tempPath("v1.log");
    std::ofstream(path, std::ios::binary)
        .write(reinterpret_cast<const char*>(bytes.data()), std::streamsize(bytes.size()));

    // Resuming it goes on in format 1.
    {
        auto recorder = SessionRecorder::append(path, bytes.size(), 1);
        const LogRecord leave{500000, LeaveEvent{1}};
        ASSERT_TRUE(recorder->write({&leave, 1}));
    }
    const LogContents log = readSessionLog(path);
    ASSERT_TRUE(log.stopped.empty()) << log.stopped;
    EXPECT_EQ(log.version, 1u);
    ASSERT_EQ(log.records.size(), 13u);
    EXPECT_EQ(log.header.cautionMm, 3.0f);
    EXPECT_EQ(log.header.dangerMm, 1.0f);
    EXPECT_EQ(log.records[2].as<ToolEvent>()->forceN, -1.0f);
    EXPECT_TRUE(log.records.back().is<LeaveEvent>());

    SessionReplay replay(log.header, logStartVolume(log.header, loadVolume));
    replay.applyAll(log.records);
    const nlohmann::json j = nlohmann::json::parse(replayReportText(replay, log, path));
    EXPECT_EQ(j.at("log_format"), 1);
    EXPECT_EQ(j.at("assessment").at("caution_mm"), 3.0);
    ASSERT_EQ(j.at("participants").size(), 1u);
    const nlohmann::json& m = j.at("participants")[0].at("metrics");
    EXPECT_EQ(j.at("participants")[0].at("name"), "Ada");
    EXPECT_EQ(m.at("max_force_n"), 0.0) << "a v1 log has no forces";
    EXPECT_GT(m.at("bone_removed_mm3").at("cortical").get<double>(), 0.0);
    EXPECT_DOUBLE_EQ(m.at("session_time_s").get<double>(), 0.4999);
    std::filesystem::remove(path);
}

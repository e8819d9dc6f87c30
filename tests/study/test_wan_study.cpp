// The WAN study run tiny: both designs through the link emulator and a classroom of two, real
// server and clients in one process. Its CSV keeps the issue's columns, every cell it measures is
// there and sane (updates arrive; nothing beats the emulated delay), and the report gains its
// sections and plots with the targets beside them.
#include "study/report.h"
#include "study/wan_study.h"

#include "libsim/camera.h"
#include "libsim/error.h"
#include "libsim/skull.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <sstream>
#include <unistd.h>

using namespace trephine;
using namespace trephine::study;

namespace {

std::string slurpFile(const std::filesystem::path& p) {
    std::ifstream in(p);
    return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

Volume paperSkull(int n) {
    Volume v = makeSkull(n);
    v.setSpacing(glm::vec3(paperSpacingMm(n)));
    return v;
}

WanStudyConfig tinyConfig() {
    WanStudyConfig c;
    c.volumeName = "skull:64";
    c.window = 200;
    c.links = {{0, 0, 100}, {40, 1, 100}};
    c.boxes = {10};
    c.classroomBox = 10;
    c.soakS = c.targetSoakS = c.classroomSoakS = 0.6;
    c.classroom = {2};
    c.joinTimeoutS = 20;
    return c;
}

const WanResults& tinyRun() {
    static const WanResults results = runWanStudy(paperSkull(64), tinyConfig());
    return results;
}

WanRow made(const char* design, double rtt, int clients, double egress) {
    WanRow r;
    r.design = design;
    r.rttMs = rtt;
    r.rateMbit = 100;
    r.clients = clients;
    r.box = 10;
    r.classroom = clients > 1;
    r.updatesPerS = r.minUpdatesPerS = 40;
    r.latencyP50Ms = rtt / 2 + 2;
    r.latencyP99Ms = rtt / 2 + 9;
    r.joinMs = 3 * rtt + 30;
    r.viewChangeMs = r.classroom ? std::nan("") : rtt + 20;
    r.maxStallMs = 30;
    r.soakS = 1;
    r.egressBytesPerS = egress;
    return r;
}

} // namespace

// One run (about 8 s) for the CSV and the figures: ctest starts each test in a process of its own.
TEST(WanStudy, TheCsvHasTheIssuesColumnsAndARowWithSaneFiguresPerDesignLinkAndClassroom) {
    const std::string issue = "design,rtt_ms,loss_pct,rate_mbit,clients,box,updates_per_s,"
                              "latency_p50_ms,latency_p99_ms,join_ms,view_change_ms,max_stall_ms";
    const std::string header = wanCsvHeader();
    EXPECT_EQ(header.rfind(issue, 0), 0u) << header;
    const size_t columns = size_t(std::count(header.begin(), header.end(), ','));
    const WanResults& r = tinyRun();
    for (const WanRow& w : r.rows) {
        const std::string line = wanCsvRow(w);
        EXPECT_EQ(size_t(std::count(line.begin(), line.end(), ',')), columns) << line;
    }
    // 2 designs x 2 links x 1 box, then a classroom of 2 per design.
    ASSERT_EQ(r.rows.size(), 6u);
    ASSERT_EQ(r.clients.size(), 4u);
    for (const WanRow& w : r.rows) {
        SCOPED_TRACE(wanCsvRow(w));
        EXPECT_GT(w.joinMs, 0);
        EXPECT_GT(w.updatesPerS, 0);
        EXPECT_GT(w.egressBytesPerS, 0);
        ASSERT_FALSE(std::isnan(w.latencyP50Ms));
        // The client's latency is the server's cut to its picture: one way at least.
        EXPECT_GE(w.latencyP50Ms, w.rttMs / 2);
        EXPECT_GE(w.latencyP99Ms, w.latencyP50Ms);
        EXPECT_GE(w.maxStallMs, 1000.0 / w.offeredPerS * 0.5);
        // A join is a round trip at least (the connect, the hello), and more.
        EXPECT_GE(w.joinMs, w.rttMs);
        if (!w.classroom && w.design == "dbi") {
            EXPECT_GE(w.viewChangeMs, w.rttMs) << "a new view is a request and its image";
        }
        if (w.classroom) {
            EXPECT_TRUE(std::isnan(w.viewChangeMs));
        }
    }
    for (const WanClientRow& c : r.clients) {
        EXPECT_GT(c.updatesPerS, 0) << c.index;
        EXPECT_EQ(c.driller, c.index == 0);
    }
}

TEST(WanStudy, TheReportHasWanAndClassroomSectionsWithTheirPlotsAndTargets) {
    StudyReportInput in;
    in.command = "trephine study wan";
    in.machine = "test machine";
    in.wanConfig = tinyConfig();
    in.wan.rows = {made("dbi", 0, 1, 4e4),    made("dbi", 40, 1, 4e4),
                   made("volume", 0, 1, 6e4), made("volume", 40, 1, 6e4),
                   made("dbi", 0, 4, 1.6e5),  made("volume", 0, 4, 2.4e5)};
    const auto dir = std::filesystem::temp_directory_path() /
                     ("trephine-wan-report-" + std::to_string(::getpid()));
    const std::string md = writeStudyReport(in, dir.string());
    EXPECT_NE(md.find("## WAN: both designs"), std::string::npos);
    EXPECT_NE(md.find("## Classroom"), std::string::npos);
    EXPECT_NE(md.find("quickly flood the network"), std::string::npos);
    EXPECT_NE(md.find("a classroom of 64 joins without a flag"), std::string::npos) << md;
    // The target is on loopback: a rate-limited link's classroom is noted, not judged.
    EXPECT_NE(md.find("NOTE classroom of 4 (dbi design, in-process clients, one shared 100 Mbit/s "
                      "link)"),
              std::string::npos)
        << md;
    // Beside it, what the target asks of the link, from the lone client's bytes an update.
    EXPECT_NE(md.find("alone, one client's 10^3 updates are 1.0 kB each on the wire, so 30/s to "
                      "each of 4 is 1 Mbit/s of the link's 100"),
              std::string::npos)
        << md;
    const std::string plot = slurpFile(dir / "classroom.svg");
    EXPECT_NE(plot.find("the shared link"), std::string::npos);
    for (const char* svg : {"wan.svg", "wan-join.svg", "classroom.svg"})
        EXPECT_TRUE(std::filesystem::exists(dir / svg)) << svg;
    std::filesystem::remove_all(dir);
}

TEST(WanStudy, TheClassroomTargetJudgesALoopbackClassroom) {
    auto classroom = [](double p99) {
        WanRow r = made("dbi", 0, 64, 2e7);
        r.rateMbit = 0;
        r.minUpdatesPerS = 31;
        r.latencyP99Ms = p99;
        return r;
    };
    auto line = [](const WanResults& r) {
        for (const std::string& l : wanTargetLines(r))
            if (l.find("classroom of 64 (dbi") != std::string::npos)
                return l;
        return std::string();
    };
    WanResults r;
    r.rows = {classroom(42)};
    EXPECT_EQ(line(r).rfind("PASS classroom of 64 (dbi design, in-process clients, loopback", 0),
              0u)
        << line(r);
    r.rows = {classroom(51)};
    EXPECT_EQ(line(r).rfind("MISS classroom of 64", 0), 0u) << line(r);
}

TEST(WanStudy, ABoxThatDoesNotFitIsRefusedBeforeAnythingStarts) {
    WanStudyConfig c = tinyConfig();
    c.boxes = {100};
    EXPECT_THROW(checkWanStudy(paperSkull(64), c), Error);
    c.boxes = {10};
    c.classroom = {0};
    EXPECT_THROW(checkWanStudy(paperSkull(64), c), Error);
}

// Issue 32's LAN target judges the update study's rows over the emulated LAN, size by size.
TEST(WanStudy, TheLanNonRegressionTargetJudgesEachSize) {
    auto row = [](const char* method, int n, double rate) {
        UpdateStudyRow r;
        r.method = method;
        r.box = n;
        r.updatesPerS = rate;
        return r;
    };
    const std::vector<std::string> lines =
        lanTargetLines({row("dbi", 10, 800), row("volume", 10, 100), row("dbi", 40, 700),
                        row("volume", 40, 100), row("dbi", 20, 100), row("volume", 20, 100)});
    ASSERT_EQ(lines.size(), 2u);
    EXPECT_EQ(lines[0].rfind("PASS LAN non-regression 10^3: dbi / volume 8.0x", 0), 0u) << lines[0];
    EXPECT_EQ(lines[1].rfind("MISS LAN non-regression 40^3: dbi / volume 7.0x", 0), 0u) << lines[1];
}

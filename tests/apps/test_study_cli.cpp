// `trephine study updates|display|all --quick` run as a user would: the CSV's exact columns with
// sane values, and a report that names every figure.
#include "test_support.h"

#include "libsim/volume.h"
#include "libsim/volume_io.h"

#include <gtest/gtest.h>

#include <chrono>

#include <thread>

#include <unistd.h>

#include <sys/wait.h>

#include <fcntl.h>

#include <csignal>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <vector>

using namespace trephine::testing;

namespace {

std::vector<std::string> split(const std::string& line, char sep) {
    std::vector<std::string> out;
    std::stringstream ss(line);
    for (std::string cell; std::getline(ss, cell, sep);)
        out.push_back(cell);
    return out;
}

struct Csv {
    std::vector<std::string> header;
    std::vector<std::map<std::string, std::string>> rows;
};

Csv readCsv(const std::string& path) {
    Csv csv;
    std::stringstream ss(slurp(path));
    std::string line;
    if (!std::getline(ss, line))
        return csv;
    csv.header = split(line, ',');
    while (std::getline(ss, line)) {
        std::vector<std::string> cells = split(line, ',');
        EXPECT_EQ(cells.size(), csv.header.size()) << line;
        std::map<std::string, std::string> row;
        for (size_t i = 0; i < cells.size() && i < csv.header.size(); ++i)
            row[csv.header[i]] = cells[i];
        csv.rows.push_back(row);
    }
    return csv;
}

double num(const std::map<std::string, std::string>& row, const std::string& column) {
    auto it = row.find(column);
    EXPECT_NE(it, row.end()) << column;
    return it == row.end() ? -1.0 : std::stod(it->second);
}

// Every row sane: positive rates and sizes, BB_screen inside the 500x500 window and growing with
// N for every method; the volume method's raw bytes are exactly N^3.
void checkUpdates(const Csv& csv, const std::vector<int>& sizes) {
    const std::string expected = "method,box,bb_screen_w,bb_screen_h,bytes_per_update,"
                                 "raw_bytes_per_update,updates_per_s,latency_p50_ms,"
                                 "latency_p99_ms";
    std::string first;
    for (size_t i = 0; i < 9 && i < csv.header.size(); ++i)
        first += (i ? "," : "") + csv.header[i];
    EXPECT_EQ(first, expected);
    for (const char* stage : {"erode_ms", "render_ms", "encode_ms", "transmit_ms",
                              "client_apply_ms", "client_render_ms", "grid_ms"})
        EXPECT_NE(std::find(csv.header.begin(), csv.header.end(), stage), csv.header.end())
            << stage;
    std::map<std::string, std::vector<std::map<std::string, std::string>>> byMethod;
    for (const auto& row : csv.rows)
        byMethod[row.at("method")].push_back(row);
    for (const char* m : {"dbi", "dbi-fullrender", "volume", "volume-zstd"})
        ASSERT_EQ(byMethod[m].size(), sizes.size()) << m;
    for (const auto& [method, rows] : byMethod) {
        double lastW = 0;
        for (size_t i = 0; i < rows.size(); ++i) {
            const auto& r = rows[i];
            EXPECT_EQ(int(num(r, "box")), sizes[i]);
            const double w = num(r, "bb_screen_w"), h = num(r, "bb_screen_h");
            EXPECT_GT(w, 0);
            EXPECT_GT(h, 0);
            EXPECT_LE(w, 500);
            EXPECT_LE(h, 500);
            EXPECT_GT(w, lastW) << method << " BB_screen must grow with N";
            lastW = w;
            EXPECT_GT(num(r, "bytes_per_update"), 0) << method;
            EXPECT_GT(num(r, "updates_per_s"), 0) << method;
            EXPECT_GT(num(r, "latency_p50_ms"), 0) << method;
            EXPECT_GE(num(r, "latency_p99_ms"), num(r, "latency_p50_ms")) << method;
            const double n = sizes[i];
            if (method.rfind("volume", 0) == 0) {
                EXPECT_EQ(num(r, "raw_bytes_per_update"), n * n * n);
                EXPECT_GT(num(r, "client_render_ms"), 0) << "the volume client re-renders";
                // Its brick-grid update is timed, as a part of its apply.
                EXPECT_GT(num(r, "grid_ms"), 0) << method;
                EXPECT_LE(num(r, "grid_ms"), num(r, "client_apply_ms")) << method;
            } else {
                EXPECT_EQ(num(r, "raw_bytes_per_update"), 5.0 * w * h);
                EXPECT_GT(num(r, "render_ms"), 0) << "the server renders BB_screen";
                // The server's brick-grid update travels in the update, a part of its render.
                EXPECT_GT(num(r, "grid_ms"), 0) << method;
                EXPECT_LE(num(r, "grid_ms"), num(r, "render_ms")) << method;
            }
        }
    }
    // The raw volume method sends exactly one byte a voxel.
    for (size_t i = 0; i < sizes.size(); ++i) {
        const double n = sizes[i];
        EXPECT_NEAR(num(byMethod["volume"][i], "bytes_per_update"), n * n * n, 0.5);
    }
}

// `trephine study updates ARGS --volume skull:64 --out DIR/out`, which must succeed: what it
// printed, and the CSV it wrote.
struct UpdatesRun {
    CommandResult result;
    Csv csv;
};

UpdatesRun runUpdates(TempDir& dir, const std::string& args) {
    UpdatesRun run;
    run.result = runTrephine(dir, "study updates " + args + " --volume skull:64 --out '" +
                                      dir / "out" + "'");
    EXPECT_EQ(run.result.exitCode, 0) << run.result.out << run.result.err;
    run.csv = readCsv(dir / "out/updates.csv");
    return run;
}

} // namespace

TEST(StudyCli, UpdatesQuickWritesEveryColumnWithSaneValues) {
    TempDir dir;
    const UpdatesRun run = runUpdates(dir, "--quick --sizes 8,16");
    checkUpdates(run.csv, {8, 16});
    EXPECT_NE(run.result.out.find("update rate 8^3"), std::string::npos) << run.result.out;
    EXPECT_NE(run.result.out.find("update size 16^3"), std::string::npos) << run.result.out;
}

// --methods runs only the methods named; the rate target needs both dbi and volume, so none prints.
TEST(StudyCli, UpdatesMethodsRunsOnlyThoseNamed) {
    TempDir dir;
    const UpdatesRun run = runUpdates(dir, "--quick --sizes 8 --methods dbi");
    ASSERT_EQ(run.csv.rows.size(), 1u);
    EXPECT_EQ(run.csv.rows[0].at("method"), "dbi");
    EXPECT_EQ(run.result.out.find("update rate"), std::string::npos) << run.result.out;
}

// --rounds splits the cycles over several sweeps and pools them: every cell still reports all of
// its cycles, and the run says how it was measured.
TEST(StudyCli, UpdatesRoundsPoolEveryCycle) {
    TempDir dir;
    const UpdatesRun run =
        runUpdates(dir, "--sizes 8,12 --cycles 7 --rounds 3 --methods dbi,volume");
    EXPECT_NE(run.result.out.find("7 cycles per method and size in 3 rounds"), std::string::npos)
        << run.result.out;
    ASSERT_EQ(run.csv.rows.size(), 4u);
    for (const auto& row : run.csv.rows) {
        EXPECT_EQ(num(row, "cycles"), 7) << row.at("method") << " " << row.at("box");
        EXPECT_GT(num(row, "latency_p50_ms"), 0);
    }
}

// Without --rounds, fewer cycles than the default four rounds run one cycle a round.
TEST(StudyCli, UpdatesFewCyclesRunFewerRounds) {
    TempDir dir;
    const UpdatesRun run = runUpdates(dir, "--sizes 8 --cycles 2 --methods dbi");
    EXPECT_NE(run.result.out.find("2 cycles per method and size in 2 rounds"), std::string::npos)
        << run.result.out;
    ASSERT_EQ(run.csv.rows.size(), 1u);
    EXPECT_EQ(num(run.csv.rows[0], "cycles"), 2);
}

// `study all` checks the options of its later studies before the first one runs: a bad --link
// fails at once, not after the haptics study.
TEST(StudyCli, AllChecksItsOptionsBeforeRunning) {
    TempDir dir;
    CommandResult r =
        runTrephine(dir, "study all --quick --link rate=nan --out '" + dir / "all" + "'");
    EXPECT_NE(r.exitCode, 0);
    EXPECT_NE(r.err.find("rate=nan"), std::string::npos) << r.err;
    EXPECT_FALSE(std::filesystem::exists(dir / "all/haptics.csv"));
}

// Likewise a volume that does not open: the folder's earlier results stay as they were.
TEST(StudyCli, AllWithAVolumeThatDoesNotOpenLeavesEarlierResultsAlone) {
    TempDir dir;
    std::filesystem::create_directories(dir / "all");
    { std::ofstream(dir / "all/haptics.csv") << "yesterday's run\n"; }
    CommandResult r = runTrephine(dir, "study all --quick --volume '" + dir / "nosuch.nrrd" +
                                           "' --out '" + dir / "all" + "'");
    EXPECT_NE(r.exitCode, 0);
    EXPECT_NE(r.err.find("nosuch.nrrd"), std::string::npos) << r.err;
    std::ifstream in(dir / "all/haptics.csv");
    std::string line;
    std::getline(in, line);
    EXPECT_EQ(line, "yesterday's run");
}

// Likewise a volume that opens but is too small for the update study's cuts (--quick: up to
// 80^3): refused before the haptics study replaces the folder's haptics.csv.
TEST(StudyCli, AllWithAVolumeTooSmallForTheCutsLeavesEarlierResultsAlone) {
    TempDir dir;
    std::filesystem::create_directories(dir / "all");
    { std::ofstream(dir / "all/haptics.csv") << "yesterday's run\n"; }
    CommandResult r =
        runTrephine(dir, "study all --quick --volume skull:32 --out '" + dir / "all" + "'");
    EXPECT_NE(r.exitCode, 0);
    EXPECT_NE(r.err.find("does not fit the volume"), std::string::npos) << r.err;
    EXPECT_EQ(r.out.find("haptics"), std::string::npos) << r.out;
    std::ifstream in(dir / "all/haptics.csv");
    std::string line;
    std::getline(in, line);
    EXPECT_EQ(line, "yesterday's run");
}

// A volume without bone where the study cuts: one line saying so, not a study of cuts of air.
TEST(StudyCli, UpdatesOnAVolumeWithoutBoneOnItsMiddleColumnSaysSo) {
    TempDir dir;
    const std::string path = dir / "air.nrrd";
    trephine::saveVolume(trephine::Volume(glm::ivec3(32), glm::vec3(1.0f)), path);
    CommandResult r = runTrephine(dir, "study updates --quick --sizes 8 --volume '" + path +
                                           "' --out '" + dir / "out" + "'");
    EXPECT_NE(r.exitCode, 0);
    EXPECT_NE(r.err.find("no bone on its middle column"), std::string::npos) << r.err;
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
}

// A box that does not fit below the bone surface was clipped by the volume and still reported
// as N^3 (120^3 on skull:128 held 120 x 120 x 98 voxels), sizes or methods given twice ran
// twice (the targets read the first), and an empty --link ran loopback again as the "emulated
// link": each is one line, before anything runs.
TEST(StudyCli, ABoxBelowTheVolumeRepeatsAndAnEmptyLinkAreRefused) {
    TempDir dir;
    const struct {
        const char* args;
        const char* says;
    } cases[] = {
        {"study updates --sizes 10,120 --cycles 2 --rounds 1",
         "a 120^3 box does not fit below the bone surface of the volume (98 voxels deep there)"},
        {"study updates --sizes 10,10 --cycles 2 --rounds 1", "box size 10 is given twice"},
        {"study updates --sizes 10 --methods dbi,dbi --cycles 2 --rounds 1",
         "method 'dbi' is given twice"},
        {"study all --quick --link ''", "--link: give the link's conditions"},
    };
    for (const auto& c : cases) {
        SCOPED_TRACE(c.args);
        CommandResult r = runTrephine(dir, std::string(c.args) + " --out '" + dir / "o" + "'");
        EXPECT_NE(r.exitCode, 0);
        EXPECT_NE(r.err.find(c.says), std::string::npos) << r.err;
        EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
        EXPECT_FALSE(std::filesystem::exists(dir / "o/updates.csv"));
        EXPECT_FALSE(std::filesystem::exists(dir / "o/haptics.csv"));
    }
}

// --cycles and --rounds given on the command line win over --quick's.
TEST(StudyCli, UpdatesQuickKeepsTheCyclesGiven) {
    TempDir dir;
    const UpdatesRun run = runUpdates(dir, "--quick --sizes 8 --methods dbi --cycles 7");
    ASSERT_EQ(run.csv.rows.size(), 1u);
    EXPECT_EQ(num(run.csv.rows[0], "cycles"), 7);
}

// A CSV whose bytes never reach the disk (here: a full device) is an error, not "wrote".
TEST(StudyCli, UpdatesFailsWhenTheCsvCannotBeWritten) {
    if (!std::filesystem::exists("/dev/full"))
        GTEST_SKIP() << "no /dev/full";
    TempDir dir;
    std::filesystem::create_directories(dir / "out");
    std::filesystem::create_symlink("/dev/full", dir / "out/updates.csv");
    CommandResult r = runTrephine(dir, "study updates --quick --sizes 8 --methods dbi --cycles 1 "
                                       "--volume skull:64 --out '" +
                                           dir / "out" + "'");
    EXPECT_NE(r.exitCode, 0) << r.out;
    EXPECT_NE(r.err.find("updates.csv"), std::string::npos) << r.err;
    EXPECT_EQ(r.out.find("wrote"), std::string::npos) << r.out;
}

// --link puts the link emulator between the clients and the server: at 20 Mbit/s a 16^3 volume
// update (4096 bytes) cannot arrive in under 1.6 ms, which loopback delivers in microseconds.
TEST(StudyCli, UpdatesLinkEmulatesTheNetwork) {
    TempDir dir;
    const UpdatesRun run =
        runUpdates(dir, "--quick --sizes 16 --methods dbi,volume --link rate=20");
    EXPECT_NE(
        run.result.out.find("emulated link: latency 0 ms, jitter 0 ms, loss 0 %, rate 20 Mbit/s"),
        std::string::npos)
        << run.result.out;
    ASSERT_EQ(run.csv.rows.size(), 2u);
    for (const auto& row : run.csv.rows) {
        if (row.at("method") == "volume") {
            EXPECT_GE(num(row, "transmit_ms"), 4096 * 8 / 20e6 * 1e3) << "rate not applied";
        }
    }
}

TEST(StudyCli, BadFlagsGiveOneLine) {
    TempDir dir;
    for (const char* args :
         {"study updates --codec gzip --quick", "study updates --sizes 0",
          "study updates --camera nowhere --quick", "study updates --volume nosuch.nrrd --quick",
          "study updates --quick --methods dbi,teleport",
          "study updates --quick --codec lz4 --methods volume-zstd",
          "study updates --sizes 8 --cycles 3 --rounds 4", "study updates --sizes 8 --rounds 0",
          "study updates --quick --sizes 8 --link warp=9", "study all --quick --link rate=nan",
          "study all --quick --codec gzip"}) {
        CommandResult r = runTrephine(dir, std::string(args) + " --out '" + dir / "o" + "'");
        EXPECT_NE(r.exitCode, 0) << args;
        EXPECT_FALSE(r.err.empty()) << args;
        EXPECT_LE(std::count(r.err.begin(), r.err.end(), '\n'), 2) << args << ": " << r.err;
    }
}

// Found before any study ran, in one line: a loss of 100 % or more (the emulator caps it at 100,
// and the study waited a minute per method for updates that never came); an empty --out (haptics
// wrote into the working folder, updates said "Invalid argument"); a folder that takes no file
// (found only once the study had run). And a display study that cannot run says why on stderr.
TEST(StudyCli, ImpossibleLinksAndOutputFoldersAreRefusedBeforeTheStudy) {
    TempDir dir;
    struct Case {
        std::string args;
        const char* says;
    } cases[] = {
        {"study updates --quick --link loss=100 --out '" + dir / "o" + "'",
         "--link loss=100: a loss of 100 % lets no update through"},
        {"study all --quick --link loss=250 --out '" + dir / "o" + "'",
         "--link loss=250: a loss of 100 %"},
        {"study haptics --quick --out ''", "--out: an empty path"},
        {"study updates --quick --out ''", "--out: an empty path"},
        {"study updates --quick --out /proc", "--out /proc: cannot write into it"},
        {"study haptics --quick --out /proc", "--out /proc: cannot write into it"},
    };
    for (const Case& c : cases) {
        CommandResult r = runTrephine(dir, c.args);
        EXPECT_EQ(r.exitCode, 1) << c.args;
        EXPECT_NE(r.err.find(c.says), std::string::npos) << c.args << ": " << r.err;
        EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << c.args << ": " << r.err;
        EXPECT_EQ(r.out.find("cycles"), std::string::npos) << "no study ran: " << r.out;
    }
    EXPECT_FALSE(std::filesystem::exists(dir / "haptics.csv"));
    const std::string err = dir / "display.err";
    const int status = std::system(("env -u DISPLAY -u WAYLAND_DISPLAY " +
                                    shellQuote(TREPHINE_BIN) + " study display --quick --out " +
                                    shellQuote(dir / "d") + " >/dev/null 2>" + shellQuote(err))
                                       .c_str());
    EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 1);
    EXPECT_EQ(slurp(err).rfind("trephine: the display study did not run: ", 0), 0u) << slurp(err);
}

// A folder in DIR where `study all` writes a file (here report.md) failed the last move after the
// whole run, with the CSVs already replaced and the new report deleted: refused at the start,
// nothing of DIR touched.
TEST(StudyCli, AllRefusesAFolderWhereItWritesAFile) {
    TempDir dir;
    std::filesystem::create_directories(dir / "out/report.md");
    std::ofstream(dir / "out/updates.csv") << "an earlier run\n";
    CommandResult r = runTrephine(dir, "study all --quick --link off --out '" + dir / "out" + "'");
    EXPECT_EQ(r.exitCode, 1);
    EXPECT_NE(r.err.find("report.md there is not a file"), std::string::npos) << r.err;
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
    EXPECT_EQ(slurp(dir / "out/updates.csv"), "an earlier run\n");
}

// A misspelt mode or study, or none, is named in one line with the choices (CLI11 alone said "A
// subcommand is required", whatever the word).
TEST(StudyCli, AMisspeltOrMissingModeIsNamedWithTheChoices) {
    TempDir dir;
    struct Case {
        const char* args;
        const char* says;
    } cases[] = {
        {"stduy updates --quick", "unknown mode 'stduy' (modes: server,"},
        {"study update --quick", "unknown subcommand 'update' (study has: haptics,"},
        {"", "a mode is required (modes: server,"},
        {"study", "a subcommand is required (study has: haptics, updates, display, wan, all)"}};
    for (const Case& c : cases) {
        CommandResult r = runTrephine(dir, c.args);
        EXPECT_EQ(r.exitCode, 2) << c.args;
        EXPECT_NE(r.err.find(c.says), std::string::npos) << c.args << ": " << r.err;
        EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << c.args << ": " << r.err;
    }
    EXPECT_EQ(runTrephine(dir, "study --help").exitCode, 0);
}

// --link off: the update study runs once, over loopback, and the report has no link sections.
// An earlier run's link results (and, with no display here, its display.csv) in the same folder
// would sit beside a report that does not mention them: they are removed, and that is said.
TEST(StudyCli, AllLinkOffRunsTheUpdateStudyOnce) {
    TempDir dir;
    const std::string out = dir / "study";
    std::filesystem::create_directories(out);
    for (const char* name : {"updates-link.csv", "updates-link.svg", "display.csv", "notes.txt"})
        std::ofstream(out + "/" + name) << "an earlier run\n";
    // No display: the display study is not run, so display.csv is stale too.
    CommandResult r;
    {
        const ScopedEnv noDisplay("DISPLAY", std::nullopt);
        r = runTrephine(dir, "study all --quick --link off --out '" + out + "'");
    }
    ASSERT_EQ(r.exitCode, 0) << r.out << r.err;
    EXPECT_NE(r.out.find("== 3/4 display =="), std::string::npos) << r.out;
    EXPECT_NE(r.out.find("== 4/4 WAN and classroom (quick-sized) =="), std::string::npos) << r.out;
    checkUpdates(readCsv(out + "/updates.csv"), {10, 40, 80});
    EXPECT_FALSE(std::filesystem::exists(out + "/updates-link.csv"));
    EXPECT_FALSE(std::filesystem::exists(out + "/updates-link.svg"));
    EXPECT_FALSE(std::filesystem::exists(out + "/display.csv"));
    EXPECT_NE(r.out.find("removed updates-link.csv, updates-link.svg, display.csv from an earlier "
                         "run"),
              std::string::npos)
        << r.out;
    EXPECT_EQ(slurp(out + "/notes.txt"), "an earlier run\n") << "not ours: left alone";
    EXPECT_EQ(slurp(out + "/report.md").find("emulated link"), std::string::npos);
}

TEST(StudyCli, AllQuickWritesAReportNamingEveryFigure) {
    TempDir dir;
    const std::string out = dir / "study";
    CommandResult r = runTrephine(dir, "study all --quick --out '" + out + "'");
    ASSERT_EQ(r.exitCode, 0) << r.out << r.err;
    checkUpdates(readCsv(out + "/updates.csv"), {10, 40, 80});
    // The update study again over the paper's LAN, emulated: its own CSV, plot and sections.
    const Csv link = readCsv(out + "/updates-link.csv");
    checkUpdates(link, {10, 40, 80});
    for (const auto& row : link.rows) {
        if (row.at("method") == "volume" && num(row, "box") == 80) { // 512 kB at 100 Mbit/s
            EXPECT_GE(num(row, "transmit_ms"), 512000 * 8 / 100e6 * 1e3) << "link not applied";
        }
    }
    EXPECT_FALSE(readCsv(out + "/haptics.csv").rows.empty());
    const std::string report = slurp(out + "/report.md");
    for (const char* figure :
         {"Table 1", "Figure 7: update rates over loopback", "Figure 7 over the emulated link",
          "rate 100 Mbit/s", "Figure 8", "Stage breakdown", "Display", "Haptics", "Machine",
          "updates.svg", "updates-link.svg", "bytes.svg", "paper"})
        EXPECT_NE(report.find(figure), std::string::npos) << figure;
    for (const char* svg : {"/updates.svg", "/updates-link.svg", "/bytes.svg"}) {
        const std::string s = slurp(out + svg);
        EXPECT_EQ(s.rfind("<svg", 0), 0u) << svg;
        EXPECT_NE(s.find("<polyline"), std::string::npos) << svg;
    }
    if (std::getenv("DISPLAY")) { // ctest runs under xvfb-run: the display study must have run
        const Csv display = readCsv(out + "/display.csv");
        ASSERT_EQ(display.rows.size(), 3u);
        for (const auto& row : display.rows)
            EXPECT_GT(num(row, "fps"), 0) << row.at("renderer");
        EXPECT_EQ(report.find("Not measured"), std::string::npos);
    }
}

// A CSV that cannot be written (here: no file may grow, as on a full disk) fails the run, and an
// earlier run's file of that name is left whole: it was opened, so emptied, before the write
// that failed.
TEST(StudyCli, AFailedWriteLeavesTheEarlierCsvWhole) {
    TempDir dir;
    const std::string out = dir / "out";
    std::filesystem::create_directories(out);
    std::ofstream(out + "/updates.csv") << "method,box\nyesterday,8\n";
    // RLIMIT_FSIZE 0 with SIGXFSZ ignored: every write to a regular file fails with EFBIG. The
    // output goes through a pipe, which the limit does not touch.
    const std::string cmd = "( ulimit -f 0; trap '' XFSZ; exec " + shellQuote(TREPHINE_BIN) +
                            " study updates --quick --sizes 8 --methods dbi --cycles 1 --volume "
                            "skull:64 --out " +
                            shellQuote(out) + " ) 2>&1 | cat > " + shellQuote(dir / "log.txt");
    ASSERT_EQ(std::system(cmd.c_str()), 0);
    const std::string log = slurp(dir / "log.txt");
    EXPECT_NE(log.find("trephine: cannot write " + out + "/updates.csv"), std::string::npos) << log;
    EXPECT_EQ(slurp(out + "/updates.csv"), "method,box\nyesterday,8\n");
    size_t files = 0;
    for (const auto& e : std::filesystem::directory_iterator(out)) {
        (void)e;
        ++files;
    }
    EXPECT_EQ(files, 1u) << "no temporary file left behind";
}

// `study all` writes into a staging folder inside DIR and moves the set in once the report is
// written: stopped part way (Ctrl-C after the haptics study), it leaves the earlier run's files
// as they were (it left new CSVs beside the old report). A staging folder a killed run left is
// removed by the next run.
TEST(StudyCli, AllStoppedPartWayLeavesTheEarlierRunsFilesAsTheyWere) {
    TempDir dir;
    const std::string out = dir / "all";
    std::filesystem::create_directories(out + "/.study-all-999999999");
    for (const char* name : {"report.md", "haptics.csv", "updates.csv"})
        std::ofstream(out + "/" + name) << "yesterday's run\n";
    const pid_t pid = fork();
    if (pid == 0) {
        const int devnull = open("/dev/null", O_WRONLY);
        dup2(devnull, 1);
        dup2(devnull, 2);
        execl(TREPHINE_BIN, TREPHINE_BIN, "study", "all", "--quick", "--link", "off", "--out",
              out.c_str(), static_cast<char*>(nullptr));
        _exit(127);
    }
    ASSERT_GT(pid, 0);
    const std::string staged = out + "/.study-all-" + std::to_string(pid) + "/haptics.csv";
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(60);
    while (!std::filesystem::exists(staged) && std::chrono::steady_clock::now() < deadline)
        std::this_thread::sleep_for(std::chrono::milliseconds(10));
    const bool reached = std::filesystem::exists(staged);
    kill(pid, SIGINT);
    int status = 0;
    waitpid(pid, &status, 0);
    ASSERT_TRUE(reached) << "the haptics study never finished";
    for (const char* name : {"report.md", "haptics.csv", "updates.csv"}) {
        std::ifstream in(out + "/" + name);
        std::string line;
        std::getline(in, line);
        EXPECT_EQ(line, "yesterday's run") << name;
    }
    EXPECT_FALSE(std::filesystem::exists(out + "/updates.svg"));
    EXPECT_FALSE(std::filesystem::exists(out + "/.study-all-999999999"))
        << "a killed run's staging folder is removed";
}

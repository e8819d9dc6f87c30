// Options that name a file to write, as a user gets them wrong: refused with one line naming the
// option before anything runs, so nothing made in the run (a drilled skull, a session's
// statistics) is lost at its end.
#include "test_support.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <string>

using namespace trephine::testing;

namespace {

// `trephine ARGS` under `timeout`: a server that wrongly starts would otherwise never end.
CommandResult runBounded(const TempDir& dir, const std::string& args) {
    const std::string out = dir / "stdout.txt", err = dir / "stderr.txt";
    const std::string cmd = "timeout -s KILL 20 " + shellQuote(TREPHINE_BIN) + " " + args + " >" +
                            shellQuote(out) + " 2>" + shellQuote(err);
    const int status = std::system(cmd.c_str());
    CommandResult r;
    r.exitCode = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    r.out = slurp(out);
    r.err = slurp(err);
    return r;
}

} // namespace

// An empty value (`--save-on-exit "$UNSET"`) read as "not given": the server ran the session and
// wrote nothing when it stopped. A folder was found only at the end of the run.
TEST(OutputPathsCli, AnEmptyPathOrAFolderIsRefusedBeforeTheRun) {
    TempDir dir;
    const std::string folder = shellQuote(dir.path.string());
    const struct {
        std::string args;
        const char* option;
    } cases[] = {
        {"server --port 0 --volume sphere:16 --save-on-exit ''", "--save-on-exit"},
        {"server --port 0 --volume sphere:16 --report ''", "--report"},
        {"server --port 0 --volume sphere:16 --report " + folder, "--report"},
        {"trainee --headless --connect 127.0.0.1:9 --report ''", "--report"},
        {"trainee --headless --connect 127.0.0.1:9 --save-dbi " + folder, "--save-dbi"},
        {"trainee --connect 127.0.0.1:9 --screenshot ''", "--screenshot"},
        {"instructor --connect 127.0.0.1:9 --screenshot " + folder, "--screenshot"},
        {"demo --screenshot ''", "--screenshot"},
        {"render --volume sphere:16 --size 16x16 --out ''", "--out"},
        {"render --volume sphere:16 --size 16x16 --png " + folder, "--png"},
    };
    for (const auto& c : cases) {
        SCOPED_TRACE(c.args);
        CommandResult r = runBounded(dir, c.args);
        EXPECT_NE(r.exitCode, 0);
        EXPECT_NE(r.exitCode, -1) << "killed: it ran instead of refusing";
        EXPECT_EQ(r.err.rfind(std::string("trephine: ") + c.option + ": ", 0), 0u) << r.err;
        EXPECT_TRUE(r.err.find("an empty path") != std::string::npos ||
                    r.err.find("is a folder") != std::string::npos)
            << r.err;
        EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
        EXPECT_EQ(r.out, "");
    }
}

// The server's --report is written when the session ends: a folder that is not there (or a file
// where the folder should be) lost the session's statistics after it, and is refused before it
// starts, as the trainee's --report always was.
TEST(OutputPathsCli, TheServerReportFolderIsCheckedBeforeTheSession) {
    TempDir dir;
    std::ofstream(dir / "file.txt") << "a file\n";
    for (const std::string& report : {dir / "nosuch/server.json", dir / "file.txt/server.json"}) {
        SCOPED_TRACE(report);
        CommandResult r =
            runBounded(dir, "server --port 0 --volume sphere:16 --report " + shellQuote(report));
        EXPECT_EQ(r.exitCode, 1);
        EXPECT_EQ(r.err, "trephine: --report " + report + ": cannot write there (no folder " +
                             std::filesystem::path(report).parent_path().string() +
                             " we may write to)\n");
        EXPECT_EQ(r.out, "");
    }
}

// The server's --report written when it stops, on a disk where no file may grow: the failure is
// said, and the report of an earlier session at that path is left whole (it was emptied).
TEST(OutputPathsCli, AServerReportThatCannotBeWrittenLeavesTheEarlierOneWhole) {
    TempDir dir;
    const std::string report = dir / "server.json";
    std::ofstream(report) << "{\"earlier\": true}\n";
    // RLIMIT_FSIZE 0 with SIGXFSZ ignored: every write to a regular file fails with EFBIG; the
    // output goes through a pipe, which the limit does not touch. SIGTERM after 2 s stops it.
    const std::string cmd =
        "( ulimit -f 0; trap '' XFSZ; exec timeout --preserve-status -s TERM 2 " +
        shellQuote(TREPHINE_BIN) + " server --port 0 --volume sphere:16 --report " +
        shellQuote(report) + " ) 2>&1 | cat > " + shellQuote(dir / "log.txt");
    ASSERT_EQ(std::system(cmd.c_str()), 0);
    const std::string log = slurp(dir / "log.txt");
    EXPECT_NE(log.find("trephine: --report " + report + ": cannot write it"), std::string::npos)
        << log;
    EXPECT_EQ(slurp(report), "{\"earlier\": true}\n");
    size_t files = 0;
    for (const auto& e : std::filesystem::directory_iterator(dir.path))
        files += e.path().filename() != "log.txt";
    EXPECT_EQ(files, 1u) << "no temporary file left behind";
}

// `render --out` / `--png` into a folder that is not there failed only after the render, naming the
// temporary file beside the target: now one line naming the option, before the volume is loaded.
TEST(OutputPathsCli, RenderOutputsInAMissingFolderAreRefusedBeforeTheRender) {
    TempDir dir;
    for (const std::string& args : {"--out " + shellQuote(dir / "nosuch/a.exr"),
                                    "--png " + shellQuote(dir / "nosuch/a.png")}) {
        SCOPED_TRACE(args);
        CommandResult r = runBounded(dir, "render --volume sphere:16 --size 16x16 " + args);
        EXPECT_EQ(r.exitCode, 1);
        EXPECT_EQ(r.err.rfind("trephine: --", 0), 0u) << r.err;
        EXPECT_NE(r.err.find("cannot write there (no folder " + (dir / "nosuch")),
                  std::string::npos)
            << r.err;
        EXPECT_EQ(r.err.find(".tmp."), std::string::npos) << r.err;
        EXPECT_EQ(r.out, "") << "nothing rendered";
    }
}

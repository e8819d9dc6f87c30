// `trephine server` says where to join it: its UDP port, this machine's addresses with the
// command that joins from each, and a warning when the session will be discarded at exit (no
// --save-on-exit). Runs the binary; SIGTERM stops the server a few seconds after its start.
#include "test_support.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <regex>
#include <string>
#include <sys/wait.h>

using trephine::testing::shellQuote;
using trephine::testing::TempDir;

namespace {

// The server's output until SIGTERM stops it a few seconds after its start.
trephine::testing::CommandResult serve(const TempDir& dir, const std::string& extra) {
    const std::string out = dir / "stdout.txt", err = dir / "stderr.txt";
    const std::string cmd = shellQuote(TREPHINE_BIN) +
                            " server --port 0 --volume sphere:32 --render-threads 1 " + extra +
                            " >" + shellQuote(out) + " 2>" + shellQuote(err) +
                            " & p=$!; sleep 3; kill -TERM $p; wait $p";
    const int status = std::system(cmd.c_str());
    trephine::testing::CommandResult r;
    r.exitCode = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    r.out = trephine::testing::slurp(out);
    r.err = trephine::testing::slurp(err);
    return r;
}

} // namespace

TEST(ServerCli, PrintsItsUdpPortAddressesAndThatTheSessionIsDiscarded) {
    TempDir dir;
    const auto r = serve(dir, "");
    ASSERT_EQ(r.exitCode, 0) << r.err;
    std::smatch m;
    ASSERT_TRUE(std::regex_search(r.out, m, std::regex("on port ([0-9]+);"))) << r.out;
    const std::string port = m[1];
    EXPECT_NE(r.out.find("listening on UDP port " + port), std::string::npos) << r.out;
    EXPECT_NE(
        r.out.find("from this machine: trephine trainee --connect 127.0.0.1:" + port + " --code "),
        std::string::npos)
        << "the loopback address, with the command that joins it (the generated trainee code)\n"
        << r.out;
    EXPECT_NE(r.out.find("warning: the session (the drilled skull and the marks) is discarded"),
              std::string::npos)
        << r.out;
}

TEST(ServerCli, SaysNothingIsDiscardedWithSaveOnExit) {
    TempDir dir;
    const auto r = serve(dir, "--save-on-exit " + shellQuote(dir / "kept.nrrd"));
    ASSERT_EQ(r.exitCode, 0) << r.err;
    EXPECT_NE(r.out.find("listening on UDP port"), std::string::npos) << r.out;
    EXPECT_EQ(r.out.find("discarded"), std::string::npos) << r.out;
}

// The assessment's flags: zones out of order are refused in one line before anything starts; a
// --debrief folder is made and gets a debrief when the server stops (nobody joined: it says so).
TEST(ServerCli, AssessmentZonesAreCheckedAndTheDebriefFolderIsWritten) {
    TempDir dir;
    const auto bad = trephine::testing::runTrephine(
        dir, "server --port 0 --volume sphere:32 --danger-mm 4 --caution-mm 3");
    EXPECT_NE(bad.exitCode, 0);
    EXPECT_NE(bad.err.find("need 0 < danger < caution < 20 mm"), std::string::npos) << bad.err;
    EXPECT_EQ(std::count(bad.err.begin(), bad.err.end(), '\n'), 1) << bad.err;

    const std::string debrief = dir / "debrief";
    const auto r = serve(dir, "--caution-mm 4 --danger-mm 2 --debrief " + shellQuote(debrief));
    ASSERT_EQ(r.exitCode, 0) << r.err;
    EXPECT_TRUE(std::filesystem::is_directory(debrief)) << r.out;
}

// `--link SPEC` as a user gives it: on a trainee it puts the link emulator between the trainee and
// its server, on a server in front of its port; either way the trainee's own ping figure sees the
// added round trip and the picture still arrives. A bad spec is one line naming it, in every mode.
#include "child_process.h"
#include "test_support.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <memory>
#include <regex>
#include <string>

using namespace trephine::testing;

namespace {

// The server as a user starts it, open (no codes), on a free port; `extra` adds its options.
std::unique_ptr<Child> startServer(const std::string& extra) {
    std::vector<std::string> args{"server",    "--port",           "0", "--open", "--volume",
                                  "sphere:32", "--render-threads", "1"};
    if (!extra.empty()) {
        args.push_back("--link");
        args.push_back(extra);
    }
    return std::make_unique<Child>(args);
}

struct TraineeFigures {
    long updates = -1, full = -1;
    double rttUs = -1;
};

// "trainee: 93 updates (2 full), latency ... rtt p50 100195 us": the headless trainee's summary.
TraineeFigures figuresOf(const std::string& out) {
    TraineeFigures f;
    std::smatch m;
    if (std::regex_search(out, m, std::regex("trainee: ([0-9]+) updates \\(([0-9]+) full\\)")))
        f.updates = std::stol(m[1]), f.full = std::stol(m[2]);
    if (std::regex_search(out, m, std::regex("rtt p50 ([0-9]+) us")))
        f.rttUs = std::stod(m[1]);
    return f;
}

CommandResult headlessTrainee(const TempDir& dir, int port, const std::string& link) {
    return runTrephine(
        dir, "trainee --headless --duration 1 --connect 127.0.0.1:" + std::to_string(port) +
                 (link.empty() ? "" : " --link " + shellQuote(link)));
}

} // namespace

TEST(LinkCli, ATraineeThroughItsLinkMeasuresTheAddedRoundTripAndGetsThePicture) {
    TempDir dir;
    auto server = startServer("");
    const int port = server->port();
    ASSERT_GT(port, 0);
    const CommandResult r = headlessTrainee(dir, port, "latency=50");
    ASSERT_EQ(r.exitCode, 0) << r.err;
    const TraineeFigures f = figuresOf(r.out);
    EXPECT_GE(f.rttUs, 100000) << "50 ms each way: " << r.out;
    EXPECT_GE(f.full, 1) << "the full picture arrived: " << r.out;
    EXPECT_GT(f.updates, f.full) << "and the drilling's updates: " << r.out;
}

TEST(LinkCli, AServerWithALinkPutsItInFrontOfItsPort) {
    TempDir dir;
    auto server = startServer("latency=50");
    const int port = server->port(); // the public port, where the relay listens
    ASSERT_GT(port, 0);
    const CommandResult r = headlessTrainee(dir, port, "");
    ASSERT_EQ(r.exitCode, 0) << r.err;
    const TraineeFigures f = figuresOf(r.out);
    EXPECT_GE(f.rttUs, 100000) << r.out;
    EXPECT_GE(f.full, 1) << r.out;
}

TEST(LinkCli, ABadSpecIsOneLineNamingItInEveryMode) {
    TempDir dir;
    for (const char* mode :
         {"server --port 0", "trainee --headless --connect 127.0.0.1:9",
          "trainee --connect 127.0.0.1:9", "instructor --connect 127.0.0.1:9", "demo --headless"}) {
        for (const char* spec : {"latency=fast", "lag=3", "loss=100"}) {
            SCOPED_TRACE(std::string(mode) + " --link " + spec);
            const CommandResult r = runTrephine(dir, std::string(mode) + " --link " + spec);
            EXPECT_NE(r.exitCode, 0);
            EXPECT_NE(r.err.find(spec), std::string::npos) << r.err;
            EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
        }
    }
}

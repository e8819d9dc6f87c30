// `trephine server` as a process: SIGTERM stops it cleanly, --save-on-exit holds every drilling
// step it applied and --report is written; `trephine trainee --headless` runs its haptic loop.
#include "net/marks_file.h"
#include "net/scene.h"
#include "net/session_client.h"
#include "net/session_server.h"
#include "net/view.h"

#include "libsim/skull.h"
#include "libsim/volume_io.h"

#include "loopback.h"
#include "test_support.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <glm/gtx/quaternion.hpp>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <sys/wait.h>
#include <thread>
#include <unistd.h>
#include <vector>

using namespace trephine;
using namespace trephine::net;

using trephine::testing::loopbackServerConfig;
using trephine::testing::shellQuote;

namespace {

// A trainee's --report, parsed (an unreadable or malformed one is an empty object, which fails
// the assertions on its fields).
nlohmann::json readJson(const std::string& path) {
    std::ifstream in(path);
    nlohmann::json j = nlohmann::json::parse(in, nullptr, false);
    return j.is_discarded() ? nlohmann::json::object() : j;
}

// `trephine MODE ARGS` (MODE: server unless given) as a child process, its stdout read line by
// line.
struct ServerProcess {
    pid_t pid = -1;
    FILE* out = nullptr;

    // ignoreHangup: started as `nohup` starts it (SIGHUP ignored, inherited across exec).
    explicit ServerProcess(std::vector<std::string> args, const char* mode = "server",
                           bool ignoreHangup = false) {
        int fds[2];
        if (pipe(fds) != 0)
            return;
        // These tests' clients join without codes (the coded CLI has its own test).
        if (std::string(mode) == "server" &&
            std::find(args.begin(), args.end(), "--trainee-code") == args.end())
            args.push_back("--open");
        args.insert(args.begin(), {TREPHINE_BIN, mode});
        pid = fork();
        if (pid == 0) {
            if (ignoreHangup)
                signal(SIGHUP, SIG_IGN);
            dup2(fds[1], 1);
            close(fds[0]);
            std::vector<char*> argv;
            for (std::string& a : args)
                argv.push_back(a.data());
            argv.push_back(nullptr);
            execv(TREPHINE_BIN, argv.data());
            _exit(127);
        }
        close(fds[1]);
        out = fdopen(fds[0], "r");
    }
    ~ServerProcess() {
        if (pid > 0)
            stop();
    }
    // The next line it printed ("" at the end).
    std::string line() {
        char buf[512] = {};
        return out && fgets(buf, sizeof buf, out) ? std::string(buf) : std::string();
    }
    // `sig` (SIGTERM by default), then its exit status (-1: it did not exit normally).
    int stop(int sig = SIGTERM) {
        kill(pid, sig);
        int status = 0;
        const bool waited = waitpid(pid, &status, 0) == pid;
        pid = -1;
        if (out)
            fclose(out);
        out = nullptr;
        return waited && WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    }
};

// The port in the server's "... on port N; Ctrl-C stops" line, or -1.
int portIn(const std::string& text) {
    const auto at = text.find("on port ");
    return at == std::string::npos ? -1 : std::stoi(text.substr(at + 8));
}

} // namespace

TEST(SessionCli, SigtermWritesSaveOnExitWithTheDrilling) {
    std::string path = (std::filesystem::temp_directory_path() /
                        ("trephine_sigterm_" + std::to_string(getpid()) + ".nrrd"))
                           .string();
    std::string report = path + ".json";
    ServerProcess server({"--port", "0", "--volume", "sphere:32", "--render-threads", "1",
                          "--save-on-exit", path, "--report", report});
    const std::string text = server.line();
    const int port = portIn(text);
    ASSERT_GT(port, 0) << "the server printed: " << text;

    Volume sphere = makeSphere(32);
    ClientConfig cfg;
    cfg.view = toViewSpec(cameraPreset("top", sphere, {32, 32}));
    SessionClient client(cfg);
    client.connect(parseAddress("127.0.0.1:" + std::to_string(port)));
    auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(60);
    while (!client.hasFullImage() && !client.closed() &&
           std::chrono::steady_clock::now() < deadline)
        client.poll(1);
    ASSERT_TRUE(client.hasFullImage());
    glm::vec3 top(0.0f, 0.0f, sphereRadiusMm(32));
    for (int i = 0; i < 30; ++i) {
        ToolState t;
        t.sequence = uint32_t(i + 1);
        t.clientTimeUs = 1000000 + uint64_t(i) * 10000;
        t.diameterMm = 5.0f;
        t.position = top - glm::vec3(0, 0, 0.05f * float(i));
        t.speed = 1.0f;
        t.drilling = true;
        client.sendToolState(t);
        client.poll(1);
    }
    // Drilling shows up as image updates; wait for the first before stopping the server.
    while (client.updatesApplied() < 2 && std::chrono::steady_clock::now() < deadline)
        client.poll(1);
    ASSERT_GE(client.updatesApplied(), 2u);
    kill(server.pid, SIGTERM);
    while (!client.closed() && std::chrono::steady_clock::now() < deadline)
        client.poll(1);
    EXPECT_NE(client.closeReason().find("shutting down"), std::string::npos);
    EXPECT_EQ(server.stop(), 0);
    Volume saved = loadVolume(path);
    EXPECT_EQ(saved.dims(), sphere.dims());
    EXPECT_FALSE(saved == sphere) << "the applied drilling is in the saved volume";
    EXPECT_TRUE(readMarksFile(marksPathFor(path)).empty()) << "no marks, and a file saying so";
    std::filesystem::remove(path);
    std::filesystem::remove(marksPathFor(path));
    std::filesystem::remove(scenePathFor(path));
    // --report: per-channel and per-peer statistics, written when the server stopped.
    std::ifstream r(report);
    nlohmann::json json = nlohmann::json::parse(r, nullptr, false);
    ASSERT_FALSE(json.is_discarded()) << "the server report is JSON";
    ASSERT_TRUE(json["peers"].is_array()) << json.dump(2);
    EXPECT_EQ(json["peers"].size(), 1u) << json.dump(2);
    EXPECT_TRUE(json["haptic_models_sent"].is_number_unsigned()) << json.dump(2);
    EXPECT_EQ(json["haptic_models_sent"], json["peers"][0]["haptic_models"]) << json.dump(2);
    EXPECT_EQ(json["malformed_dropped"], 0) << json.dump(2);
    std::filesystem::remove(report);
}

// `trephine trainee --headless` against an in-process server: its haptic loop sends tool states at
// --tool-rate, every one is answered with a force model, and the report holds the loop's figures
// and the force round trip.
TEST(SessionCli, HeadlessTraineeRunsTheHapticLoopAndReportsIt) {
    Volume sphere = makeSphere(32);
    ServerConfig sc = loopbackServerConfig("sphere:32");
    SessionServer server(sphere, sc);
    server.start();
    std::string report = (std::filesystem::temp_directory_path() /
                          ("trephine_trainee_" + std::to_string(getpid()) + ".json"))
                             .string();
    std::string cmd = shellQuote(TREPHINE_BIN) +
                      " trainee --connect 127.0.0.1:" + std::to_string(server.port()) +
                      " --headless --camera top --size 64 --duration 1 --tool-rate 50 --report " +
                      shellQuote(report) + " > /dev/null 2>&1";
    ASSERT_EQ(std::system(cmd.c_str()), 0) << cmd;
    server.stop();
    const nlohmann::json json = readJson(report);
    const nlohmann::json& haptics = json.at("haptics");
    EXPECT_EQ(haptics.at("tool_rate_hz").get<double>(), 50.0) << json;
    const double sent = json.at("tool_states_sent").get<double>();
    EXPECT_GT(sent, 10.0) << json; // about 50 in the second, plus the final lift
    EXPECT_GT(haptics.at("models_received").get<double>(), 0.0) << json;
    EXPECT_LE(haptics.at("models_received").get<double>(), sent) << json;
    EXPECT_GT(haptics.at("ticks").get<double>(), 0.0) << json;
    EXPECT_GT(haptics.at("force_round_trip_p50_us").get<double>(), 0.0) << json;
    EXPECT_GT(server.hapticModelsSent(), 0u);
    EXPECT_LE(double(server.hapticModelsSent()), sent); // unsequenced: loss is allowed
    std::filesystem::remove(report);
}

// Others drilling on after a headless trainee's script ends do not keep it waiting: it waited for
// 0.5 s without any update, however long they went on, and reported their updates as its own.
TEST(SessionCli, AHeadlessTraineeDoesNotWaitForOthersToStopDrilling) {
    Volume sphere = makeSphere(32);
    SessionServer server(sphere, loopbackServerConfig("sphere:32"));
    server.start();
    // Someone else changes the top of the sphere ten times a second for up to 20 s.
    const Box3i box{{12, 12, 26}, {20, 20, 32}};
    std::vector<uint8_t> density, material;
    sphere.copyBox(box, density, material);
    std::atomic<bool> done{false};
    std::thread other([&] {
        for (int i = 0; i < 200 && !done; ++i) {
            if (i % 2)
                server.submitVoxels(box, density, material);
            else
                server.submitBoxCut(box);
            std::this_thread::sleep_for(std::chrono::milliseconds(100));
        }
    });
    const std::string report = (std::filesystem::temp_directory_path() /
                                ("trephine_trainee_drain_" + std::to_string(getpid()) + ".json"))
                                   .string();
    const std::string cmd = shellQuote(TREPHINE_BIN) +
                            " trainee --connect 127.0.0.1:" + std::to_string(server.port()) +
                            " --headless --camera top --size 64 --duration 1 --report " +
                            shellQuote(report) + " > /dev/null 2>&1";
    const int status = std::system(cmd.c_str());
    done = true;
    other.join();
    server.stop();
    ASSERT_EQ(status, 0) << cmd;
    const nlohmann::json json = readJson(report);
    ASSERT_TRUE(json.contains("duration_s")) << json;
    // The second of script, then at most 2 s for the last updates (not the others' 20 s).
    EXPECT_LT(json.at("duration_s").get<double>(), 8.0) << json;
    std::filesystem::remove(report);
}

// A headless trainee whose --size is larger than the server serves stops in one line naming the
// limit (it ran on with its 1x1 placeholder view and reported that as its picture).
TEST(SessionCli, AHeadlessTraineeLargerThanTheServerServesStopsInOneLine) {
    Volume sphere = makeSphere(32);
    ServerConfig sc = loopbackServerConfig("sphere:32");
    sc.maxViewPixels = 100 * 100;
    SessionServer server(sphere, sc);
    server.start();
    trephine::testing::TempDir dir;
    const auto r = trephine::testing::runTrephine(
        dir, "trainee --connect 127.0.0.1:" + std::to_string(server.port()) +
                 " --headless --camera top --size 200 --duration 1 --report " +
                 shellQuote(dir / "r.json"));
    server.stop();
    EXPECT_NE(r.exitCode, 0);
    EXPECT_NE(r.err.find("The server serves views of at most 10000 pixels; this view is 200 x 200: "
                         "restart with --size 100 or less"),
              std::string::npos)
        << r.err;
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
    EXPECT_FALSE(std::filesystem::exists(dir / "r.json"));
}

// `trephine trainee --headless --sync volume`: the replicated-volume baseline computes its forces
// locally on its copy of the volume, and the report names the mode.
// A CSV script that changes tools: the volume trainee's local forces follow it (the server's
// drill follows every tool state), not the first row's tool for the whole run.
TEST(SessionCli, HeadlessVolumeTraineeForcesFollowTheScriptsToolChanges) {
    Volume sphere = makeSphere(32);
    SessionServer server(sphere, loopbackServerConfig("sphere:32"));
    server.start();
    const auto dir = std::filesystem::temp_directory_path();
    const std::string tag = std::to_string(getpid());
    const std::string csv = (dir / ("trephine_vtools_" + tag + ".csv")).string();
    const std::string out = (dir / ("trephine_vtools_" + tag + ".txt")).string();
    {
        std::ofstream f(csv);
        f << "time_s,x,y,z,qw,qx,qy,qz,speed,tool\n";
        for (int i = 0; i <= 80; ++i) // a burr for 0.4 s, then the perforator
            f << i * 0.01 << ",0,0,20,1,0,0,0,1," << (i < 40 ? "burr:4" : "perforator:8") << "\n";
    }
    std::string cmd = shellQuote(TREPHINE_BIN) +
                      " trainee --connect 127.0.0.1:" + std::to_string(server.port()) +
                      " --headless --sync volume --camera top --size 64 --script " +
                      shellQuote(csv) + " > " + shellQuote(out) + " 2>&1";
    ASSERT_EQ(std::system(cmd.c_str()), 0) << cmd;
    server.stop();
    std::ifstream o(out);
    std::string text((std::istreambuf_iterator<char>(o)), std::istreambuf_iterator<char>());
    EXPECT_NE(text.find("haptic ticks (the rest: before the volume arrived), with 2 tools"),
              std::string::npos)
        << text;
    std::filesystem::remove(csv);
    std::filesystem::remove(out);
}

TEST(SessionCli, HeadlessVolumeTraineeComputesForcesOnItsOwnVolume) {
    Volume sphere = makeSphere(32);
    SessionServer server(sphere, loopbackServerConfig("sphere:32"));
    server.start();
    const auto dir = std::filesystem::temp_directory_path();
    const std::string tag = std::to_string(getpid());
    const std::string report = (dir / ("trephine_vtrainee_" + tag + ".json")).string();
    const std::string out = (dir / ("trephine_vtrainee_" + tag + ".txt")).string();
    std::string cmd = shellQuote(TREPHINE_BIN) +
                      " trainee --connect 127.0.0.1:" + std::to_string(server.port()) +
                      " --headless --sync volume --camera top --size 64 --duration 1 --report " +
                      shellQuote(report) + " > " + shellQuote(out) + " 2>&1";
    ASSERT_EQ(std::system(cmd.c_str()), 0) << cmd;
    server.stop();
    std::ifstream o(out);
    std::string text((std::istreambuf_iterator<char>(o)), std::istreambuf_iterator<char>());
    const nlohmann::json json = readJson(report);
    const auto at = text.find("forces computed locally on the replicated volume in ");
    ASSERT_NE(at, std::string::npos) << text;
    EXPECT_GT(std::stoll(text.substr(at + 52)), 0) << text;
    EXPECT_EQ(json.at("sync"), "volume") << json;
    EXPECT_GT(json.at("haptics").at("local_force_ticks").get<double>(), 0.0) << json;
    std::filesystem::remove(report);
    std::filesystem::remove(out);
}

// A saved session's marks come back with its volume: `--volume FILE` reads FILE.marks, says so,
// and serves them; a malformed marks file stops the server before it starts, in one line.
TEST(SessionCli, AServerStartedFromASavedSessionServesItsMarks) {
    trephine::testing::TempDir dir;
    const std::string volume = dir / "session.nrrd";
    saveVolume(makeSphere(32), volume);
    AnnotationInfo a, b;
    a.position = {1, 2, 3};
    a.label = "entry";
    b.position = {-4, 0, 9};
    b.label = "avoid";
    writeMarksFile(marksPathFor(volume), {a, b});
    ServerProcess server({"--port", "0", "--volume", volume, "--render-threads", "1"});
    const std::string first = server.line();
    EXPECT_NE(first.find("2 marks from " + marksPathFor(volume)), std::string::npos) << first;
    const int port = portIn(server.line());
    ASSERT_GT(port, 0);
    SessionClient client(ClientConfig{});
    client.connect(parseAddress("127.0.0.1:" + std::to_string(port)));
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(60);
    while (client.annotations().size() < 2 && !client.closed() &&
           std::chrono::steady_clock::now() < deadline)
        client.poll(1);
    EXPECT_EQ(server.stop(), 0);
    ASSERT_EQ(client.annotations().size(), 2u);
    EXPECT_EQ(client.annotations()[0].label, "entry");
    EXPECT_EQ(client.annotations()[1].position, b.position);

    std::ofstream(marksPathFor(volume)) << "trephine-marks 1\nmark 1 2 \"x\"\n";
    const trephine::testing::CommandResult r =
        trephine::testing::runTrephine(dir, "server --port 0 --volume " + shellQuote(volume));
    EXPECT_NE(r.exitCode, 0);
    EXPECT_NE(r.err.find("session.nrrd.marks:2: coordinate"), std::string::npos) << r.err;
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;

    // Opened with a query, the file's marks are still its own (the marks path took the query in,
    // found none, and the save then wrote an empty marks file over the two).
    writeMarksFile(marksPathFor(volume), {a, b});
    ServerProcess queried({"--port", "0", "--volume", volume + "?spacing=2,2,2", "--render-threads",
                           "1", "--save-on-exit", volume});
    const std::string line = queried.line();
    EXPECT_NE(line.find("2 marks from " + marksPathFor(volume)), std::string::npos) << line;
    EXPECT_GT(portIn(queried.line()), 0);
    EXPECT_EQ(queried.stop(), 0);
    EXPECT_EQ(readMarksFile(marksPathFor(volume)).size(), 2u);
}

// A closed terminal or dropped ssh (SIGHUP) killed the server without its save, and so did its
// output gone (piped into a `tee` that Ctrl-C ended: SIGPIPE on the next line): both now stop it
// as Ctrl-C does, with the session saved and exit 0.
TEST(SessionCli, AHangupOrAClosedOutputStillSavesTheSession) {
    trephine::testing::TempDir dir;
    for (int sig : {SIGHUP, SIGQUIT, SIGINT}) {
        SCOPED_TRACE(sig);
        const std::string path = dir / (std::to_string(sig) + "-saved.nrrd");
        ServerProcess server({"--port", "0", "--volume", "sphere:32", "--render-threads", "1",
                              "--save-on-exit", path});
        ASSERT_GT(portIn(server.line()), 0);
        if (sig == SIGINT) { // the reader is gone: the server's next line meets a closed pipe
            fclose(server.out);
            server.out = nullptr;
        }
        EXPECT_EQ(server.stop(sig), 0);
        EXPECT_EQ(loadVolume(path).dims(), glm::ivec3(32));
        EXPECT_TRUE(std::filesystem::exists(marksPathFor(path)));
    }
}

// Under nohup (SIGHUP ignored) a hang-up leaves the server running, as before the handler for
// SIGHUP was added (it stopped a `nohup trephine server &` at the ssh logout).
TEST(SessionCli, UnderNohupAHangupLeavesTheServerRunning) {
    trephine::testing::TempDir dir;
    const std::string path = dir / "s.nrrd";
    ServerProcess server(
        {"--port", "0", "--volume", "sphere:16", "--render-threads", "1", "--save-on-exit", path},
        "server", true);
    const int port = portIn(server.line());
    ASSERT_GT(port, 0);
    kill(server.pid, SIGHUP);
    // Still serving after the hang-up: a client joins (the server ran since the signal came).
    SessionClient client(
        trephine::testing::namedClientConfig(makeSphere(16), "after", Role::Trainee, 16));
    client.connect(trephine::testing::loopback(uint16_t(port)));
    EXPECT_TRUE(trephine::testing::pumpUntil(
        {&client}, [&] { return client.welcomed(); }, 20.0))
        << client.closeReason();
    client.disconnect();
    int status = 0;
    EXPECT_EQ(waitpid(server.pid, &status, WNOHANG), 0) << "the hang-up stopped it";
    EXPECT_EQ(server.stop(), 0);
    EXPECT_TRUE(std::filesystem::exists(path));
}

// --report over the saved session (or its marks) replaced the skull with JSON, exit 0; a NIfTI
// session reloads with no dura or brain: each is one line at start.
TEST(SessionCli, AReportOverTheSaveOrANiftiSaveIsRefusedAtStart) {
    trephine::testing::TempDir dir;
    const std::string save = dir / "s.nrrd";
    for (const std::string& args :
         {"--save-on-exit " + shellQuote(save) + " --report " + shellQuote(save),
          "--save-on-exit " + shellQuote(save) + " --report " + shellQuote(save + ".marks"),
          "--save-on-exit " + shellQuote(dir / "s.nii.gz"),
          "--save-on-exit " + shellQuote(dir / "s.NII")}) {
        SCOPED_TRACE(args);
        const auto r =
            trephine::testing::runTrephine(dir, "server --port 0 --volume sphere:16 " + args);
        EXPECT_NE(r.exitCode, 0);
        EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
        EXPECT_TRUE(r.err.find("where --save-on-exit writes") != std::string::npos ||
                    r.err.find("NIfTI keeps no materials") != std::string::npos)
            << r.err;
        EXPECT_FALSE(std::filesystem::exists(save));
    }
}

// A headless trainee whose server died mid-script (killed: no goodbye) ran its script to the end
// and exited 0, as ENet notices a silent peer only after 5 to 30 s: it now says it lost the server
// within seconds and exits 1, with its report still written.
TEST(SessionCli, AHeadlessTraineeWhoseServerDiesSaysSoAndFails) {
    trephine::testing::TempDir dir;
    ServerProcess server({"--port", "0", "--volume", "sphere:32", "--render-threads", "1"});
    const int port = portIn(server.line());
    ASSERT_GT(port, 0);
    const std::string cmd = shellQuote(TREPHINE_BIN) +
                            " trainee --connect 127.0.0.1:" + std::to_string(port) +
                            " --headless --camera top --size 64 --duration 4 --report " +
                            shellQuote(dir / "r.json") + " 2>&1";
    FILE* p = popen(cmd.c_str(), "r");
    ASSERT_NE(p, nullptr);
    std::string text;
    char buf[1024];
    bool killed = false;
    while (fgets(buf, sizeof buf, p)) {
        text += buf;
        if (!killed && text.find("script samples") != std::string::npos) {
            server.stop(SIGKILL); // the script has started
            killed = true;
        }
    }
    const int status = pclose(p);
    ASSERT_TRUE(killed) << text;
    EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 1) << text;
    EXPECT_NE(text.find("trainee: lost the server 127.0.0.1:" + std::to_string(port) +
                        ": nothing heard for 3 s"),
              std::string::npos)
        << text;
    EXPECT_TRUE(std::filesystem::exists(dir / "r.json"));
}

// Ctrl-C of a headless trainee ended it at once with nothing written: the script stops early, and
// the figures so far are printed and the report written, exit 1.
TEST(SessionCli, CtrlCOfAHeadlessTraineeStillWritesItsReport) {
    trephine::testing::TempDir dir;
    Volume sphere = makeSphere(32);
    SessionServer server(sphere, loopbackServerConfig("sphere:32"));
    server.start();
    ServerProcess trainee({"--connect", "127.0.0.1:" + std::to_string(server.port()), "--headless",
                           "--camera", "top", "--size", "64", "--duration", "30", "--report",
                           dir / "r.json"},
                          "trainee");
    std::string text;
    for (std::string line = trainee.line(); !line.empty(); line = trainee.line()) {
        text += line;
        if (line.find("script samples") != std::string::npos)
            break;
    }
    ASSERT_NE(text.find("script samples"), std::string::npos) << text;
    // Interrupted mid-script: once its tool states reach the server.
    ASSERT_TRUE(trephine::testing::waitFor([&] { return server.toolStatesApplied() > 0; }));
    EXPECT_EQ(trainee.stop(SIGINT), 1);
    server.stop();
    const nlohmann::json json = readJson(dir / "r.json");
    ASSERT_TRUE(json.contains("duration_s")) << json;
    EXPECT_LT(json.at("duration_s").get<double>(), 10.0) << json; // not the 30 s script
}

// A headless trainee that cannot join stops in one line saying why: a full server's refusal, and
// an address where no server answers (the client thread does not retry for a headless run).
TEST(SessionCli, AHeadlessTraineeThatCannotJoinSaysWhyInOneLine) {
    Volume sphere = makeSphere(32);
    ServerConfig sc = loopbackServerConfig("sphere:32");
    sc.maxClients = 1;
    SessionServer server(sphere, sc);
    server.start();
    SessionClient first(ClientConfig{});
    first.connect(trephine::testing::loopback(server.port()));
    ASSERT_TRUE(trephine::testing::pumpUntil({&first}, [&] { return first.welcomed(); }));
    std::atomic<bool> done{false};
    std::thread pump([&] {
        while (!done)
            first.poll(5);
    });
    trephine::testing::TempDir dir;
    const std::string address = "127.0.0.1:" + std::to_string(server.port());
    auto r = trephine::testing::runTrephine(dir, "trainee --headless --connect " + address +
                                                     " --camera top --size 64 --duration 1");
    done = true;
    pump.join();
    first.disconnect();
    EXPECT_NE(r.exitCode, 0);
    EXPECT_EQ(r.err, "trephine: trainee: " + address + " refused us: the server is full\n");

    // Nobody at this port now (the server stopped: its port is free).
    server.stop();
    r = trephine::testing::runTrephine(dir, "trainee --headless --connect " + address +
                                                " --camera top --size 64 --duration 1");
    EXPECT_NE(r.exitCode, 0);
    EXPECT_EQ(r.err, "trephine: trainee: no answer from " + address +
                         " (is `trephine server` running?)\n");
}

// `trephine server` makes codes when none are given and prints them after its port; a headless
// trainee with the trainee code joins, with a wrong one it stops in one line naming the reason.
TEST(SessionCli, AServerPrintsItsCodesAndOnlyTheRightOneJoins) {
    ServerProcess server({"--port", "0", "--volume", "sphere:32", "--render-threads", "1",
                          "--trainee-code", "LAB-TRAINEE"});
    const int port = portIn(server.line());
    ASSERT_GT(port, 0);
    EXPECT_EQ(server.line(), "trephine server: trainee code    LAB-TRAINEE\n");
    const std::string instructor = server.line();
    ASSERT_EQ(instructor.rfind("trephine server: instructor code ", 0), 0u) << instructor;
    EXPECT_NE(instructor.find("(generated)"), std::string::npos) << instructor;
    trephine::testing::TempDir dir;
    const std::string address = "127.0.0.1:" + std::to_string(port);
    const std::string trainee =
        "trainee --headless --connect " + address + " --camera top --size 64 --duration 1 --code ";
    auto r = trephine::testing::runTrephine(dir, trainee + "lab-trainee");
    EXPECT_EQ(r.exitCode, 0) << r.err;
    r = trephine::testing::runTrephine(dir, trainee + "LAB-TRAINER");
    EXPECT_NE(r.exitCode, 0);
    EXPECT_EQ(r.err, "trephine: trainee: " + address + " refused us: wrong session code\n");
    r = trephine::testing::runTrephine(dir, "trainee --headless --connect " + address +
                                                " --camera top --size 64 --duration 1");
    EXPECT_EQ(r.err, "trephine: trainee: " + address +
                         " refused us: this session needs a code: give the one the server "
                         "printed (--code)\n");
    r = trephine::testing::runTrephine(dir, trainee + "no!");
    EXPECT_NE(r.exitCode, 0);
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
    EXPECT_EQ(server.stop(), 0);
}

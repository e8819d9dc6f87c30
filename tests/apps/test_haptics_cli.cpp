// `trephine study haptics` and `trephine devices` run as a user would: exit codes, the CSV's exact
// header and one row per case, and one-line errors for bad flags.
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <sys/wait.h>
#include <unistd.h>

namespace fs = std::filesystem;

namespace {

struct HapticsTempDir {
    fs::path path;
    HapticsTempDir() {
        static std::atomic<int> counter{0};
        auto stamp = std::chrono::steady_clock::now().time_since_epoch().count();
        path =
            fs::temp_directory_path() / ("trephine_haptics_" + std::to_string(getpid()) + "_" +
                                         std::to_string(counter++) + "_" + std::to_string(stamp));
        fs::create_directories(path);
    }
    ~HapticsTempDir() {
        std::error_code ec;
        fs::remove_all(path, ec);
    }
};

struct CliResult {
    int exitCode = -1;
    std::string out, err;
};

std::string readAll(const fs::path& p) {
    std::ifstream f(p, std::ios::binary);
    return std::string(std::istreambuf_iterator<char>(f), {});
}

CliResult run(const HapticsTempDir& dir, const std::string& args) {
    const fs::path out = dir.path / "stdout.txt", err = dir.path / "stderr.txt";
    std::string cmd = std::string("'") + TREPHINE_BIN + "' " + args + " >'" + out.string() +
                      "' 2>'" + err.string() + "'";
    int status = std::system(cmd.c_str());
    CliResult r;
    r.exitCode = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    r.out = readAll(out);
    r.err = readAll(err);
    return r;
}

} // namespace

TEST(HapticsCli, StudyWritesTheCsv) {
    HapticsTempDir dir;
    const fs::path out = dir.path / "study";
    CliResult r =
        run(dir, "study haptics --volume box --update-rates 20,100 --latencies 0 --out '" +
                     out.string() + "'");
    ASSERT_EQ(r.exitCode, 0) << r.err;
    std::istringstream csv(readAll(out / "haptics.csv"));
    std::string line;
    ASSERT_TRUE(std::getline(csv, line));
    EXPECT_EQ(line.rfind("method,update_hz,latency_ms,force_rms_error_n,force_peak_error_n,"
                         "energy_injected_j,stable",
                         0),
              0u)
        << line;
    int rows = 0;
    while (std::getline(csv, line))
        rows += !line.empty();
    EXPECT_EQ(rows, 4); // 2 rates x 1 latency x 2 methods
    EXPECT_NE(r.out.find("perforator"), std::string::npos) << r.out;
}

// --quick reduces the grid, but rates and latencies given on the command line win (they were
// silently replaced by 20, 100 Hz x 0, 50 ms).
TEST(HapticsCli, QuickKeepsTheRatesAndLatenciesGiven) {
    HapticsTempDir dir;
    const fs::path out = dir.path / "quick";
    CliResult r = run(dir, "study haptics --quick --volume box --update-rates 50 --latencies 25 "
                           "--out '" +
                               out.string() + "'");
    ASSERT_EQ(r.exitCode, 0) << r.err;
    std::istringstream csv(readAll(out / "haptics.csv"));
    std::string line;
    std::getline(csv, line);
    int rows = 0;
    while (std::getline(csv, line)) {
        if (line.empty())
            continue;
        ++rows;
        EXPECT_NE(line.find(",50,25,"), std::string::npos) << line;
    }
    EXPECT_EQ(rows, 2); // 1 rate x 1 latency x 2 methods
}

TEST(HapticsCli, BadRateIsOneLineError) {
    HapticsTempDir dir;
    CliResult r =
        run(dir, "study haptics --volume box --update-rates 0 --out '" + dir.path.string() + "'");
    EXPECT_NE(r.exitCode, 0);
    EXPECT_NE(r.err.find("--update-rates"), std::string::npos) << r.err;
}

TEST(HapticsCli, DevicesExitsZero) {
    HapticsTempDir dir;
    CliResult r = run(dir, "devices");
    EXPECT_EQ(r.exitCode, 0) << r.err;
    // What each shell would drive its tool with, whatever hardware is attached.
    EXPECT_NE(r.out.find("window (trainee, instructor): mouse"), std::string::npos) << r.out;
    EXPECT_NE(r.out.find("headless trainee: script"), std::string::npos) << r.out;
}

// A CSV whose bytes never reach the disk (here: a full device) is an error, not "wrote".
TEST(HapticsCli, StudyFailsWhenTheCsvCannotBeWritten) {
    if (!fs::exists("/dev/full"))
        GTEST_SKIP() << "no /dev/full";
    HapticsTempDir dir;
    fs::create_symlink("/dev/full", dir.path / "haptics.csv");
    CliResult r = run(dir, "study haptics --quick --volume box --out '" + dir.path.string() + "'");
    EXPECT_NE(r.exitCode, 0) << r.out;
    EXPECT_NE(r.err.find("haptics.csv"), std::string::npos) << r.err;
    EXPECT_EQ(r.out.find("wrote"), std::string::npos) << r.out;
}

// Replacing writes: the temporary files a killed run left beside an output (Ctrl-C ends a run
// before the writer's destructor removes its own) are removed by the next write of that output,
// and a live process's are left alone.
#include "libsim/replacing_file.h"
#include "libsim/skull.h"
#include "libsim/volume_io.h"

#include "test_support.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <string>
#include <sys/wait.h>
#include <unistd.h>

using namespace trephine;
using trephine::testing::slurp;
using trephine::testing::TempDir;

namespace {

// A process id no process has now: a child that has exited and been waited for.
pid_t goneProcess() {
    const pid_t pid = fork();
    if (pid == 0)
        _exit(0);
    int status = 0;
    waitpid(pid, &status, 0);
    return pid;
}

} // namespace

TEST(ReplacingFile, AKilledRunsTemporaryFilesGoWithTheNextWrite) {
    TempDir dir;
    const std::string gone = std::to_string(goneProcess());
    const std::string alive = std::to_string(getppid()); // the test's parent: running
    const std::string csv = dir / "haptics.csv";
    for (const std::string& name :
         {"haptics.csv.trephine-" + gone + ".tmp", "haptics.trephine-" + gone + ".tmp.csv",
          "haptics.csv.trephine-" + alive + ".tmp", "other.csv.trephine-" + gone + ".tmp",
          std::string("haptics.csv.trephine-notapid.tmp")})
        std::ofstream(dir / name) << "partial\n";
    ASSERT_TRUE(writeReplacing(csv, "a,b\n"));
    EXPECT_EQ(slurp(csv), "a,b\n");
    EXPECT_FALSE(std::filesystem::exists(dir / ("haptics.csv.trephine-" + gone + ".tmp")));
    EXPECT_FALSE(std::filesystem::exists(dir / ("haptics.trephine-" + gone + ".tmp.csv")));
    EXPECT_TRUE(std::filesystem::exists(dir / ("haptics.csv.trephine-" + alive + ".tmp")))
        << "a running process's";
    EXPECT_TRUE(std::filesystem::exists(dir / ("other.csv.trephine-" + gone + ".tmp")))
        << "another output's";
    EXPECT_TRUE(std::filesystem::exists(dir / "haptics.csv.trephine-notapid.tmp"));

    // A volume save (its own writer) sweeps too.
    const std::string nii = dir / "v.nii.gz";
    std::ofstream(dir / ("v.nii.gz.trephine-" + gone + ".tmp")) << "partial\n";
    saveVolume(makeSphere(8), nii);
    EXPECT_FALSE(std::filesystem::exists(dir / ("v.nii.gz.trephine-" + gone + ".tmp")));
}

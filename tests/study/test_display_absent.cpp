// Without the GUI (TREPHINE_BUILD_GUI=OFF) the display study is absent: `study display` says why
// and writes no display.csv. With the GUI, tests/study_display measures it.
#include "study/commands.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <string>
#include <unistd.h>

using namespace trephine::study;

#ifndef TREPHINE_HAVE_GUI

TEST(DisplayStudy, WithoutTheGuiItSaysWhyAndWritesNoCsv) {
    const auto dir =
        std::filesystem::temp_directory_path() / ("trephine_display_" + std::to_string(getpid()));
    DisplayOptions o;
    o.out = dir.string();
    o.quick = true;
    const DisplayFigures f = runDisplayStudy(o);
    EXPECT_FALSE(f.measured);
    EXPECT_NE(f.why.find("TREPHINE_BUILD_GUI=OFF"), std::string::npos) << f.why;
    EXPECT_TRUE(f.entries.empty());
    EXPECT_FALSE(std::filesystem::exists(dir / "display.csv"));
    std::filesystem::remove_all(dir);
}

#endif

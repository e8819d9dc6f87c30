// `trephine trainee --script` as a user runs it: a script with a value the trainee cannot use is
// refused before anything connects, with one line naming the file, the line and the column.
#include "test_support.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <string>

using namespace trephine::testing;

namespace {

CommandResult runScript(const TempDir& dir, const std::string& rows) {
    const std::string path = dir / "script.csv";
    std::ofstream(path) << rows;
    // Nothing listens on port 9 of loopback: a script that passes would fail to connect instead.
    return runTrephine(dir, "trainee --headless --connect 127.0.0.1:9 --duration 1 --script '" +
                                path + "'");
}

struct RowCase {
    const char* row;  // the script's second line (after a good first one)
    const char* says; // in the refusal
};

// Each row after a good one is refused: exit 1, one line that says why.
void expectRefused(const TempDir& dir, std::initializer_list<RowCase> cases) {
    const std::string good = "0,0,0,50,1,0,0,0,0,burr:5\n";
    for (const RowCase& c : cases) {
        SCOPED_TRACE(c.row);
        CommandResult r = runScript(dir, good + c.row);
        EXPECT_EQ(r.exitCode, 1);
        EXPECT_NE(r.err.find(c.says), std::string::npos) << r.err;
        EXPECT_NE(r.err.find("script.csv"), std::string::npos) << "names the file: " << r.err;
        EXPECT_EQ(r.err.find('\n'), r.err.size() - 1) << "one line: " << r.err;
    }
}

} // namespace

TEST(TraineeCli, AScriptWithValuesTheTraineeCannotUseIsRefusedWithItsLine) {
    TempDir dir;
    expectRefused(
        dir,
        {
            {"nan,0,0,50,1,0,0,0,0,burr:5\n", "line 2: column 1 is not a finite number"},
            {"1,inf,0,50,1,0,0,0,0,burr:5\n", "line 2: column 2 is not a finite number"},
            {"1,1e39,0,50,1,0,0,0,0,burr:5\n", "line 2: column 2 is not a finite number"},
            {"1e300,0,0,50,1,0,0,0,0,burr:5\n", "line 2: column 1 is not a finite number"},
            {"100000,0,0,50,1,0,0,0,0,burr:5\n", "line 2: time must be from 0 to 86400 s"},
            {"1,0,0,50,0,0,0,0,0,burr:5\n", "line 2: the orientation quaternion is zero"},
            {"1,0,0,50,1,0,0,0,0,burr:-3\n", "line 2: burr diameter -3 mm is out of range"},
            {"1,0,0,50,1,0,0,0,0,diamond:5\n", "line 2: diamond diameter 5 mm is out of range"},
            {"1,0,0,50,1,0,0,0,0,drill:5\n", "line 2: tool must be NAME:D or NAME"},
        });
}

// CLI::Range lets NaN through (every comparison with it is false): floating-point options use a
// range that also wants a finite number, finite as a float.
TEST(TraineeCli, NanAndInfiniteOptionValuesAreRefused) {
    TempDir dir;
    for (const char* args :
         {"demo --headless --feed nan", "demo --headless --max-seconds inf",
          "demo --headless --feed 1e39", "trainee --headless --connect 127.0.0.1:9 --tool-rate nan",
          "trainee --headless --connect 127.0.0.1:9 --duration -inf"}) {
        SCOPED_TRACE(args);
        CommandResult r = runTrephine(dir, args);
        EXPECT_NE(r.exitCode, 0);
        EXPECT_NE(r.err.find("not a finite number"), std::string::npos) << r.err;
    }
}

// The outputs are checked before the session: a typo found at its end would waste it.
TEST(TraineeCli, OutputsThatCannotBeWrittenAreRefusedBeforeConnecting) {
    TempDir dir;
    const std::string session = "trainee --headless --connect 127.0.0.1:9 --duration 1 ";
    CommandResult r = runTrephine(dir, session + "--report '" + dir / "no-such/r.json" + "'");
    EXPECT_EQ(r.exitCode, 1);
    EXPECT_NE(r.err.find("--report"), std::string::npos) << r.err;
    EXPECT_NE(r.err.find("cannot write there"), std::string::npos) << r.err;
    r = runTrephine(dir, session + "--save-dbi '" + dir / "picture.png" + "'");
    EXPECT_EQ(r.exitCode, 1);
    EXPECT_NE(r.err.find("must end in .exr"), std::string::npos) << r.err;
}

// The protocol carries names of up to 64 bytes; a longer --name was sent anyway and the server's
// refusal read "the server did not understand our hello". Now refused before connecting.
TEST(TraineeCli, ANameTooLongForTheProtocolIsRefusedBeforeConnecting) {
    TempDir dir;
    const std::string name(65, 'a');
    for (const std::string& mode : {std::string("trainee --headless"), std::string("instructor")}) {
        SCOPED_TRACE(mode);
        CommandResult r = runTrephine(dir, mode + " --connect 127.0.0.1:9 --name " + name);
        EXPECT_NE(r.exitCode, 0);
        EXPECT_NE(r.err.find("--name: a name of 65 bytes is too long (at most 64)"),
                  std::string::npos)
            << r.err;
        EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
    }
}

// A --connect no server can listen on, and an unknown --camera preset, are refused as the
// command line is read: port 0 waited 10 s for "no answer", and the camera was met only once
// connected. (No display here: the window modes say so before connecting, so only checks made
// while the command line is read can show in their message.)
TEST(TraineeCli, ABadAddressOrCameraIsRefusedBeforeConnecting) {
    TempDir dir;
    const struct {
        std::string args, says;
    } cases[] = {
        {"trainee --headless --connect 127.0.0.1:0", "the port must be a number 1-65535"},
        {"trainee --headless --connect localhost:65536", "the port must be a number 1-65535"},
        {"trainee --headless --connect a:b:1", "'a:b:1' is not HOST:PORT"},
        {"trainee --headless --connect ''", "an empty address"},
        {"instructor --connect host:", "the port must be a number 1-65535"},
        {"trainee --headless --connect 127.0.0.1:9 --camera nowhere", "nowhere not in {"},
    };
    for (const auto& c : cases) {
        SCOPED_TRACE(c.args);
        CommandResult r = runTrephine(dir, c.args + " --duration 30");
        EXPECT_NE(r.exitCode, 0);
        EXPECT_NE(r.err.find(c.says), std::string::npos) << r.err;
        EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
    }
}

// Cells that are not wholly a number: stod read "0x10" as hex 16, "5mm" and "1.5.2" as their
// leading number and a trailing comma's empty 11th column not at all, so a mistyped script
// drilled somewhere other than written.
TEST(TraineeCli, AScriptCellThatIsNotWhollyANumberIsRefused) {
    TempDir dir;
    expectRefused(dir, {
                           {"0x10,0,0,50,1,0,0,0,0,burr:5\n", "line 2: column 1 is not a number"},
                           {"1,0,0,50mm,1,0,0,0,0,burr:5\n", "line 2: column 4 is not a number"},
                           {"1,1.5.2,0,50,1,0,0,0,0,burr:5\n", "line 2: column 2 is not a number"},
                           {"1,0,0,50,1,0,0,0,,burr:5\n", "line 2: column 9 is not a number"},
                           {"1,0,0,50,1,0,0,0,0,burr:5x\n",
                            "line 2: tool diameter in 'burr:5x' is not a number"},
                           {"1,0,0,50,1,0,0,0,0,perforator:\n",
                            "line 2: tool diameter in 'perforator:' is not a number"},
                           {"1,0,0,50,1,0,0,0,0,burr:5,\n", "line 2: expected 10 columns"},
                       });
    // Spaces around a number and Windows line ends are fine: this one fails only to connect.
    CommandResult r =
        runScript(dir, "0,0,0,50,1,0,0,0,0,burr:5\n 1 , 0,0,50,1,0,0,0,+0.5,burr: 5\r\n");
    EXPECT_EQ(r.err.find("script"), std::string::npos) << r.err;
}

// Line 1 is a header only when its first cell is not a number: a first sample written " 5.0" or
// "+5.0" was skipped as a header (judged by its first character), so the script lost it and the
// decreasing time on line 2 went unnoticed.
TEST(TraineeCli, AFirstSampleWithASpaceOrAPlusIsASampleNotAHeader) {
    TempDir dir;
    for (const char* first : {" 5.0,0,0,50,1,0,0,0,0,burr:5\n", "+5.0,0,0,50,1,0,0,0,0,burr:5\n"}) {
        SCOPED_TRACE(first);
        CommandResult r = runScript(dir, std::string(first) + "1,0,0,50,1,0,0,0,0,burr:5\n");
        EXPECT_EQ(r.exitCode, 1);
        EXPECT_NE(r.err.find("line 2: times must not decrease"), std::string::npos) << r.err;
    }
    // A real header is still one.
    CommandResult r =
        runScript(dir, "time_s,x,y,z,qw,qx,qy,qz,speed,tool\n0,0,0,50,1,0,0,0,0,burr:5\n");
    EXPECT_EQ(r.err.find("script"), std::string::npos) << r.err;
}

// A script saved with a UTF-8 byte order mark (as spreadsheets write CSV) lost its first sample,
// skipped as a header: the decreasing time on line 2 went unnoticed; a header after a mark is
// still one.
TEST(TraineeCli, AByteOrderMarkIsNotPartOfTheFirstSample) {
    TempDir dir;
    CommandResult r = runScript(dir, "\xEF\xBB\xBF"
                                     "5.0,0,0,50,1,0,0,0,0,burr:5\r\n"
                                     "1,0,0,50,1,0,0,0,0,burr:5\r\n");
    EXPECT_EQ(r.exitCode, 1);
    EXPECT_NE(r.err.find("line 2: times must not decrease"), std::string::npos) << r.err;
    r = runScript(dir, "\xEF\xBB\xBF"
                       "time_s,x,y,z,qw,qx,qy,qz,speed,tool\n"
                       "0,0,0,50,1,0,0,0,0,burr:5\n");
    EXPECT_EQ(r.err.find("script"), std::string::npos) << r.err;
}

// A script that is a folder read as "no samples"; one with no line ends (/dev/zero, a binary
// file) grew a single line until memory ran out.
TEST(TraineeCli, AScriptThatIsNotATextFileIsRefused) {
    TempDir dir;
    const std::string folder = dir / "scripts";
    std::filesystem::create_directories(folder);
    CommandResult r =
        runTrephine(dir, "trainee --headless --connect 127.0.0.1:9 --script " + shellQuote(folder));
    EXPECT_EQ(r.exitCode, 1);
    EXPECT_EQ(r.err, "trephine: script " + folder +
                         ": a folder, not a CSV file (use `burrhole` or a CSV file)\n");
    if (std::filesystem::exists("/dev/zero")) {
        r = runTrephine(dir, "trainee --headless --connect 127.0.0.1:9 --script /dev/zero");
        EXPECT_EQ(r.exitCode, 1);
        EXPECT_EQ(r.err, "trephine: script /dev/zero line 1: longer than 4096 characters: not a "
                         "CSV trajectory\n");
    }
}

// --report and --save-dbi naming one file: the picture, written last, replaced the report, and
// the run exited 0. Refused before connecting, as the server refuses --report over its save.
TEST(TraineeCli, AReportWhereTheDbiIsSavedIsRefused) {
    TempDir dir;
    const std::string same = dir / "sd.exr";
    CommandResult r = runTrephine(dir, "trainee --headless --connect 127.0.0.1:9 --duration 1 "
                                       "--report '" +
                                           same + "' --save-dbi '" + same + "'");
    EXPECT_EQ(r.exitCode, 1);
    EXPECT_NE(r.err.find("is where --save-dbi writes the picture"), std::string::npos) << r.err;
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
}

// A headless demo that fails (here: stopped before the perforator broke through) said so only on
// stdout, with exit 1 and nothing on stderr.
TEST(TraineeCli, AFailedHeadlessDemoSaysWhyOnStderr) {
    TempDir dir;
    CommandResult r = runTrephine(dir, "demo --headless --max-seconds 0.1");
    EXPECT_EQ(r.exitCode, 1);
    EXPECT_EQ(r.err, "trephine: demo: the perforator did not break through in 0.1 s\n");
}

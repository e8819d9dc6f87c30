// `--device` and `--pedal-map` as a user types them: a spec the shell cannot use, a device that
// is not attached or a bad mapping is one line and exit 1 before anything connects, and
// `trephine devices` says what each mode would use.
#include "test_support.h"

#include <gtest/gtest.h>

#include <fstream>
#include <string>

using namespace trephine::testing;

namespace {

// Nothing listens on port 9 of loopback: a refusal that came too late would fail to connect.
CommandResult headless(const TempDir& dir, const std::string& flags) {
    return runTrephine(dir, "trainee --headless --connect 127.0.0.1:9 --duration 1 " + flags);
}

void expectOneLine(const CommandResult& r, const std::string& says) {
    EXPECT_EQ(r.exitCode, 1);
    EXPECT_NE(r.err.find(says), std::string::npos) << r.err;
    EXPECT_EQ(r.err.find('\n'), r.err.size() - 1) << "one line: " << r.err;
}

} // namespace

TEST(DevicesCli, TheHeadlessTraineeRefusesADeviceItCannotUseBeforeConnecting) {
    TempDir dir;
    expectOneLine(headless(dir, "--device mouse"), "--device mouse: the headless trainee has no");
    expectOneLine(headless(dir, "--device trackball"), "--device trackball: unknown device");
    expectOneLine(headless(dir, "--device spacemouse:usb"), "unknown backend (auto, hid or spnav)");
    expectOneLine(headless(dir, "--device 'spacemouse?speed=-4'"), "out of range");
    // No SpaceMouse is attached to a test machine.
    expectOneLine(headless(dir, "--device spacemouse:hid"), "no SpaceMouse found through hidapi");
    expectOneLine(headless(dir, "--device plugin:" + (dir / "none.so")), "cannot load it");
    expectOneLine(headless(dir, "--pedal-map default"), "--pedal-map: the window's");
}

TEST(DevicesCli, DevicesSaysWhatEachModeWouldUseAndRefusesABadMapping) {
    TempDir dir;
    CommandResult r = runTrephine(dir, "devices");
    EXPECT_EQ(r.exitCode, 0) << r.err;
    EXPECT_NE(r.out.find("window (trainee, instructor): mouse"), std::string::npos) << r.out;
    EXPECT_NE(r.out.find("headless trainee: script"), std::string::npos) << r.out;
    r = runTrephine(dir, "devices --device spacemouse:hid --pedal-map default");
    EXPECT_EQ(r.exitCode, 0) << r.err;
    EXPECT_NE(r.out.find("headless trainee (--device spacemouse:hid): refused: --device "
                         "spacemouse:hid: no SpaceMouse found"),
              std::string::npos)
        << r.out;
    EXPECT_NE(r.out.find(R"(pedal: {"clutch":{"button":0})"), std::string::npos) << r.out;

    const std::string map = dir / "pedal.json";
    std::ofstream(map)
        << R"({"speed": {"axis": 0}, "clutch": {"button": 3}, "tool_switch": {"button": 3}})";
    expectOneLine(runTrephine(dir, "devices --pedal-map " + map),
                  "pedal.json: tool_switch.button: is the clutch's button too (3)");
}

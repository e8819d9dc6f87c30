// The windowed client shared by `trephine trainee`, `instructor` and `demo` (issue 6). Builds
// without the GUI too: then windowAvailable() says why not and runWindowedClient() refuses.
#pragma once

#include <CLI/CLI.hpp>
#include <string>
#include <vector>

namespace trephine::app {

struct WindowedOptions {
    std::string connect; // HOST:PORT
    std::string name = "trainee";
    std::string code; // the role's code (docs/security.md); empty: an open session
    bool instructor = false;
    std::string camera = "site";
    std::string codec = "lz4";
    int size = 500;
    std::string sizeOption = "--window-size"; // the option that set `size` (the trainee's: --size)
    std::string script;                       // "" or "burrhole"
    std::string screenshot;
    int frames = 0;
    double timeoutS = 90.0;
    float orbitDeg = 0.0f;
    // The site seen at a working angle, as over a surgeon's shoulder, not straight down the
    // drill's axis (which showed the handpiece end on).
    float tiltDeg = 30.0f;
    std::string sync = "dbi";          // the design to start in: dbi or volume (issue 7)
    std::string volumeCodec = "raw";   // volume boxes: raw, lz4 or zstd
    std::vector<double> switchSyncAtS; // scripted Comparison toggles (s after the first picture)
    std::vector<std::string> marks;    // instructor: "X,Y,Z[:LABEL]" marks placed on joining
    std::string takeOver; // [Instructor] the trainee (name or client id) to take over once joined
    std::string viewAs;   // [Instructor] the participant (name or client id) to view as once joined
    std::string link;     // --link: the emulator between this window and `connect`
    std::string device;   // --device: mouse (""), spacemouse[...] or plugin:PATH.so
    std::string pedalMap; // --pedal-map: a mapping file or "default" ("": no pedal)
};

// True when this build has the GUI and a window can open here; `why` says why not.
bool windowAvailable(std::string* why);
// Runs the trainee/instructor window; returns the exit code.
int runWindowedClient(const WindowedOptions& o);

// Adds --screenshot, --frames, --view, --orbit, --tilt, --window-size, --timeout, --sync,
// --volume-codec, --switch-sync-at and --link to a windowed mode's subcommand.
void addWindowOptions(CLI::App* sub, WindowedOptions& o);

// --device SPEC and --pedal-map FILE, the same words for every shell (the window, the headless
// trainee, `trephine devices`); libsim_devices/device_select.h parses the spec.
void addDeviceOptions(CLI::App* sub, std::string& device, std::string& pedalMap);

} // namespace trephine::app

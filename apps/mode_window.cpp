// The windowed client (issue 6) and `trephine instructor`. `trephine trainee` calls
// runWindowedClient when it runs without --headless.
#include "mode_window.h"

#include "libsim/camera.h"
#include "libsim/error.h"
#include "libsim_devices/device_select.h"
#include "libsim_devices/pedal.h"
#include "link_option.h"
#include "modes.h"
#include "net/enet_host.h"

#include <cstdio>

#ifdef TREPHINE_HAVE_GUI
#include "ui/trainer_app.h"
#include "ui/window.h"
#endif

namespace trephine::app {

bool windowAvailable(std::string* why) {
#ifdef TREPHINE_HAVE_GUI
    return ui::displayAvailable(why);
#else
    if (why)
        *why = "this trephine was built without the GUI (TREPHINE_BUILD_GUI=OFF)";
    return false;
#endif
}

int runWindowedClient(const WindowedOptions& o) {
#ifdef TREPHINE_HAVE_GUI
    std::string why;
    if (!windowAvailable(&why))
        throw Error("cannot open a window: " + why + " (use --headless, or run under xvfb-run)");
    const auto link = net::startLinkEnd(o.link, net::LinkEnd::Client, net::parseAddress(o.connect));
    // The device and the pedal's mapping are opened before the window: a bad one is one line.
    std::string error;
    std::shared_ptr<Device> device = openDevice(o.device, DeviceShell::Window, error);
    if (!error.empty())
        throw Error(error);
    ui::TrainerOptions t;
    t.device = std::move(device);
    if (!o.pedalMap.empty())
        t.pedalMap = readPedalMap(o.pedalMap);
    t.address = link ? net::relayAddress(*link) : o.connect;
    t.name = o.name;
    t.code = o.code;
    t.instructor = o.instructor;
    t.camera = o.camera;
    t.codec = o.codec;
    t.size = o.size;
    t.sizeOption = o.sizeOption;
    t.script = o.script;
    t.screenshot = o.screenshot;
    t.frames = o.frames;
    t.timeoutS = o.timeoutS;
    t.orbitDeg = o.orbitDeg;
    t.tiltDeg = o.tiltDeg;
    t.sync = o.sync;
    t.volumeCodec = o.volumeCodec;
    t.switchSyncAtS = o.switchSyncAtS;
    t.marks = o.marks;
    t.takeOver = o.takeOver;
    t.viewAs = o.viewAs;
    return ui::runTrainerWindow(t);
#else
    (void)o;
    throw Error("this trephine was built without the GUI (TREPHINE_BUILD_GUI=OFF), so it has no "
                "window (a trainee can run --headless)");
#endif
}

void addWindowOptions(CLI::App* sub, WindowedOptions& o) {
    sub->add_option("--screenshot", o.screenshot,
                    "Write the window to this PNG once the view has settled, then exit")
        ->check(outputFile());
    sub->add_option(
           "--frames", o.frames,
           "Settled frames to render before the screenshot (without one: frames showing the "
           "picture to run)")
        ->check(CLI::Range(0, 1000000));
    // Checked here: the window only met an unknown name once the volume had arrived, then ran
    // on without a picture (with --screenshot, until --timeout said "without a settled view").
    std::vector<std::string> views{"site"};
    for (const std::string& n : cameraPresetNames())
        views.push_back(n);
    sub->add_option("--view", o.camera, "site (close view of the burr site) or a camera preset")
        ->check(CLI::IsMember(views))
        ->capture_default_str();
    sub->add_option("--orbit", o.orbitDeg, "Initial orbit of the view about the site, degrees")
        ->check(finiteRange(-90.0, 90.0));
    sub->add_option("--tilt", o.tiltDeg, "Initial tilt of the view, degrees")
        ->check(finiteRange(-60.0, 60.0));
    sub->add_option("--window-size", o.size, "View size in pixels (square, 1:1 with the DBI)")
        ->check(CLI::Range(64, 2048))
        ->capture_default_str();
    sub->add_option("--timeout", o.timeoutS,
                    "With --screenshot or --frames: give up (exit 1) after this many seconds "
                    "without the view")
        ->check(finiteRange(1.0, 3600.0))
        ->capture_default_str();
    sub->add_option(
           "--sync", o.sync,
           "Design to start in: dbi (the server renders, sends image rectangles) or volume "
           "(the window holds the volume, ray casts it and computes forces locally); the "
           "Comparison panel's toggle switches live")
        ->check(CLI::IsMember({"dbi", "volume"}))
        ->capture_default_str();
    sub->add_option("--volume-codec", o.volumeCodec,
                    "Volume design: voxel boxes raw (1 byte each, as the paper), lz4 or zstd")
        ->check(CLI::IsMember({"raw", "lz4", "zstd"}))
        ->capture_default_str();
    sub->add_option("--switch-sync-at", o.switchSyncAtS,
                    "Flip the Comparison toggle at these seconds after the first picture "
                    "(comma-separated; each waits for the switch before it)")
        ->delimiter(',')
        ->check(finiteRange(0.0, 3600.0));
    addLinkOption(sub, o.link, "between this window and its server");
    addDeviceOptions(sub, o.device, o.pedalMap);
}

void addDeviceOptions(CLI::App* sub, std::string& device, std::string& pedalMap) {
    sub->add_option("--device", device,
                    "What drives the tool: mouse (the window's default), script (the headless "
                    "trainee's), spacemouse[:auto|hid|spnav][?speed=MM/S,turn=DEG/S,deadzone=N] "
                    "or plugin:PATH.so[?ARGS] (docs/devices.md; `trephine devices` says what is "
                    "attached)");
    sub->add_option("--pedal-map", pedalMap,
                    "Window: read a foot pedal or joystick with this mapping (a JSON file, or "
                    "`default`: axis 0 the drill's speed, button 0 clutch, 1 next tool)");
}

void addInstructorMode(CLI::App& root, int& exitCode) {
    auto o = std::make_shared<WindowedOptions>();
    o->instructor = true;
    o->name = "instructor";
    CLI::App* sub = root.add_subcommand(
        "instructor", "Join a session as an instructor: the window shows every participant's tool");
    sub->add_option("--connect", o->connect, "Server address HOST:PORT")
        ->check(serverAddress())
        ->required();
    sub->add_option("--name", o->name, "Name shown to others")
        ->check(participantName())
        ->capture_default_str();
    addCodeOption(sub, o->code, "instructor");
    sub->add_option("--codec", o->codec, "Image codec: raw, lz4 or zstd")
        ->check(CLI::IsMember({"raw", "lz4", "zstd"}))
        ->capture_default_str();
    sub->add_option("--mark", o->marks,
                    "Place a mark for everyone at X,Y,Z (mm, the volume's frame) with an optional "
                    ":LABEL once joined; repeatable (the M key marks the bone under the pointer)");
    sub->add_option("--take-over", o->takeOver,
                    "Take over this trainee (its --name, or its client id) once it is in the "
                    "session: its drill pauses and yours cuts (the Session panel hands back)");
    sub->add_option(
        "--view-as", o->viewAs,
        "Watch through this participant's camera (its --name, or its client id) once it "
        "is in the session (the Session panel's *view as* / *own view* switch)");
    addWindowOptions(sub, *o);
    sub->callback([o, &exitCode] { exitCode = runWindowedClient(*o); });
}

} // namespace trephine::app

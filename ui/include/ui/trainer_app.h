// The trainee / instructor window: a ClientThread, the two-pass compositor, the mouse device (or
// a scripted tool), and the panels. `trephine trainee`, `instructor` and `demo` all run it. It
// shows the skull in either design of issue 7 and switches between them live: DBI (the server
// renders, pass 1 restores the DBI) or the replicated volume (the window keeps a copy of the
// volume on the GPU, VolumeView ray casts it in pass 1, haptics are computed locally).
#pragma once

#include "libsim/camera.h"
#include "libsim/dbi.h"
#include "libsim/device.h"
#include "libsim_devices/pedal.h"
#include "ui/panel_data.h"

#include <array>
#include <atomic>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace trephine::ui {

// [Tests] What a window saw, filled when it closes (TrainerOptions::report).
struct TrainerReport {
    ComparisonHistory comparison;         // the Comparison panel's data
    SyncDesign picture = SyncDesign::Dbi; // the design that fed the last picture
    // The last picture of pass 1 (no tools): the DBI mirror, or the ray cast read back in volume
    // mode; row 0 at the bottom. Empty when no picture arrived.
    Dbi view;
    Camera camera; // what `view` shows
    int switchesRequested = 0, switchesCompleted = 0;
    uint64_t volumeUploads = 0, volumeBoxUpdates = 0; // VolumeView::upload / updateBox calls
    uint64_t localForceTicks = 0;  // haptic ticks whose force came from the local volume
    uint64_t serverForceTicks = 0; // ... from the server's models (multi-rate)
    std::array<uint64_t, kSyncDesignCount> frames{}; // frames drawn per design
    // The tool as the window last set it (the Session panel's controls and the keys).
    int toolKind = 0; // ToolKind
    float toolDiameterMm = 0.0f;
    float pushMm = 0.0f;
    // Where each panel was when the window closed (ImGui's window rectangles: x, y, w, h), by
    // its title; a panel not drawn (the full-window view) is absent.
    std::map<std::string, std::array<float, 4>> panels;
    // The client model's report (net::ClientModel::report), as the headless trainee writes it.
    nlohmann::ordered_json session;
};

// [Tests] The user's hands as a test drives them, in place of the mouse's: the pointer in window
// pixels from the top left (negative: off the window), the buttons held, the wheel's notches this
// frame, whether Ctrl or Shift is held, and a size to resize the window to (as dragging its
// corner; 0: leave it).
struct InjectedInput {
    float x = -1.0f, y = -1.0f;
    bool left = false, right = false;
    float wheel = 0.0f;
    bool zoomKey = false;
    int windowWidth = 0, windowHeight = 0;
    bool done = false; // the gesture is over: the view may settle (a screenshot be taken)
};

struct TrainerOptions {
    std::string address = "127.0.0.1:7777"; // HOST:PORT
    std::string name = "trainee";
    std::string code; // the role's code (docs/security.md); empty: an open session
    bool instructor = false;
    std::string codec = "lz4";
    std::string sync = "dbi";        // the design to start in: "dbi" or "volume"
    std::string volumeCodec = "raw"; // volume boxes: raw (1 byte a voxel, as the paper), lz4, zstd
    std::string camera = "site";     // "site" (close view of the burr site) or a camera preset
    float distanceMm = 170.0f;       // eye to site for "site"
    float orbitDeg = 0.0f; // initial orbit and tilt of the view (the View panel's sliders)
    float tiltDeg = 0.0f;
    int size = 500; // DBI and view size in pixels (1:1 with the window)
    // The window's size; 0: the view's and the panels' default columns beside it.
    int windowWidth = 0, windowHeight = 0;
    std::string sizeOption = "--size"; // the command-line option of `size`, for messages
    std::string script;                // "" (mouse) or "burrhole": a scripted drilling
    std::string screenshot; // write the window here after `frames` settled frames, then exit
    // Without a screenshot: frames showing the picture to run, then exit (0: until the window
    // closes).
    int frames = 0;
    // With --screenshot or --frames: give up (exit 1) after this long without a settled view
    // (screenshot), or without a picture (frames: from the start, or since the last frame that
    // counted). Views settle and frames count only while connected; a window closed before the
    // screenshot or the frames also exits 1.
    double timeoutS = 90.0;
    bool visible = true;
    // A scripted Comparison toggle: seconds after the first picture at which the toggle is
    // flipped, as if clicked. Each waits until the switch before it has completed; the view is not
    // settled (no screenshot) before the last one has.
    std::vector<double> switchSyncAtS;
    // [Instructor] Marks placed once joined, each "X,Y,Z" (mm, the volume's frame) with an optional
    // ":LABEL"; the view is not settled (no screenshot) before the server has listed them all.
    std::vector<std::string> marks;
    // [Instructor] A trainee to take over once it is listed: its name, or its client id. The view
    // is not settled (no screenshot) before the server lists the take-over.
    std::string takeOver;
    // [Instructor] A participant to view as once it is listed (its name or client id): the view
    // follows that participant's camera. The view is not settled before the server says it.
    std::string viewAs;
    // The device that drives the tool (--device; null: the mouse) and the pedal mapping
    // (--pedal-map; nullopt: no pedal is read). ui/device_drive.h.
    std::shared_ptr<Device> device;
    std::optional<PedalMap> pedalMap;
    // [Tests] GLFW keys tapped once the picture shows, one a frame: each press and its release
    // reach the window's key callback together before the frame polls (a tap shorter than a
    // frame).
    std::vector<int> tapKeys;
    TrainerReport* report = nullptr; // [Tests] filled when the window closes
    // [Tests] Called once a frame (first thing) with the seconds since the first picture
    // (negative before it); what it returns stands for the mouse (the view's tool and gestures
    // only) and the window's frame.
    std::function<InjectedInput(double)> input;
    // [Tests] The window closes once this is set, as if its close button was clicked (exit 0,
    // unless a screenshot or frames were asked for and not done).
    const std::atomic<bool>* quit = nullptr;
    // [Tests] Called on the window's thread with the camera of each whole picture the view takes
    // in (a server's full image, or the local volume's picture redrawn after a change).
    std::function<void(const Camera&)> onPicture;
    // [Tests] Called on the window's thread with each frame's composite of the view (the picture
    // and the meshes, no overlays; row 0 at the bottom) and the camera it was drawn with.
    std::function<void(const Dbi&, const Camera&)> onComposite;
};

// Runs the window until it closes. Returns the process exit code; throws trephine::Error when no
// window can open (the caller decides on a headless fallback) or on a bad option.
int runTrainerWindow(const TrainerOptions& options);

} // namespace trephine::ui

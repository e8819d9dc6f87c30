// The trainee / instructor window: a ClientThread, the two-pass compositor, the mouse device (or
// a scripted tool), and the panels. `trephine trainee`, `instructor` and `demo` all run it.
#pragma once

#include <string>

namespace trephine::ui {

struct TrainerOptions {
    std::string address = "127.0.0.1:7777"; // HOST:PORT
    std::string name = "trainee";
    bool instructor = false;
    std::string codec = "lz4";
    std::string camera = "site"; // "site" (close view of the burr site) or a camera preset
    float distanceMm = 170.0f;   // eye to site for "site"
    float orbitDeg = 0.0f;       // initial orbit and tilt of the view (the View panel's sliders)
    float tiltDeg = 0.0f;
    int size = 500;         // DBI and view size in pixels (1:1 with the window)
    std::string script;     // "" (mouse) or "burrhole": a scripted drilling
    std::string screenshot; // write the window here after `frames` settled frames, then exit
    int frames = 0;         // 0: run until the window closes (or the screenshot is taken)
    double timeoutS = 90.0; // with --screenshot: give up (exit 1) after this long
    bool visible = true;
};

// Runs the window until it closes. Returns the process exit code; throws trephine::Error when no
// window can open (the caller decides on a headless fallback).
int runTrainerWindow(const TrainerOptions& options);

} // namespace trephine::ui

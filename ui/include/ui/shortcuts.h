// The window's keyboard: one table of every shortcut (the F1 overlay lists it), what a frame's
// queued key presses (Window::keyPresses) do to the tool, the marks and the window, the F1
// overlay, and short notes over the view ("M: no bone under the pointer").
#pragma once

#include "ui/panels.h"
#include "ui/window.h"

#include <span>
#include <string>
#include <vector>

namespace trephine::ui {

struct Shortcut {
    const char* keys;
    const char* does;
};
// Every shortcut the window knows, in the order the F1 overlay lists them.
std::span<const Shortcut> shortcuts();

// The window's own toggles the keyboard flips.
struct WindowToggles {
    bool help = false;     // the F1 overlay
    bool fullView = false; // panels hidden, the view alone (H or F11)
};

// What the presses asked for this frame besides the tool's controls (changed in place).
struct KeyActions {
    bool markAtPointer = false;  // M (an instructor's: the caller checks)
    bool leaveTextField = false; // Enter or Escape while a text field has the keyboard
    bool labelledMark = false;   // Enter in the mark's label field
    bool toolChanged = false;    // kind, size or depth moved
    bool playPause = false;      // Space, an odd number of times (a replay's: the caller checks)
    int replaySteps = 0;         // Right presses less Left presses: kReplayStepS each
};

// Applies one frame's presses in order. While a text field has the keyboard (`textField`) only
// Enter and Escape count (both leave the field; Enter in the mark's label field, `labelField`,
// also places the labelled mark); while another widget is held (`widgetHeld`: a slider being
// dragged) no tool key counts, so the slider and the key cannot fight.
KeyActions applyKeys(const std::vector<KeyPress>& presses, bool textField, bool labelField,
                     bool widgetHeld, ToolControls& tool, WindowToggles& toggles);

// The F1 overlay: every shortcut, centred over the whole window, when `toggles.help`.
void drawShortcutOverlay(const WindowToggles& toggles);

// A short note over the top of the view for a few seconds (feedback to a key that did nothing).
struct ViewNote {
    std::string text;
    double until = 0.0;
    void show(std::string t, double now, double forS = 2.5) {
        text = std::move(t);
        until = now + forS;
    }
    // Draws it in the view (`viewX`, `viewY`, `viewW` wide) while it lasts.
    void draw(double now, float viewX, float viewY, float viewW) const;
};

} // namespace trephine::ui

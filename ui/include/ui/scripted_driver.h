// The window's scripted driver: what a scripted run asks of a trainer window (--script burrhole,
// --switch-sync-at, --mark, --take-over, --screenshot, --frames, --timeout), kept out of the
// window's own code. The window asks it each frame what is due and tells it what the frame showed;
// it decides when a scripted run is over and with what exit code.
#pragma once

#include "net/scripts.h"

#include "libsim/dbi.h"
#include "libsim/skull.h"
#include "net/client_model.h"
#include "net/client_thread.h"
#include "ui/mouse_tool.h"
#include "ui/panel_data.h"

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

namespace trephine::ui {

struct TrainerOptions;

// "X,Y,Z[:LABEL]" (mm) as an Annotate add; a malformed one is a one-line error naming it.
net::Annotate parseMark(const std::string& text);

class ScriptedDriver {
public:
    // Throws Error for a flag the window's role cannot use or a malformed --mark.
    explicit ScriptedDriver(const TrainerOptions& o);

    // A scripted screenshot is the same whatever the display's pointer hovers.
    bool ignoresPointer() const;
    bool drivesTool() const { return m_burrhole; }
    // [--script burrhole] The tool at `now` (s): the script starts at its first call.
    net::ScriptPose tool(const SurfaceSite& site, double now);
    // True once, on the frame the script ended (the view settles from then on).
    bool toolJustDone();

    // [--switch-sync-at] The design to switch to now, once the switch before has completed.
    std::optional<net::SyncDesign> switchDue(double now, double firstPictureAt, bool switching,
                                             net::SyncDesign wanted);
    // [--mark, --take-over] Sends what is due on this connection.
    void sendDue(const net::ClientSnapshot& snap, net::ClientThread& client);

    // What a frame showed, for the settle, screenshot and frame rules.
    struct Frame {
        const net::ClientSnapshot* snap = nullptr;
        bool havePicture = false, viewMatches = false, haveScene = false, switching = false;
        double sinceLastUpdateS = 0;
        uint16_t holding = 0;      // [instructor] the trainee held
        bool pointerBusy = false;  // [Tests] an injected pointer has not finished its gesture
        std::string viewNotServed; // the message when the server does not serve the view
    };
    // Before the frame ends: true when it ends the run at once, unframed (a view not served).
    bool abortsBeforeEnd(const Frame& f);
    // Whether the window's picture is wanted from this frame.
    bool wantsCapture(const Frame& f, double now);
    // After the frame: true when the run is over (exitCode() says how).
    bool afterFrame(const Frame& f, double now, const Dbi& capture);
    // After the window closed: a run closed before its screenshot or frames fails.
    void closed();
    bool scripted() const { return !m_screenshot.empty() || m_frames > 0; }
    int exitCode() const { return m_exitCode; }

private:
    bool settled(const Frame& f) const;

    std::string m_address, m_screenshot, m_takeOverName, m_viewAsName;
    int m_frames = 0;
    double m_timeoutS = 0;
    bool m_burrhole = false, m_scriptDone = true, m_justDone = false;
    double m_scriptStart = -1;
    std::vector<double> m_switchAtS;
    size_t m_nextSwitch = 0;
    std::vector<net::Annotate> m_marks;
    bool m_marksSent = true;
    ScriptedTakeOver m_takeOver;
    int m_settledFrames = 0, m_frameCount = 0, m_pictureFrames = 0;
    double m_lastPictureFrameAt = 0;
    bool m_ended = false;
    bool m_shoot = false, m_timedOut = false;
    int m_exitCode = 0;
};

} // namespace trephine::ui

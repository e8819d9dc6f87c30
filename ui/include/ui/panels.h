// The window's Dear ImGui panels, one per file (panel_<name>.cpp). Each draws from model data
// (ClientSnapshot and the histories in panel_data.h) every frame; its own UI state is the small
// struct declared beside it here.
#pragma once

#include "libsim/tool_catalogue.h"
#include "net/client_thread.h"
#include "ui/layout.h"
#include "ui/panel_data.h"

#include <array>
#include <map>
#include <optional>
#include <string>
#include <vector>

namespace trephine::ui {

// [Network] round trip, per-channel rates, update rate, latency histogram, codec, compression.
void drawNetworkPanel(const net::ClientSnapshot& snap, const NetworkHistory& history, double now);

// [Dirty boxes] BB_screen overlays on the view and the list of recent updates.
struct DirtyBoxPanelState {
    bool overlay = true;
};
void drawDirtyBoxPanel(DirtyBoxPanelState& state, const DirtyBoxHistory& boxes, double now);
// Fading rectangles over the view, whose top-left corner is at `viewOrigin` (ImGui coordinates)
// and which is `viewHeight` pixels tall (DBI rows count from the bottom).
void drawDirtyBoxOverlay(const DirtyBoxPanelState& state, const DirtyBoxHistory& boxes, double now,
                         float viewOriginX, float viewOriginY, int viewHeight);

// [Forces] |F| and x/y/z of the server's samples and the haptic loop's extrapolated force
// (loopRateHz: the rate the loop achieves). For an instructor (`participants` not null), one more
// plot per other participant from the server's relayed models, named and coloured as its tool.
// Every plot shows the same last 4 s up to `now` (the histories' clock) on one force scale, said
// in the panel.
void drawForcesPanel(const ForceHistory& forces, double loopRateHz, double now,
                     const ParticipantForces* participants = nullptr,
                     const std::map<uint16_t, net::ParticipantInfo>* roster = nullptr);

// [Session] role, participants, tool, its size, speed, connection state.
struct ToolControls {
    int kind = 0; // the selected ToolKind
    // Each kind's size, kept while another is selected: the catalogue's defaults to start.
    std::array<float, kToolKindCount> diameterMm = defaultDiameters();
    float& diameter(ToolKind k) { return diameterMm.at(size_t(k)); }
    float diameter(ToolKind k) const { return diameterMm.at(size_t(k)); }
    static std::array<float, kToolKindCount> defaultDiameters();
    float speed = 1.0f;    // [0, 1]
    float pushMm = 0.0f;   // how far the tip is pushed below the surface under the cursor
    bool drilling = false; // mouse button held (or the script drills)
    bool canDrill = true;  // a trainee nobody holds, or an instructor holding one (TakeOver)
};
// The range of ToolControls::pushMm (the slider's), and one step of the wheel or an arrow key.
constexpr float kPushMinMm = -5.0f, kPushMaxMm = 10.0f, kPushStepMm = 0.25f;
// pushMm moved by `steps` steps (the wheel's notches up, or Up, +1: deeper; down, or Down, -1:
// shallower), kept in the range so that a held arrow key cannot drive the tip through the inner
// table.
float steppedPush(float pushMm, float steps);
// The selected tool, its diameter, and that diameter's range and one step of `[` / `]`, as the
// tool catalogue gives them (libsim/tool_catalogue.h).
ToolKind selectedKind(const ToolControls& c);
float selectedDiameter(const ToolControls& c);
struct SizeRange {
    float minMm, maxMm, stepMm;
};
SizeRange sizeRange(ToolKind kind);
// The selected tool's size moved by `steps` steps, kept in its range.
void stepToolSize(ToolControls& c, int steps);
// `c` with every tool's size, speed and push depth within their sliders' ranges, NaN to
// the lowest: the server counts an out-of-range tool state as malformed and disconnects a client
// sending many.
ToolControls withinRanges(ToolControls c);
// The marks on the skull (the server's Annotations): listed for everyone; an instructor also
// labels the next one, marks the bone under the pointer, removes one or clears them. The panel
// only records what was asked this frame; the window sends it.
struct MarkControls {
    char label[net::kMaxNameLength + 1] = "";
    bool canMark = false;      // instructors
    bool addAtPointer = false; // asked this frame ("mark the pointer" or the M key)
    bool clearAll = false;
    uint32_t removeId = 0;    // 0: none
    size_t undoable = 0;      // marks the last removal took (the window's MarkUndo)
    bool undo = false;        // asked this frame: put them back
    bool labelActive = false; // the label field had the keyboard when the panel was last drawn
};
// What the marks asked for this frame (`controls`, then reset) comes to, as Annotates to send: an
// Add at the pointer, a Clear or a Remove (remembered in `undo` first) and the undo's Adds. Only
// while the link is up and welcomed (the client drops an Annotate otherwise): a removal asked
// without one is not remembered (its undo would re-add marks still on the skull), and an undo
// asked without one stays pending, so its marks are not lost.
std::vector<net::Annotate> markRequests(MarkControls& controls, MarkUndo& undo,
                                        const net::ClientSnapshot& snap,
                                        const std::optional<glm::vec3>& pointerPick);
// Taking over a trainee's drilling (TakeOver): an instructor's buttons in the participants list.
// The panel only records what was asked this frame; the window sends it.
struct TakeOverControls {
    bool canTakeOver = false;          // instructors
    std::optional<uint16_t> asked;     // a trainee's client id, or 0 to hand back
    std::optional<net::Remove> remove; // an instructor's remove, or letting the removed rejoin
    std::optional<net::Role> newCode;  // an instructor asks for a new code of this role
    // Plain requests the panel asked for this frame (net::ClientRequest), sent as they are.
    std::vector<net::ClientRequest> requests;
};
// Who holds trainee `id` in `roster` (0: nobody, or not listed), and whom `instructor` holds.
uint16_t takenOverBy(const std::map<uint16_t, net::ParticipantInfo>& roster, uint16_t id);
uint16_t heldBy(const std::map<uint16_t, net::ParticipantInfo>& roster, uint16_t instructor);
// [Instructor] View as: watch through a participant's camera (ViewAs); the server knows every
// client's view, so it is a view request, no new rendering.
struct ViewAsControls {
    bool canViewAs = false;        // instructors
    std::optional<uint16_t> asked; // a participant's client id, or 0 for its own view again
    // --view-as: a participant's name or client id to view as once listed (per connection).
    std::string scripted;
    int scriptedOnAttempt = -1;
    // The participant to view as on connection `attempt` for --view-as, if one other than `self`
    // is listed and none was asked for on this connection yet (marks it asked).
    std::optional<uint16_t> due(int attempt, uint16_t self,
                                const std::map<uint16_t, net::ParticipantInfo>& participants);
};
void drawSessionPanel(const net::ClientSnapshot& snap, ToolControls& tool, MarkControls& marks,
                      TakeOverControls& takeOver, ViewAsControls& viewAs, const std::string& role,
                      const std::string& address, const std::string& name);
// The colour marks are drawn in (both in the view and in the list).
glm::vec4 markColor();

// [View] orbit and zoom about the site; a change requests a new DBI.
// The View panel's ranges, which the view's own gestures (drag, Ctrl/Shift + wheel) keep too.
constexpr float kViewMinYawDeg = -90.0f, kViewMaxYawDeg = 90.0f;
constexpr float kViewMinPitchDeg = -60.0f, kViewMaxPitchDeg = 60.0f;
constexpr float kViewMinDistanceMm = 80.0f, kViewMaxDistanceMm = 500.0f;
constexpr float kOrbitDegPerPx = 0.3f; // a right drag across a 500-pixel view turns 150 degrees
struct ViewControls {
    float yawDeg = 0.0f, pitchDeg = 0.0f, distanceMm = 200.0f;
    bool dirty = false; // changed since the last request
    // Where *reset* goes back to: the view the window opened with (--orbit, --tilt, and the
    // camera's distance).
    float homeYawDeg = 0.0f, homePitchDeg = 0.0f, homeDistanceMm = 200.0f;
    void setHome() { homeYawDeg = yawDeg, homePitchDeg = pitchDeg, homeDistanceMm = distanceMm; }
    void reset() {
        yawDeg = homeYawDeg, pitchDeg = homePitchDeg, distanceMm = homeDistanceMm;
        dirty = true;
    }
};
// True when the user changed the view this frame. `picture` names what shows the view ("DBI",
// or "local render" in volume mode); `camera`, the view it was made with (none yet: no picture):
// its eye and target on one line, the whole camera in a tooltip, so the panel does not scroll in
// the default window.
bool drawViewPanel(ViewControls& view, bool waitingForImage, const char* picture,
                   const Camera* camera);

// [Comparison] one toggle between the two designs and, for both, live plots and the current
// update rate, bytes per update (and raw), update latency p50/p99, client frame time and haptic
// rate. `live` is the design feeding the picture: its figures are drawn bright, the other's
// greyed with their age. `wanted` is the design asked for, which the toggle flips; while it
// differs from `live` (a switch waiting for its first full update) the toggle and the table say
// so. Returns true when the user flipped it this frame (the caller then switches the client,
// e.g. ClientThread's sync mode).
bool drawComparisonPanel(SyncDesign& wanted, SyncDesign live, const ComparisonHistory& history,
                         double now);

// A tooltip for the last item drawn, shown on hover.
void itemTip(const char* text);

// The colour the server gave participant `id` (Participants' colour), the same in every window;
// a neutral grey while the roster does not list it yet.
glm::vec4 participantColor(const std::map<uint16_t, net::ParticipantInfo>& roster, uint16_t id);
glm::vec4 toColour(net::Rgb8 c);

// [Assessment] panel (panel_assessment.cpp): the server's live metrics, a trainee's own or an
// instructor's everyone's; the safety banner across the top of the view (this client's zone
// first, and for an instructor whoever else is in danger); a participant's zone for the Session
// panel's row; a zone's colour, and a tool's while it is in a zone.
void drawAssessmentPanel(const net::ClientSnapshot& snap);

// [Replay] The timeline of the log the server serves (net/replay_protocol.h): a bar along the
// bottom of the view (`view`, ImGui coordinates) with play / pause, the position to drag (the
// seek goes on release), the time and the speed. The bar and the keys (Space, Left / Right)
// only record what was asked; the window sends it.
struct ReplayControls {
    std::vector<net::ReplayControl> asked; // this frame's, in order (the window sends and clears)
    std::optional<double> dragS;           // the position slider held here (s)
    // The last seek asked, shown until the server's state has answered it (its seeks count).
    std::optional<uint64_t> seekUs;
    uint32_t seekAnswered = 0;
    // The position to show: the slider's while held, a seek asked until answered, else the
    // server's (`positionUs`, moved on to now).
    uint64_t shownUs(const net::ReplayState& state, uint64_t positionUs) const;
    void seek(const net::ReplayState& state, uint64_t toUs);
    // One frame's keys: Space (play / pause) and `steps` of kReplayStepS (Right on, Left back).
    void keys(bool playPause, int steps, const net::ReplayState& state, uint64_t positionUs);
};
inline constexpr double kReplayStepS = 5.0;
void drawReplayTimeline(const net::ReplayState& state, uint64_t positionUs, ReplayControls& c,
                        const UiRect& view);
void drawSafetyBanner(const net::ClientSnapshot& snap, int viewSize);
void drawZoneBadge(const net::ClientSnapshot& snap, uint16_t id);
glm::vec4 zoneColor(net::Zone z);
std::optional<glm::vec4> toolZoneColor(const net::ClientSnapshot& snap, uint16_t id);
// How the window names participant `id`: the name from its hello as the server's roster lists it
// ("client N" when the roster does not list it yet, or it gave no name).
std::string participantName(const std::map<uint16_t, net::ParticipantInfo>& roster, uint16_t id);

} // namespace trephine::ui

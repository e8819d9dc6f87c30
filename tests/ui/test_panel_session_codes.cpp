// The Session panel's code rows drawn under Xvfb: an instructor with the session's codes sees
// them with a button each, and clicking "new trainee code" asks for one; a trainee, or an
// instructor of an open session (no codes sent), has no such button.
#include "gl_window_test.h"
#include "ui/panels.h"
#include "ui/window.h"

#include <gtest/gtest.h>
#include <imgui/imgui.h>
#include <imgui/imgui_internal.h>

#include <memory>
#include <optional>

using namespace trephine;
using namespace trephine::ui;

namespace {

struct SessionPanelRig {
    WindowConfig wc;
    std::unique_ptr<Window> window;
    net::ClientSnapshot snap;
    ToolControls tool;
    MarkControls marks;
    TakeOverControls takeOver;
    ViewAsControls viewAs;

    SessionPanelRig() {
        wc.width = 520;
        wc.height = 600;
        wc.visible = false;
        window = std::make_unique<Window>(wc);
        snap.state = net::LinkState::Connected;
        // The first frame through the backends (they build the fonts); input is set by hand after.
        window->beginFrame();
        draw();
        window->endFrame(nullptr);
    }
    void draw() {
        ImGui::SetNextWindowPos(ImVec2(0, 0));
        ImGui::SetNextWindowSize(ImVec2(float(wc.width), float(wc.height)));
        drawSessionPanel(snap, tool, marks, takeOver, viewAs, "instructor", "127.0.0.1:7777",
                         "Dr. Cho");
    }
    // One frame with the mouse at `mouse` (input set by hand: the hidden window has no cursor).
    void frame(ImVec2 mouse, bool down) {
        ImGuiIO& io = ImGui::GetIO();
        io.MousePos = mouse;
        io.MouseDown[0] = down;
        ImGui::NewFrame();
        draw();
        window->endFrame(nullptr);
    }
    // Where the button labelled `label` is, found by hovering down the panel's left edge.
    std::optional<ImVec2> find(const char* label) {
        frame({-1, -1}, false);
        ImGuiWindow* w = ImGui::FindWindowByName("Session");
        if (!w)
            return std::nullopt;
        const ImGuiID id = w->GetID(label);
        const float x = ImGui::GetStyle().WindowPadding.x + 8.0f;
        for (float y = 0; y < float(wc.height); y += 3.0f) {
            frame({x, y}, false);
            frame({x, y}, false); // hovered as of the frame before
            if (ImGui::GetCurrentContext()->HoveredIdPreviousFrame == id)
                return ImVec2(x, y);
        }
        return std::nullopt;
    }
};

net::Codes codes() {
    net::Codes c;
    c.trainee = "QX7M-4KTD";
    c.instructor = "HW2R-9PZE";
    return c;
}

} // namespace

TEST(SessionPanel, AnInstructorClicksNewTraineeCode) {
    TREPHINE_NEED_DISPLAY("the panel");
    SessionPanelRig rig;
    rig.takeOver.canTakeOver = rig.marks.canMark = rig.viewAs.canViewAs = true;
    rig.snap.codes = codes();
    const std::optional<ImVec2> trainee = rig.find("new trainee code");
    const std::optional<ImVec2> instructor = rig.find("new instructor code");
    ASSERT_TRUE(trainee && instructor);
    EXPECT_LT(trainee->y, instructor->y); // the trainee code's row first
    EXPECT_FALSE(rig.takeOver.newCode);
    rig.frame(*trainee, true);  // press
    rig.frame(*trainee, false); // release over it: a click
    ASSERT_TRUE(rig.takeOver.newCode.has_value());
    EXPECT_EQ(*rig.takeOver.newCode, net::Role::Trainee);
    rig.takeOver.newCode.reset();
    rig.frame(*instructor, true);
    rig.frame(*instructor, false);
    ASSERT_TRUE(rig.takeOver.newCode.has_value());
    EXPECT_EQ(*rig.takeOver.newCode, net::Role::Instructor);
}

TEST(SessionPanel, NoCodeButtonsForATraineeOrWithoutCodes) {
    TREPHINE_NEED_DISPLAY("the panel");
    {
        SessionPanelRig trainee;
        trainee.snap.codes = codes(); // never sent to a trainee; the panel would not show them
        EXPECT_FALSE(trainee.find("new trainee code"));
    }
    SessionPanelRig open;
    open.takeOver.canTakeOver = open.marks.canMark = true;
    EXPECT_FALSE(open.find("new trainee code"));
    EXPECT_TRUE(open.find("let removed rejoin")); // the finder does find a button that is there
}

// The window's keyboard: a tap whose press and release reach GLFW's key callback inside one frame
// still counts (ImGui 1.86 polls key state once a frame and would miss it); sizes follow the
// selected tool; Up and the wheel agree; Enter and Escape leave a text field. Windows need a
// display (xvfb-run).
#include "gl_window_test.h"
#include "ui/shortcuts.h"
#include "ui/trainer_app.h"

#include "libsim/skull.h"
#include "libsim/tool.h"
#include "net/session_server.h"

#include "loopback.h"

#include <GLFW/glfw3.h>
#include <gtest/gtest.h>

using namespace trephine;
using namespace trephine::ui;

namespace {

std::vector<KeyPress> keys(std::initializer_list<int> k) {
    std::vector<KeyPress> out;
    for (int key : k)
        out.push_back({key, 0});
    return out;
}

} // namespace

TEST(WindowInput, KeyTapsInsideOneFrameChangeTheTool) {
    TREPHINE_NEED_DISPLAY("the trainee window");
    const Volume skull = makeSkull(64);
    net::SessionServer server(skull, trephine::testing::loopbackServerConfig("skull:64"));
    trephine::testing::Pumped pumped(server);
    auto run = [&](std::vector<int> taps) {
        TrainerReport report;
        TrainerOptions o;
        o.address = "127.0.0.1:" + std::to_string(server.port());
        o.camera = "working";
        o.size = 96;
        o.frames = int(taps.size()) + 2;
        o.timeoutS = 60.0;
        o.visible = false;
        o.tapKeys = std::move(taps);
        o.report = &report;
        EXPECT_EQ(trephine::testing::whilePumping([&] { return runTrainerWindow(o); }), 0);
        return report;
    };
    // The burr starts at 5 mm: two taps of [ make it 4 mm, Up pushes it one step deeper.
    const TrainerReport burr = run({GLFW_KEY_LEFT_BRACKET, GLFW_KEY_LEFT_BRACKET, GLFW_KEY_UP});
    EXPECT_EQ(burr.toolKind, int(ToolKind::Burr));
    EXPECT_FLOAT_EQ(burr.toolDiameterMm, 4.0f);
    EXPECT_FLOAT_EQ(burr.pushMm, kPushStepMm) << "Up goes deeper, as the wheel up does";
    // P selects the perforator (14 mm); ] steps it by 1 mm and stops at its 16 mm.
    const TrainerReport perf =
        run({GLFW_KEY_P, GLFW_KEY_RIGHT_BRACKET, GLFW_KEY_RIGHT_BRACKET, GLFW_KEY_RIGHT_BRACKET});
    EXPECT_EQ(perf.toolKind, int(ToolKind::Perforator));
    EXPECT_FLOAT_EQ(perf.toolDiameterMm, toolType(ToolKind::Perforator).maxDiameterMm);
    server.stop();
}

TEST(Shortcuts, ToolKeysFollowTheSelectedTool) {
    ToolControls t;
    WindowToggles w;
    applyKeys(keys({GLFW_KEY_RIGHT_BRACKET, GLFW_KEY_RIGHT_BRACKET, GLFW_KEY_RIGHT_BRACKET}), false,
              false, false, t, w);
    EXPECT_FLOAT_EQ(t.diameter(ToolKind::Burr), toolType(ToolKind::Burr).maxDiameterMm)
        << "5 + 0.5 + 0.5, then held at 6";
    EXPECT_EQ(selectedKind(t), ToolKind::Burr);
    applyKeys(keys({GLFW_KEY_P, GLFW_KEY_LEFT_BRACKET}), false, false, false, t, w);
    EXPECT_EQ(selectedKind(t), ToolKind::Perforator);
    EXPECT_FLOAT_EQ(selectedDiameter(t), toolType(ToolKind::Perforator).defaultDiameterMm - 1.0f);
    EXPECT_FLOAT_EQ(t.diameter(ToolKind::Burr), toolType(ToolKind::Burr).maxDiameterMm)
        << "the burr's size is kept";
    for (int i = 0; i < 20; ++i)
        stepToolSize(t, -1);
    EXPECT_FLOAT_EQ(selectedDiameter(t), toolType(ToolKind::Perforator).minDiameterMm);
    applyKeys(keys({GLFW_KEY_B}), false, false, false, t, w);
    EXPECT_FLOAT_EQ(selectedDiameter(t), toolType(ToolKind::Burr).maxDiameterMm);
    // D: the diamond burr, 2 mm, in 0.5 mm steps of its own.
    applyKeys(keys({GLFW_KEY_D, GLFW_KEY_RIGHT_BRACKET}), false, false, false, t, w);
    EXPECT_EQ(selectedKind(t), ToolKind::DiamondBurr);
    EXPECT_FLOAT_EQ(selectedDiameter(t), 2.5f);
    EXPECT_FLOAT_EQ(t.diameter(ToolKind::Burr), toolType(ToolKind::Burr).maxDiameterMm);
    applyKeys(keys({GLFW_KEY_B}), false, false, false, t, w);
    // Up and Down: deeper and shallower, as the wheel's up and down.
    applyKeys(keys({GLFW_KEY_UP, GLFW_KEY_UP, GLFW_KEY_DOWN}), false, false, false, t, w);
    EXPECT_FLOAT_EQ(t.pushMm, steppedPush(0.0f, 1.0f));
    // A slider held: its keys do not fight it.
    const ToolControls held = t;
    applyKeys(keys({GLFW_KEY_B, GLFW_KEY_LEFT_BRACKET}), false, false, true, t, w);
    EXPECT_EQ(t.diameter(ToolKind::Burr), held.diameter(ToolKind::Burr));
}

TEST(Shortcuts, EnterAndEscapeLeaveATextFieldAndEnterPlacesTheLabelledMark) {
    ToolControls t;
    WindowToggles w;
    // Typing "mp[" into the label field: characters, not shortcuts.
    KeyActions a =
        applyKeys(keys({GLFW_KEY_M, GLFW_KEY_P, GLFW_KEY_LEFT_BRACKET}), true, true, false, t, w);
    EXPECT_FALSE(a.markAtPointer);
    EXPECT_FALSE(a.leaveTextField);
    EXPECT_EQ(t.kind, 0);
    EXPECT_FLOAT_EQ(t.diameter(ToolKind::Burr), 5.0f);
    a = applyKeys(keys({GLFW_KEY_ENTER}), true, true, false, t, w);
    EXPECT_TRUE(a.leaveTextField);
    EXPECT_TRUE(a.labelledMark);
    // Escape leaves without a mark; the M after it in the same frame marks.
    a = applyKeys(keys({GLFW_KEY_ESCAPE, GLFW_KEY_M}), true, true, false, t, w);
    EXPECT_TRUE(a.leaveTextField);
    EXPECT_FALSE(a.labelledMark);
    EXPECT_TRUE(a.markAtPointer);
    // Enter in another field leaves it, places nothing.
    a = applyKeys(keys({GLFW_KEY_KP_ENTER}), true, false, false, t, w);
    EXPECT_TRUE(a.leaveTextField);
    EXPECT_FALSE(a.labelledMark);
}

TEST(Shortcuts, F1ListsEveryShortcutAndHHidesThePanels) {
    ToolControls t;
    WindowToggles w;
    applyKeys(keys({GLFW_KEY_F1}), false, false, false, t, w);
    EXPECT_TRUE(w.help);
    applyKeys(keys({GLFW_KEY_ESCAPE}), false, false, false, t, w);
    EXPECT_FALSE(w.help) << "Escape closes the list";
    applyKeys(keys({GLFW_KEY_H}), false, false, false, t, w);
    EXPECT_TRUE(w.fullView);
    applyKeys(keys({GLFW_KEY_F11}), false, false, false, t, w);
    EXPECT_FALSE(w.fullView);
    // The list names every key the window acts on.
    std::string all;
    for (const Shortcut& s : shortcuts())
        all += std::string(s.keys) + "\n";
    for (const char* k : {"F1", "B", "P", "D", "[", "]", "M", "Up", "Down", "Enter", "Escape", "H"})
        EXPECT_NE(all.find(k), std::string::npos) << k;
}

// The window's keyboard: the shortcut table, the presses' effects, the F1 overlay, view notes.
#include "ui/shortcuts.h"

#include <GLFW/glfw3.h>
#include <imgui.h>

#include <algorithm>
#include <vector>

namespace trephine::ui {

namespace {

// One table: the F1 overlay lists it, and docs/ui.md says the same. The tools' keys come from
// the tool catalogue, after the first three rows.
constexpr size_t kToolRowsAt = 3;
constexpr Shortcut kShortcuts[] = {
    {"left button (over the bone)", "drill while held"},
    {"wheel up / Up", "push the tool deeper (0.25 mm a step)"},
    {"wheel down / Down", "draw the tool back"},
    {"[  ]", "smaller / larger tool (burrs 0.5 mm, the perforator 1 mm a step)"},
    {"M", "instructor: mark the bone under the pointer (with the label typed)"},
    {"Enter (in the label field)", "place the labelled mark at the last bone pointed at"},
    {"Escape", "leave a text field; close this list"},
    {"H or F11", "full-window view: hide the panels, again to show them"},
    {"Space", "replay: play / pause"},
    {"Left / Right", "replay: 5 s back / on"},
    {"F1", "show or hide this list"},
};

} // namespace

std::span<const Shortcut> shortcuts() {
    static const std::vector<Shortcut> all = [] {
        std::vector<Shortcut> rows(std::begin(kShortcuts), std::begin(kShortcuts) + kToolRowsAt);
        for (const ToolType* t : toolTypes())
            rows.push_back({t->key, t->name});
        rows.insert(rows.end(), std::begin(kShortcuts) + kToolRowsAt, std::end(kShortcuts));
        return rows;
    }();
    return all;
}

KeyActions applyKeys(const std::vector<KeyPress>& presses, bool textField, bool labelField,
                     bool widgetHeld, ToolControls& tool, WindowToggles& toggles) {
    KeyActions a;
    for (const KeyPress& k : presses) {
        const bool enter = k.key == GLFW_KEY_ENTER || k.key == GLFW_KEY_KP_ENTER;
        if (textField && !a.leaveTextField) {
            if (enter || k.key == GLFW_KEY_ESCAPE) {
                a.leaveTextField = true;
                a.labelledMark = a.labelledMark || (enter && labelField);
            }
            continue; // the field's characters, not shortcuts
        }
        switch (k.key) {
        case GLFW_KEY_F1:
            toggles.help = !toggles.help;
            continue;
        case GLFW_KEY_ESCAPE:
            toggles.help = false;
            continue;
        case GLFW_KEY_H:
        case GLFW_KEY_F11:
            toggles.fullView = !toggles.fullView;
            continue;
        case GLFW_KEY_M:
            a.markAtPointer = true;
            continue;
        default:
            break;
        }
        if (widgetHeld)
            continue;
        const ToolControls before = tool;
        // A tool's key (its catalogue entry's letter) selects it.
        for (const ToolType* t : toolTypes())
            if (k.key == GLFW_KEY_A + (t->key[0] - 'A'))
                tool.kind = int(t->kind);
        switch (k.key) {
        case GLFW_KEY_LEFT_BRACKET:
            stepToolSize(tool, -1);
            break;
        case GLFW_KEY_RIGHT_BRACKET:
            stepToolSize(tool, +1);
            break;
        case GLFW_KEY_UP:
            tool.pushMm = steppedPush(tool.pushMm, +1.0f);
            break;
        case GLFW_KEY_DOWN:
            tool.pushMm = steppedPush(tool.pushMm, -1.0f);
            break;
        case GLFW_KEY_SPACE:
            a.playPause = !a.playPause;
            break;
        case GLFW_KEY_LEFT:
            --a.replaySteps;
            break;
        case GLFW_KEY_RIGHT:
            ++a.replaySteps;
            break;
        default:
            break;
        }
        a.toolChanged = a.toolChanged || tool.kind != before.kind ||
                        tool.diameterMm != before.diameterMm || tool.pushMm != before.pushMm;
    }
    return a;
}

void drawShortcutOverlay(const WindowToggles& toggles) {
    if (!toggles.help)
        return;
    const ImVec2 display = ImGui::GetIO().DisplaySize;
    ImGui::SetNextWindowPos(ImVec2(display.x * 0.5f, display.y * 0.5f), ImGuiCond_Always,
                            ImVec2(0.5f, 0.5f));
    ImGui::SetNextWindowBgAlpha(0.92f);
    ImGui::SetNextWindowFocus();
    const ImGuiWindowFlags flags = ImGuiWindowFlags_AlwaysAutoResize | ImGuiWindowFlags_NoCollapse |
                                   ImGuiWindowFlags_NoSavedSettings;
    if (ImGui::Begin("Shortcuts (F1 or Escape to close)", nullptr, flags)) {
        if (ImGui::BeginTable("keys", 2, ImGuiTableFlags_RowBg)) {
            for (const Shortcut& s : shortcuts()) {
                ImGui::TableNextRow();
                ImGui::TableSetColumnIndex(0);
                ImGui::TextColored(ImVec4(1.0f, 0.85f, 0.4f, 1.0f), "%s", s.keys);
                ImGui::TableSetColumnIndex(1);
                ImGui::TextUnformatted(s.does);
            }
            ImGui::EndTable();
        }
        ImGui::TextDisabled("Every control says what it does when the pointer rests on it.");
    }
    ImGui::End();
}

void ViewNote::draw(double now, float viewX, float viewY, float viewW) const {
    if (text.empty() || now >= until)
        return;
    ImDrawList* fg = ImGui::GetForegroundDrawList();
    const ImVec2 sz = ImGui::CalcTextSize(text.c_str(), nullptr, false, viewW - 40.0f);
    const ImVec2 at(viewX + (viewW - sz.x) * 0.5f, viewY + 48.0f);
    fg->AddRectFilled(ImVec2(at.x - 10, at.y - 6), ImVec2(at.x + sz.x + 10, at.y + sz.y + 6),
                      IM_COL32(20, 20, 24, 220), 6.0f);
    fg->AddText(nullptr, 0.0f, at, IM_COL32(255, 255, 255, 255), text.c_str(), nullptr,
                viewW - 40.0f);
}

} // namespace trephine::ui

// [Dirty boxes] panel: BB_screen of each image update as a fading overlay, and the recent list.
#include "ui/panels.h"

#include <imgui.h>

namespace trephine::ui {

void drawDirtyBoxPanel(DirtyBoxPanelState& state, const DirtyBoxHistory& boxes, double now) {
    if (!ImGui::Begin("Dirty boxes")) {
        ImGui::End();
        return;
    }
    ImGui::Checkbox("show BB_screen on the view", &state.overlay);
    itemTip("Outline each update's screen box on the view, fading over a second.");
    ImGui::SameLine();
    ImGui::TextDisabled("(%zu visible)", boxes.visible(now).size());
    if (ImGui::BeginTable("recent", 5,
                          ImGuiTableFlags_ScrollY | ImGuiTableFlags_RowBg |
                              ImGuiTableFlags_SizingStretchProp,
                          ImVec2(0, 0))) {
        ImGui::TableSetupScrollFreeze(0, 1);
        ImGui::TableSetupColumn("seq");
        ImGui::TableSetupColumn("rect x y w h");
        ImGui::TableSetupColumn("pixels");
        ImGui::TableSetupColumn("bytes");
        ImGui::TableSetupColumn("delivery");
        ImGui::TableHeadersRow();
        itemTip("seq: the update's number; rect: its screen box (DBI pixels, row 0 at the "
                "bottom);\nbytes: as sent; delivery: cause on the server to applied here "
                "(not drawn yet).");
        for (auto it = boxes.boxes.rbegin(); it != boxes.boxes.rend(); ++it) {
            ImGui::TableNextRow();
            ImGui::TableNextColumn();
            ImGui::Text("%u%s", it->sequence, it->full ? " full" : "");
            ImGui::TableNextColumn();
            ImGui::Text("%d %d %d %d", it->rect.x, it->rect.y, it->rect.w, it->rect.h);
            ImGui::TableNextColumn();
            ImGui::Text("%lld", (long long)it->rect.area());
            ImGui::TableNextColumn();
            ImGui::Text("%u", it->bytes);
            ImGui::TableNextColumn();
            if (it->latencyUs >= 0)
                ImGui::Text("%.1f ms", it->latencyUs * 1e-3);
            else
                ImGui::TextDisabled("-");
        }
        ImGui::EndTable();
    }
    ImGui::End();
}

void drawDirtyBoxOverlay(const DirtyBoxPanelState& state, const DirtyBoxHistory& boxes, double now,
                         float viewOriginX, float viewOriginY, int viewHeight) {
    if (!state.overlay)
        return;
    ImDrawList* dl = ImGui::GetBackgroundDrawList();
    // Outlines of the newest few, fading; only the newest is tinted, so the bone and the burr
    // under them stay visible while drilling adds boxes at one place.
    const std::vector<DirtyBoxHistory::Box> shown = boxes.overlay(now);
    for (size_t i = 0; i < shown.size(); ++i) {
        const auto& b = shown[i];
        const bool newest = i + 1 == shown.size();
        float a = boxes.alpha(b, now);
        float x0 = viewOriginX + float(b.rect.x);
        float y0 = viewOriginY + float(viewHeight - (b.rect.y + b.rect.h));
        ImVec2 p0(x0, y0), p1(x0 + float(b.rect.w), y0 + float(b.rect.h));
        if (newest)
            dl->AddRectFilled(p0, p1, ImGui::GetColorU32(ImVec4(1.0f, 0.85f, 0.1f, 0.08f * a)));
        dl->AddRect(p0, p1,
                    ImGui::GetColorU32(ImVec4(1.0f, 0.85f, 0.1f, (newest ? 0.9f : 0.4f) * a)), 0.0f,
                    0, newest ? 1.5f : 1.0f);
    }
}

} // namespace trephine::ui

// [Forces] panel: the server's force samples and the client's extrapolated force.
#include "ui/panels.h"

#include <cstdio>
#include <imgui.h>

namespace trephine::ui {

void drawForcesPanel(const ForceHistory& forces, double loopRateHz) {
    if (!ImGui::Begin("Forces")) {
        ImGui::End();
        return;
    }
    ImGui::Text("server f %.0f /s   F %.0f Hz", forces.serverRate(), loopRateHz);
    static const char* names[4] = {"x", "y", "z", "|F|"};
    for (int c : {3, 0, 1, 2}) {
        for (int which = 0; which < 2; ++which) {
            const auto& q = which == 0 ? forces.server : forces.extrapolated;
            auto v = ForceHistory::series(q, c);
            char label[48], overlay[48];
            std::snprintf(label, sizeof label, "%s %s", names[c], which == 0 ? "f" : "F");
            std::snprintf(overlay, sizeof overlay, "%.2f N", v.empty() ? 0.0f : v.back());
            ImGui::PlotLines(label, v.data(), int(v.size()), 0, overlay, FLT_MAX, FLT_MAX,
                             ImVec2(0.0f, c == 3 ? 40.0f : 24.0f));
        }
    }
    if (forces.server.empty())
        ImGui::TextDisabled("no force models yet (touch the bone)");
    ImGui::End();
}

} // namespace trephine::ui

// [Forces] panel: the server's force samples and the client's extrapolated force.
#include "ui/panels.h"

#include <cstdio>
#include <imgui.h>

namespace trephine::ui {

namespace {

// |F| and x/y/z of one participant's relayed samples, under its name in its tool's colour.
void drawParticipant(uint16_t id, const std::string& name, const ForceHistory& h) {
    static const char* names[4] = {"x", "y", "z", "|F|"};
    glm::vec4 c = participantColor(int(id));
    ImGui::PushStyleColor(ImGuiCol_Text, ImVec4(c.r, c.g, c.b, 1.0f));
    ImGui::PushStyleColor(ImGuiCol_PlotLines, ImVec4(c.r, c.g, c.b, 1.0f));
    ImGui::Text("%s   f %.0f /s", name.c_str(), h.serverRate());
    for (int comp : {3, 0, 1, 2}) {
        auto v = ForceHistory::series(h.server, comp);
        char label[48], overlay[48];
        std::snprintf(label, sizeof label, "%s f##client%u", names[comp], unsigned(id));
        std::snprintf(overlay, sizeof overlay, "%.2f N", v.empty() ? 0.0f : v.back());
        ImGui::PlotLines(label, v.data(), int(v.size()), 0, overlay, FLT_MAX, FLT_MAX,
                         ImVec2(0.0f, comp == 3 ? 40.0f : 24.0f));
    }
    ImGui::PopStyleColor(2);
}

} // namespace

void drawForcesPanel(const ForceHistory& forces, double loopRateHz,
                     const ParticipantForces* participants,
                     const std::map<uint16_t, net::ParticipantInfo>* roster) {
    static const std::map<uint16_t, net::ParticipantInfo> kNoRoster;
    if (!ImGui::Begin("Forces")) {
        ImGui::End();
        return;
    }
    // An instructor watches the participants first; its own pointer's forces follow, folded.
    if (participants) {
        ImGui::TextDisabled("participants (relayed by the server)");
        for (const auto& [id, h] : participants->byClient)
            drawParticipant(id, participantName(roster ? *roster : kNoRoster, id), h);
        if (participants->byClient.empty())
            ImGui::TextDisabled("no participant's force model in the last %.0f s",
                                participants->windowS);
        if (!ImGui::CollapsingHeader("your tool")) {
            ImGui::End();
            return;
        }
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

// [Forces] panel: the server's force samples and the client's extrapolated force.
#include "ui/panels.h"

#include <glm/geometric.hpp>

#include <cstdio>
#include <imgui.h>

namespace trephine::ui {

namespace {

constexpr double kPlotSeconds = 4.0; // every force plot shows the same last 4 s
constexpr int kPlotPoints = 200;

// One force plot over [now - kPlotSeconds, now] on a shared scale: |F| from 0, a component
// around 0, captioned with the newest sample.
void plotForce(const char* label, const std::deque<ForceHistory::Sample>& q, int component,
               double now, float scale) {
    const std::vector<float> v =
        ForceHistory::resample(q, component, now - kPlotSeconds, now, kPlotPoints);
    char overlay[48];
    if (q.empty())
        std::snprintf(overlay, sizeof overlay, "-");
    else
        std::snprintf(overlay, sizeof overlay, "%.2f N",
                      component >= 3 ? glm::length(q.back().f) : q.back().f[component]);
    const bool magnitude = component >= 3;
    ImGui::PlotLines(label, v.data(), int(v.size()), 0, overlay, magnitude ? 0.0f : -scale, scale,
                     ImVec2(0.0f, magnitude ? 40.0f : 24.0f));
}

// The time and force axes all plots share, in words.
void scaleLine(float scale) {
    ImGui::TextDisabled("last %.0f s; |F| 0-%g N, x y z +-%g N", kPlotSeconds, double(scale),
                        double(scale));
}

// |F| and x/y/z of one participant's relayed samples, under its name in its tool's colour.
void drawParticipant(uint16_t id, const std::string& name, glm::vec4 c, const ForceHistory& h,
                     double now) {
    static const char* names[4] = {"x", "y", "z", "|F|"};
    ImGui::PushStyleColor(ImGuiCol_Text, ImVec4(c.r, c.g, c.b, 1.0f));
    ImGui::PushStyleColor(ImGuiCol_PlotLines, ImVec4(c.r, c.g, c.b, 1.0f));
    ImGui::Text("%s   f %.0f /s", name.c_str(), h.serverRate());
    const float scale = h.scaleN();
    for (int comp : {3, 0, 1, 2}) {
        char label[48];
        std::snprintf(label, sizeof label, "%s f##client%u", names[comp], unsigned(id));
        plotForce(label, h.server, comp, now, scale);
    }
    ImGui::PopStyleColor(2);
    scaleLine(scale);
}

} // namespace

void drawForcesPanel(const ForceHistory& forces, double loopRateHz, double now,
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
            drawParticipant(id, participantName(roster ? *roster : kNoRoster, id),
                            participantColor(roster ? *roster : kNoRoster, id), h, now);
        if (participants->byClient.empty())
            ImGui::TextDisabled("no participant's force model in the last %.0f s",
                                participants->windowS);
        if (!ImGui::CollapsingHeader("your tool")) {
            ImGui::End();
            return;
        }
    }
    const float scale = forces.scaleN();
    ImGui::Text("server f %.0f /s   F %.0f Hz", forces.serverRate(), loopRateHz);
    ImGui::SameLine();
    scaleLine(scale);
    static const char* names[4] = {"x", "y", "z", "|F|"};
    for (int c : {3, 0, 1, 2})
        for (int which = 0; which < 2; ++which) {
            char label[48];
            std::snprintf(label, sizeof label, "%s %s", names[c], which == 0 ? "f" : "F");
            plotForce(label, which == 0 ? forces.server : forces.extrapolated, c, now, scale);
        }
    if (forces.server.empty())
        ImGui::TextDisabled("no force models yet (touch the bone)");
    ImGui::End();
}

} // namespace trephine::ui

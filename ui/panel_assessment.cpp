// [Assessment] panel: the server's live metrics (AssessmentSnapshot): a trainee's own, an
// instructor's everyone's. And the safety warning where the trainee looks: a banner across the
// top of the view in the zone's colour with the structure and the distance; the tool takes the
// colour too (trainer_app.cpp), and the Session panel shows each participant's zone.
#include "ui/panels.h"

#include <algorithm>
#include <cstdio>
#include <imgui.h>

namespace trephine::ui {

namespace {

ImU32 zoneU32(net::Zone z) {
    const glm::vec4 c = zoneColor(z);
    return IM_COL32(int(c.r * 255.0f + 0.5f), int(c.g * 255.0f + 0.5f), int(c.b * 255.0f + 0.5f),
                    255);
}

// A small square of the zone's colour, then its name.
void zoneSwatch(net::Zone z) {
    const ImVec2 at = ImGui::GetCursorScreenPos();
    const float h = ImGui::GetTextLineHeight();
    ImGui::GetWindowDrawList()->AddRectFilled(at, ImVec2(at.x + h, at.y + h), zoneU32(z));
    ImGui::Dummy(ImVec2(h, h));
    ImGui::SameLine();
    ImGui::TextUnformatted(net::zoneName(z));
}

void drawFigures(const net::ParticipantFigures& f, const std::string& name) {
    zoneSwatch(f.zone);
    ImGui::SameLine();
    ImGui::Text("%s: %.0f s, drilling %.1f s", name.c_str(), double(f.sessionS),
                double(f.drillingS));
    if (ImGui::BeginTable("##structures", 4, ImGuiTableFlags_SizingStretchSame)) {
        ImGui::TableNextColumn();
        ImGui::TextDisabled("structure");
        ImGui::TableNextColumn();
        ImGui::TextDisabled("now mm");
        ImGui::TableNextColumn();
        ImGui::TextDisabled("closest");
        ImGui::TableNextColumn();
        ImGui::TextDisabled("contacts");
        for (const net::StructureFigures& s : f.structures) {
            ImGui::TableNextColumn();
            ImGui::TextUnformatted(s.name.c_str());
            ImGui::TableNextColumn();
            ImGui::Text("%.1f", double(s.distanceMm));
            ImGui::TableNextColumn();
            ImGui::Text("%.1f", double(s.closestMm));
            ImGui::TableNextColumn();
            ImGui::Text("%u", unsigned(s.contacts));
        }
        ImGui::EndTable();
    }
    float removed = 0;
    for (const net::MaterialFigure& m : f.removed)
        removed += m.mm3;
    ImGui::Text("bone %.0f mm3   warnings %u   strokes %u", double(removed), unsigned(f.warnings),
                unsigned(f.strokes));
    ImGui::Text("force max %.2f N, mean %.2f N", double(f.maxForceN), double(f.meanForceN));
    ImGui::Text("path %.0f mm at %.1f mm/s", double(f.pathLengthMm), double(f.meanSpeedMmS));
    ImGui::TextDisabled("time in caution %.1f s, danger %.1f s, violation %.1f s",
                        double(f.zoneS[1]), double(f.zoneS[2]), double(f.zoneS[3]));
    for (const net::ToolFigure& t : f.tools)
        ImGui::TextDisabled("%s: %.1f s", t.tool.c_str(), double(t.seconds));
}

} // namespace

glm::vec4 zoneColor(net::Zone z) {
    switch (z) {
    case net::Zone::Clear:
        return {0.20f, 0.70f, 0.30f, 1.0f};
    case net::Zone::Caution:
        return {0.95f, 0.80f, 0.10f, 1.0f};
    case net::Zone::Danger:
        return {1.00f, 0.45f, 0.05f, 1.0f};
    case net::Zone::Violation:
        return {0.85f, 0.05f, 0.10f, 1.0f};
    }
    return {1, 1, 1, 1};
}

std::optional<glm::vec4> toolZoneColor(const net::ClientSnapshot& snap, uint16_t id) {
    auto it = snap.warnings.find(id);
    if (id == 0 || it == snap.warnings.end() || it->second.zone == net::Zone::Clear)
        return std::nullopt;
    return zoneColor(it->second.zone);
}

void drawZoneBadge(const net::ClientSnapshot& snap, uint16_t id) {
    auto it = snap.warnings.find(id);
    if (it == snap.warnings.end() || it->second.zone == net::Zone::Clear)
        return;
    // Its own line under the participant's row: the 380-pixel panel cuts a long row off.
    const glm::vec4 c = zoneColor(it->second.zone);
    ImGui::TextColored(ImVec4(c.r, c.g, c.b, 1.0f), "    %s: %s %.1f mm",
                       net::zoneName(it->second.zone), it->second.structure.c_str(),
                       double(it->second.distanceMm));
}

void drawSafetyBanner(const net::ClientSnapshot& snap, int viewSize) {
    const uint16_t self = snap.welcome ? snap.welcome->clientId : 0;
    // Our own tool first; an instructor also sees whoever else is in danger or worse.
    std::vector<std::pair<const net::SafetyWarning*, std::string>> lines;
    for (const auto& [id, w] : snap.warnings) {
        if (w.zone == net::Zone::Clear || (id != self && w.zone < net::Zone::Danger))
            continue;
        char text[160];
        const char* what = w.zone == net::Zone::Violation ? "CONTACT"
                           : w.zone == net::Zone::Danger  ? "DANGER"
                                                          : "CAUTION";
        std::snprintf(text, sizeof text, "%s%s%s: %s %.1f mm",
                      id == self ? "" : participantName(snap.participants, id).c_str(),
                      id == self ? "" : " - ", what, w.structure.c_str(),
                      double(std::max(0.0f, w.distanceMm)));
        if (id == self)
            lines.insert(lines.begin(), {&w, text});
        else
            lines.push_back({&w, text});
    }
    ImDrawList* fg = ImGui::GetForegroundDrawList();
    float y = 8.0f;
    for (const auto& [w, text] : lines) {
        const ImVec2 sz = ImGui::CalcTextSize(text.c_str());
        const float h = sz.y + 14.0f;
        fg->AddRectFilled(ImVec2(8.0f, y), ImVec2(float(viewSize) - 8.0f, y + h), zoneU32(w->zone));
        const ImU32 ink =
            w->zone == net::Zone::Caution ? IM_COL32(0, 0, 0, 255) : IM_COL32(255, 255, 255, 255);
        fg->AddText(ImVec2((float(viewSize) - sz.x) * 0.5f, y + 7.0f), ink, text.c_str());
        y += h + 4.0f;
    }
}

void drawAssessmentPanel(const net::ClientSnapshot& snap) {
    if (ImGui::Begin("Assessment")) {
        if (snap.assessment.list.empty())
            ImGui::TextDisabled("No figures from the server yet.");
        const uint16_t self = snap.welcome ? snap.welcome->clientId : 0;
        for (const net::ParticipantFigures& f : snap.assessment.list) {
            ImGui::PushID(int(f.clientId));
            drawFigures(f, f.clientId == self ? std::string("you")
                                              : participantName(snap.participants, f.clientId));
            ImGui::Separator();
            ImGui::PopID();
        }
    }
    ImGui::End();
}

} // namespace trephine::ui

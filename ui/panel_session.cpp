// [Session] panel: who is here, which tool, and the connection.
#include "ui/panels.h"

#include "libsim/tool.h"

#include <algorithm>
#include <cstdio>
#include <imgui.h>

namespace trephine::ui {

float steppedPush(float pushMm, float steps) {
    return std::clamp(pushMm + steps * kPushStepMm, kPushMinMm, kPushMaxMm);
}

namespace {

float clampOrLowest(float v, float lo, float hi) {
    return v >= lo ? std::min(v, hi) : lo; // NaN fails v >= lo
}

} // namespace

ToolControls withinRanges(ToolControls c) {
    c.burrMm = clampOrLowest(c.burrMm, kBurrMinDiameterMm, kBurrMaxDiameterMm);
    c.speed = clampOrLowest(c.speed, 0.0f, 1.0f);
    c.pushMm = clampOrLowest(c.pushMm, kPushMinMm, kPushMaxMm);
    return c;
}

glm::vec4 participantColor(int index) {
    static const glm::vec4 k[] = {{0.20f, 0.45f, 0.85f, 1}, {0.85f, 0.35f, 0.20f, 1},
                                  {0.30f, 0.70f, 0.30f, 1}, {0.75f, 0.30f, 0.75f, 1},
                                  {0.95f, 0.55f, 0.70f, 1}, {0.25f, 0.75f, 0.80f, 1}};
    constexpr size_t n = sizeof k / sizeof k[0];
    // 0 is this client's own colour; every other index cycles through the rest.
    return index <= 0 ? k[0] : k[1 + size_t(index - 1) % (n - 1)];
}

std::string participantName(const std::map<uint16_t, net::ParticipantInfo>& roster, uint16_t id) {
    auto it = roster.find(id);
    if (it == roster.end() || it->second.name.empty())
        return "client " + std::to_string(id);
    return it->second.name;
}

uint16_t takenOverBy(const std::map<uint16_t, net::ParticipantInfo>& roster, uint16_t id) {
    auto it = roster.find(id);
    return it == roster.end() ? 0 : it->second.takenOverBy;
}

uint16_t heldBy(const std::map<uint16_t, net::ParticipantInfo>& roster, uint16_t instructor) {
    if (instructor == 0)
        return 0;
    for (const auto& [id, p] : roster)
        if (p.takenOverBy == instructor)
            return id;
    return 0;
}

glm::vec4 markColor() {
    return {1.0f, 0.84f, 0.0f, 1.0f};
}

std::optional<uint16_t>
ViewAsControls::due(int attempt, uint16_t self,
                    const std::map<uint16_t, net::ParticipantInfo>& participants) {
    if (scripted.empty() || scriptedOnAttempt == attempt)
        return std::nullopt;
    for (const auto& [id, p] : participants)
        if (id != self && (p.name == scripted || std::to_string(id) == scripted)) {
            scriptedOnAttempt = attempt;
            return id;
        }
    return std::nullopt;
}

void drawSessionPanel(const net::ClientSnapshot& snap, ToolControls& tool, MarkControls& marks,
                      TakeOverControls& takeOver, ViewAsControls& viewAs, const std::string& role,
                      const std::string& address, const std::string& name) {
    if (!ImGui::Begin("Session")) {
        ImGui::End();
        return;
    }
    ImVec4 stateColor = snap.state == net::LinkState::Connected ? ImVec4(0.4f, 0.9f, 0.4f, 1)
                                                                : ImVec4(1.0f, 0.6f, 0.2f, 1);
    ImGui::TextColored(stateColor, "%s", net::linkStateName(snap.state));
    ImGui::SameLine();
    ImGui::Text("%s  (attempt %d)", address.c_str(), snap.attempts);
    if (!snap.closeReason.empty())
        ImGui::TextWrapped("last close: %s", snap.closeReason.c_str());
    ImGui::Text("%s '%s'", role.c_str(), name.c_str());
    if (snap.welcome)
        ImGui::Text("client %u on %s", unsigned(snap.welcome->clientId),
                    snap.welcome->volumeName.c_str());
    // Everyone the server lists, this client first; tools as last relayed.
    const uint16_t self = snap.welcome ? snap.welcome->clientId : 0;
    ImGui::Text("participants: you + %zu", snap.participants.empty()
                                               ? snap.others.size()
                                               : snap.participants.size() - (self != 0));
    for (const auto& [id, p] : snap.participants) {
        if (id == self)
            continue;
        glm::vec4 c = participantColor(int(id));
        // View as (instructors): the participant's camera in this window, or back to our own.
        if (viewAs.canViewAs) {
            ImGui::PushID(int(id) + 0x10000);
            if (snap.viewingAs == id) {
                if (ImGui::SmallButton("own view"))
                    viewAs.asked = uint16_t(0);
            } else if (ImGui::SmallButton("view as")) {
                viewAs.asked = id;
            }
            ImGui::SameLine();
            ImGui::PopID();
        }
        // A trainee's take-over control leads its row, so a narrow (380-pixel) panel shows it
        // whole.
        if (p.role == net::Role::Trainee) {
            ImGui::PushID(int(id));
            if (p.takenOverBy == self && self != 0) {
                if (ImGui::SmallButton("hand back"))
                    takeOver.asked = uint16_t(0);
                ImGui::SameLine();
            } else if (p.takenOverBy != 0) {
                ImGui::TextDisabled("held by %s",
                                    participantName(snap.participants, p.takenOverBy).c_str());
                ImGui::SameLine();
            } else if (takeOver.canTakeOver) {
                if (ImGui::SmallButton("take over"))
                    takeOver.asked = id;
                ImGui::SameLine();
            }
            ImGui::PopID();
        }
        ImGui::TextColored(ImVec4(c.r, c.g, c.b, 1), "  %s  %s, %s",
                           participantName(snap.participants, id).c_str(),
                           p.role == net::Role::Instructor ? "instructor" : "trainee",
                           p.sync == net::Sync::Volume ? "volume" : "dbi");
        auto t = snap.others.find(id);
        if (t != snap.others.end()) {
            ImGui::SameLine();
            ImGui::TextColored(ImVec4(c.r, c.g, c.b, 1), "  %s %.0f mm%s",
                               t->second.toolKind == uint8_t(ToolKind::Perforator) ? "perforator"
                                                                                   : "burr",
                               double(t->second.diameterMm), t->second.drilling ? " drilling" : "");
        }
        drawZoneBadge(snap, id); // the assessment's zone of its tool (instructors hear of all)
    }
    // Tools of ids the roster does not list yet (its message may trail the first relays).
    for (const auto& [id, t] : snap.others) {
        if (snap.participants.count(id))
            continue;
        glm::vec4 c = participantColor(int(id));
        ImGui::TextColored(ImVec4(c.r, c.g, c.b, 1), "  client %u: %s %.0f mm%s", unsigned(id),
                           t.toolKind == uint8_t(ToolKind::Perforator) ? "perforator" : "burr",
                           double(t.diameterMm), t.drilling ? " drilling" : "");
    }
    // Marks: everyone sees the list; an instructor places, removes and clears them.
    const glm::vec4 mc = markColor();
    const ImVec4 markCol(mc.r, mc.g, mc.b, 1.0f);
    ImGui::Text("marks: %zu", snap.annotations.size());
    if (marks.canMark) {
        ImGui::SameLine();
        if (ImGui::SmallButton("mark the pointer [M]"))
            marks.addAtPointer = true;
        if (!snap.annotations.empty()) {
            ImGui::SameLine();
            if (ImGui::SmallButton("clear marks"))
                marks.clearAll = true;
        }
        if (marks.undoable) {
            ImGui::SameLine();
            char undo[48];
            std::snprintf(undo, sizeof undo, "undo removal (%zu)", marks.undoable);
            if (ImGui::SmallButton(undo))
                marks.undo = true;
        }
        ImGui::InputTextWithHint("##label", "label of the next mark", marks.label,
                                 sizeof marks.label);
    }
    for (const net::AnnotationInfo& a : snap.annotations) {
        ImGui::TextColored(markCol, "  %u %s", unsigned(a.id), a.label.c_str());
        ImGui::SameLine();
        ImGui::TextDisabled("by %s", participantName(snap.participants, a.author).c_str());
        if (marks.canMark) {
            ImGui::SameLine();
            ImGui::PushID(int(a.id));
            if (ImGui::SmallButton("remove"))
                marks.removeId = a.id;
            ImGui::PopID();
        }
    }
    ImGui::Separator();
    ImGui::RadioButton("burr [B]", &tool.kind, 0);
    ImGui::SameLine();
    ImGui::RadioButton("perforator [P]", &tool.kind, 1);
    // AlwaysClamp: a value typed in (Ctrl+click) stays in the range too (the window clamps again).
    // The sliders leave room for the longest label, so no label is cut off.
    const ImGuiSliderFlags clamp = ImGuiSliderFlags_AlwaysClamp;
    ImGui::PushItemWidth(
        -(ImGui::CalcTextSize("depth mm [wheel]").x + ImGui::GetStyle().ItemInnerSpacing.x));
    ImGui::SliderFloat("burr mm [ ]", &tool.burrMm, kBurrMinDiameterMm, kBurrMaxDiameterMm, "%.1f",
                       clamp);
    ImGui::SliderFloat("speed", &tool.speed, 0.0f, 1.0f, "%.2f", clamp);
    ImGui::SliderFloat("depth mm [wheel]", &tool.pushMm, kPushMinMm, kPushMaxMm, "%.1f", clamp);
    ImGui::PopItemWidth();
    if (snap.viewingAs)
        ImGui::TextColored(ImVec4(0.5f, 0.8f, 1, 1), "viewing as %s",
                           participantName(snap.participants, snap.viewingAs).c_str());
    const uint16_t holder = takenOverBy(snap.participants, self);
    const uint16_t held = takeOver.canTakeOver ? heldBy(snap.participants, self) : 0;
    if (held)
        ImGui::TextColored(ImVec4(1, 0.7f, 0.3f, 1),
                           "you hold %s: your drill cuts, theirs is paused",
                           participantName(snap.participants, held).c_str());
    if (holder)
        ImGui::TextColored(ImVec4(1, 0.7f, 0.3f, 1), "%s has taken over: your drill is paused",
                           participantName(snap.participants, holder).c_str());
    else if (tool.canDrill)
        ImGui::TextColored(tool.drilling ? ImVec4(1, 0.4f, 0.3f, 1) : ImVec4(0.6f, 0.6f, 0.6f, 1),
                           tool.drilling ? "DRILLING" : "hold the left button to drill");
    else
        ImGui::TextDisabled("pointer only: take over a trainee to drill");
    ImGui::End();
}

} // namespace trephine::ui

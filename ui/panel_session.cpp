// [Session] panel: who is here, which tool, and the connection.
#include "ui/panels.h"

#include "libsim/tool_catalogue.h"

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

std::array<float, kToolKindCount> ToolControls::defaultDiameters() {
    std::array<float, kToolKindCount> d{};
    for (const ToolType* t : toolTypes())
        d[size_t(t->kind)] = t->defaultDiameterMm;
    return d;
}

ToolKind selectedKind(const ToolControls& c) {
    return c.kind >= 0 && c.kind < kToolKindCount ? ToolKind(c.kind) : ToolKind::Burr;
}

float selectedDiameter(const ToolControls& c) {
    const SizeRange r = sizeRange(selectedKind(c));
    return clampOrLowest(c.diameter(selectedKind(c)), r.minMm, r.maxMm);
}

SizeRange sizeRange(ToolKind kind) {
    const ToolType& t = toolType(kind);
    return {t.minDiameterMm, t.maxDiameterMm, t.stepMm};
}

void stepToolSize(ToolControls& c, int steps) {
    const SizeRange r = sizeRange(selectedKind(c));
    float& mm = c.diameter(selectedKind(c));
    mm =
        std::clamp(clampOrLowest(mm, r.minMm, r.maxMm) + float(steps) * r.stepMm, r.minMm, r.maxMm);
}

void itemTip(const char* text) {
    if (ImGui::IsItemHovered())
        ImGui::SetTooltip("%s", text);
}

ToolControls withinRanges(ToolControls c) {
    for (const ToolType* t : toolTypes())
        c.diameter(t->kind) =
            clampOrLowest(c.diameter(t->kind), t->minDiameterMm, t->maxDiameterMm);
    c.speed = clampOrLowest(c.speed, 0.0f, 1.0f);
    c.pushMm = clampOrLowest(c.pushMm, kPushMinMm, kPushMaxMm);
    return c;
}

glm::vec4 toColour(net::Rgb8 c) {
    return {c.r / 255.0f, c.g / 255.0f, c.b / 255.0f, 1.0f};
}

glm::vec4 participantColor(const std::map<uint16_t, net::ParticipantInfo>& roster, uint16_t id) {
    auto it = roster.find(id);
    return it == roster.end() ? glm::vec4(0.7f, 0.7f, 0.7f, 1.0f) : toColour(it->second.colour);
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

namespace {

// The tool's rows: which tool (one button per catalogue entry), its size (the selected tool's
// range), speed and depth.
void toolRows(ToolControls& tool) {
    for (const ToolType* t : toolTypes()) {
        if (t != toolTypes().front())
            ImGui::SameLine();
        const std::string label = std::string(t->name) + " [" + t->key + "]";
        ImGui::RadioButton(label.c_str(), &tool.kind, int(t->kind));
        itemTip(t->tip);
    }
    // AlwaysClamp: a value typed in (Ctrl+click) stays in the range too (the window clamps again).
    // The sliders leave room for the longest label, so no label is cut off.
    const ImGuiSliderFlags clamp = ImGuiSliderFlags_AlwaysClamp;
    ImGui::PushItemWidth(
        -(ImGui::CalcTextSize("perforator mm [ ]").x + ImGui::GetStyle().ItemInnerSpacing.x));
    const ToolType& type = toolType(selectedKind(tool));
    const SizeRange range = sizeRange(type.kind);
    const std::string label = std::string(type.name) + " mm [ ]";
    ImGui::SliderFloat(label.c_str(), &tool.diameter(type.kind), range.minMm, range.maxMm,
                       range.stepMm < 1.0f ? "%.1f" : "%.0f", clamp);
    itemTip("The selected tool's diameter; [ and ] step it.");
    ImGui::SliderFloat("speed", &tool.speed, 0.0f, 1.0f, "%.2f", clamp);
    itemTip("Spindle speed, 0-1: faster cuts faster.");
    ImGui::SliderFloat("depth mm [wheel]", &tool.pushMm, kPushMinMm, kPushMaxMm, "%.1f", clamp);
    itemTip("How far the tip is pushed below the bone under the pointer. Wheel up or Up: deeper; "
            "wheel down or Down: shallower.");
    ImGui::PopItemWidth();
}

// One line, always drawn: who drills (taken over, holding, or the button's state).
void drillLine(const net::ClientSnapshot& snap, const ToolControls& tool, uint16_t self,
               bool canTakeOver) {
    const uint16_t holder = takenOverBy(snap.participants, self);
    const uint16_t held = canTakeOver ? heldBy(snap.participants, self) : 0;
    const ImVec4 warn(1, 0.7f, 0.3f, 1);
    if (holder)
        ImGui::TextColored(warn, "%s has taken over: your drill is paused",
                           participantName(snap.participants, holder).c_str());
    else if (held)
        ImGui::TextColored(warn, "you hold %s: your drill cuts, theirs is paused",
                           participantName(snap.participants, held).c_str());
    else if (snap.replay)
        ImGui::TextDisabled("a replay: your tool points, it does not cut");
    else if (tool.canDrill)
        ImGui::TextColored(tool.drilling ? ImVec4(1, 0.4f, 0.3f, 1) : ImVec4(0.6f, 0.6f, 0.6f, 1),
                           tool.drilling ? "DRILLING" : "hold the left button to drill");
    else
        ImGui::TextDisabled("pointer only: take over a trainee to drill");
}

// Who feels whose forces and who guides whose hand (HandLinks), one line each, so that a trainee
// knows; an instructor's own links read "you".
void handLinkLines(const net::ClientSnapshot& snap, uint16_t self) {
    const std::optional<net::HandLinks> links = snap.newest.get<net::HandLinks>();
    if (!links)
        return;
    auto name = [&](uint16_t id) {
        return id == self ? std::string("you") : participantName(snap.participants, id);
    };
    const ImVec4 c(0.75f, 0.6f, 1.0f, 1);
    for (const net::HandLink& l : links->list) {
        const char* s = l.instructor == self ? "" : "s";
        if (l.feels)
            ImGui::TextColored(c, "%s feel%s %s forces", name(l.instructor).c_str(), s,
                               l.feels == self ? "your" : (name(l.feels) + "'s").c_str());
        const uint16_t held = heldBy(snap.participants, l.instructor);
        if (l.guides && held)
            ImGui::TextColored(c, "%s guide%s %s hand", name(l.instructor).c_str(), s,
                               held == self ? "your" : (name(held) + "'s").c_str());
    }
}

// An instructor's own link in force (none: feels nobody, guides nobody).
net::HandLink ownHandLink(const net::ClientSnapshot& snap, uint16_t self) {
    if (const std::optional<net::HandLinks> links = snap.newest.get<net::HandLinks>())
        for (const net::HandLink& l : links->list)
            if (l.instructor == self)
                return l;
    return {self, 0, false};
}

// [Instructor] Feel a participant's forces on the force device; guide the held trainee's hand.
void handLinkButtons(const net::ClientSnapshot& snap, uint16_t id, const net::ParticipantInfo& p,
                     uint16_t self, TakeOverControls& takeOver) {
    net::HandLink link = ownHandLink(snap, self);
    ImGui::PushID(int(id) + 0x30000);
    if (ImGui::SmallButton(link.feels == id ? "stop feeling" : "feel")) {
        link.feels = link.feels == id ? 0 : id;
        takeOver.requests.push_back(net::HandLinks{{link}});
    }
    itemTip("Your force device feels this participant's drill on the bone (their force models).");
    ImGui::SameLine();
    if (p.takenOverBy == self && self != 0) {
        if (ImGui::SmallButton(link.guides ? "free hand" : "guide hand")) {
            link.guides = !link.guides;
            takeOver.requests.push_back(net::HandLinks{{link}});
        }
        itemTip("A bounded spring pulls the trainee's force device toward your tool.");
        ImGui::SameLine();
    }
    ImGui::PopID();
}

// An instructor's mark controls: the same buttons every frame (greyed when they do nothing), so
// none moves when marks arrive.
void markControlRows(const net::ClientSnapshot& snap, MarkControls& marks) {
    if (ImGui::SmallButton("mark the pointer [M]"))
        marks.addAtPointer = true;
    itemTip("Mark the bone last under the pointer for everyone, with the label below.");
    ImGui::SameLine();
    ImGui::BeginDisabled(snap.annotations.empty());
    if (ImGui::SmallButton("clear marks"))
        marks.clearAll = true;
    ImGui::EndDisabled();
    itemTip("Remove every mark (undo puts them back).");
    ImGui::SameLine();
    ImGui::BeginDisabled(marks.undoable == 0);
    char undo[48];
    std::snprintf(undo, sizeof undo, "undo removal (%zu)###undo", marks.undoable);
    if (ImGui::SmallButton(undo))
        marks.undo = true;
    ImGui::EndDisabled();
    itemTip("Put back the marks the last removal took.");
    ImGui::SetNextItemWidth(-1.0f);
    ImGui::InputTextWithHint("##label", "label of the next mark (Enter places it)", marks.label,
                             sizeof marks.label);
    marks.labelActive = ImGui::IsItemActive();
    itemTip("The next mark's label. Enter places it at the bone last under the pointer; Escape "
            "leaves the field.");
}

// One participant's row: take-over and view-as buttons first (a narrow panel shows them whole),
// then the name in its colour, and its tool.
void participantRow(const net::ClientSnapshot& snap, uint16_t id, const net::ParticipantInfo& p,
                    uint16_t self, TakeOverControls& takeOver, ViewAsControls& viewAs) {
    const glm::vec4 c = participantColor(snap.participants, id);
    if (viewAs.canViewAs) {
        ImGui::PushID(int(id) + 0x10000);
        if (snap.viewingAs == id) {
            if (ImGui::SmallButton("own view"))
                viewAs.asked = uint16_t(0);
            itemTip("Back to your own camera.");
        } else if (ImGui::SmallButton("view as")) {
            viewAs.asked = id;
        } else {
            itemTip("Watch through this participant's camera.");
        }
        ImGui::SameLine();
        ImGui::PopID();
    }
    if (p.role == net::Role::Trainee) {
        ImGui::PushID(int(id));
        if (p.takenOverBy == self && self != 0) {
            if (ImGui::SmallButton("hand back"))
                takeOver.asked = uint16_t(0);
            itemTip("Give the drill back to the trainee.");
            ImGui::SameLine();
        } else if (p.takenOverBy != 0) {
            ImGui::TextDisabled("held by %s",
                                participantName(snap.participants, p.takenOverBy).c_str());
            ImGui::SameLine();
        } else if (takeOver.canTakeOver) {
            if (ImGui::SmallButton("take over"))
                takeOver.asked = id;
            itemTip("Pause this trainee's drill and cut with yours instead.");
            ImGui::SameLine();
        }
        ImGui::PopID();
    }
    if (takeOver.canTakeOver)
        handLinkButtons(snap, id, p, self, takeOver);
    // Removing is an instructor's too (docs/security.md): refused from that address with its
    // role's code until "let removed rejoin".
    if (takeOver.canTakeOver) {
        ImGui::PushID(int(id) + 0x20000);
        if (ImGui::SmallButton("remove"))
            takeOver.remove = net::Remove{net::Remove::Op::Remove, id};
        itemTip("Send this participant away; they cannot rejoin with their code until allowed.");
        ImGui::SameLine();
        ImGui::PopID();
    }
    ImGui::TextColored(ImVec4(c.r, c.g, c.b, 1), "%s  %s, %s",
                       participantName(snap.participants, id).c_str(),
                       p.role == net::Role::Instructor ? "instructor" : "trainee",
                       p.sync == net::Sync::Volume ? "volume" : "dbi");
    auto t = snap.others.find(id);
    if (t != snap.others.end()) {
        ImGui::SameLine();
        ImGui::TextColored(ImVec4(c.r, c.g, c.b, 1), " %s %.0f mm%s",
                           toolType(ToolKind(t->second.toolKind)).name,
                           double(t->second.diameterMm), t->second.drilling ? " drilling" : "");
    }
    drawZoneBadge(snap, id); // the assessment's zone of its tool (instructors hear of all)
}

// An instructor's codes to read out, each with its button for a new one (the old code then joins
// nobody, and those removed may rejoin with the new one). Drawn only when the server sent them.
void codeRows(const net::Codes& codes, TakeOverControls& takeOver) {
    const struct {
        net::Role role;
        const std::string& code;
        const char* label;
        const char* button;
    } rows[] = {
        {net::Role::Trainee, codes.trainee, "trainee code:", "new trainee code"},
        {net::Role::Instructor, codes.instructor, "instructor code:", "new instructor code"}};
    // Buttons first, as in the participant rows; the labels in one column after the wider one.
    const ImGuiStyle& style = ImGui::GetStyle();
    const float labelX = ImGui::GetCursorPosX() + ImGui::CalcTextSize(rows[1].button).x +
                         2 * style.FramePadding.x + style.ItemSpacing.x;
    for (const auto& r : rows) {
        if (ImGui::SmallButton(r.button))
            takeOver.newCode = r.role;
        itemTip("Issue a new code: the old one no longer joins (those in stay), and anyone removed "
                "may rejoin with the new one.");
        ImGui::SameLine(labelX);
        ImGui::TextDisabled("%s", r.label);
        ImGui::SameLine();
        ImGui::TextUnformatted(r.code.c_str());
    }
}

} // namespace

// Fixed rows first (the link, the tool, the drill's state, an instructor's mark controls), the
// lists that grow as people and marks arrive below them: nothing moves under the pointer.
void drawSessionPanel(const net::ClientSnapshot& snap, ToolControls& tool, MarkControls& marks,
                      TakeOverControls& takeOver, ViewAsControls& viewAs, const std::string& role,
                      const std::string& address, const std::string& name) {
    if (!ImGui::Begin("Session")) {
        ImGui::End();
        return;
    }
    const ImVec4 stateColor = snap.state == net::LinkState::Connected ? ImVec4(0.4f, 0.9f, 0.4f, 1)
                                                                      : ImVec4(1.0f, 0.6f, 0.2f, 1);
    ImGui::TextColored(stateColor, "%s", net::linkStateName(snap.state));
    ImGui::SameLine();
    ImGui::Text("%s  (attempt %d)", address.c_str(), snap.attempts);
    if (!snap.closeReason.empty())
        itemTip(("last close: " + snap.closeReason).c_str());
    const uint16_t self = snap.welcome ? snap.welcome->clientId : 0;
    const glm::vec4 own = participantColor(snap.participants, self);
    ImGui::TextColored(ImVec4(own.r, own.g, own.b, 1), "%s '%s'", role.c_str(), name.c_str());
    itemTip("You, in the colour everyone sees you in (the server's).");
    ImGui::SameLine();
    if (snap.welcome)
        ImGui::TextDisabled("client %u on %s", unsigned(self), snap.welcome->volumeName.c_str());
    else
        ImGui::TextDisabled("not welcomed yet");
    ImGui::Separator();
    toolRows(tool);
    drillLine(snap, tool, self, takeOver.canTakeOver);
    handLinkLines(snap, self);
    if (snap.viewingAs)
        ImGui::TextColored(ImVec4(0.5f, 0.8f, 1, 1), "viewing as %s",
                           participantName(snap.participants, snap.viewingAs).c_str());
    else
        ImGui::TextDisabled("your own view");
    if (marks.canMark)
        markControlRows(snap, marks);
    if (takeOver.canTakeOver && snap.codes)
        codeRows(*snap.codes, takeOver);
    ImGui::Separator();
    // Everyone the server lists but us, in client id order (a newcomer's row comes last).
    ImGui::Text("participants: you + %zu", snap.participants.empty()
                                               ? snap.others.size()
                                               : snap.participants.size() - (self != 0));
    for (const auto& [id, p] : snap.participants)
        if (id != self)
            participantRow(snap, id, p, self, takeOver, viewAs);
    if (takeOver.canTakeOver && ImGui::SmallButton("let removed rejoin"))
        takeOver.remove = net::Remove{net::Remove::Op::AllowRejoin, 0};
    itemTip("Let everyone removed from the session join again with their code.");
    // Tools of ids the roster does not list yet (its message may trail the first relays).
    for (const auto& [id, t] : snap.others) {
        if (snap.participants.count(id))
            continue;
        ImGui::TextDisabled("client %u: %s %.0f mm%s", unsigned(id),
                            toolType(ToolKind(t.toolKind)).name, double(t.diameterMm),
                            t.drilling ? " drilling" : "");
    }
    // Marks: everyone sees the list; an instructor removes them.
    const glm::vec4 mc = markColor();
    const ImVec4 markCol(mc.r, mc.g, mc.b, 1.0f);
    ImGui::Text("marks: %zu", snap.annotations.size());
    for (const net::AnnotationInfo& a : snap.annotations) {
        ImGui::TextColored(markCol, "  %u %s", unsigned(a.id), a.label.c_str());
        ImGui::SameLine();
        ImGui::TextDisabled("by %s", participantName(snap.participants, a.author).c_str());
        if (marks.canMark) {
            ImGui::SameLine();
            ImGui::PushID(int(a.id));
            if (ImGui::SmallButton("remove"))
                marks.removeId = a.id;
            itemTip("Remove this mark for everyone.");
            ImGui::PopID();
        }
    }
    ImGui::End();
}

} // namespace trephine::ui

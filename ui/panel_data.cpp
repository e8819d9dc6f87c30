#include "ui/panel_data.h"
#include "ui/panels.h"

#include "libsim/stats.h"

#include <algorithm>
#include <cstdio>
#include <glm/geometric.hpp>

namespace trephine::ui {

std::optional<uint16_t>
ScriptedTakeOver::due(int attempt, const std::map<uint16_t, net::ParticipantInfo>& participants) {
    if (who.empty() || sentOnAttempt == attempt)
        return std::nullopt;
    for (const auto& [id, p] : participants)
        if (p.role == net::Role::Trainee && (p.name == who || std::to_string(id) == who)) {
            sentOnAttempt = attempt;
            return id;
        }
    return std::nullopt;
}

std::string defaultMarkLabel(const std::vector<net::AnnotationInfo>& marks) {
    for (size_t n = marks.size() + 1;; ++n) {
        const std::string label = "mark " + std::to_string(n);
        if (std::none_of(marks.begin(), marks.end(),
                         [&](const net::AnnotationInfo& m) { return m.label == label; }))
            return label;
    }
}

void MarkUndo::removing(const std::vector<net::AnnotationInfo>& shown, uint32_t id) {
    auto it = std::find_if(shown.begin(), shown.end(),
                           [&](const net::AnnotationInfo& m) { return m.id == id; });
    if (it != shown.end())
        m_taken = {*it};
}

void MarkUndo::clearing(const std::vector<net::AnnotationInfo>& shown) {
    if (!shown.empty())
        m_taken = shown;
}

std::vector<net::Annotate> MarkUndo::undo() {
    std::vector<net::Annotate> adds;
    for (const net::AnnotationInfo& m : m_taken) {
        net::Annotate a;
        a.op = net::Annotate::Op::Add;
        a.position = m.position;
        a.label = m.label;
        adds.push_back(std::move(a));
    }
    m_taken.clear();
    return adds;
}

std::vector<net::Annotate> markRequests(MarkControls& controls, MarkUndo& undo,
                                        const net::ClientSnapshot& snap,
                                        const std::optional<glm::vec3>& pointerPick) {
    std::vector<net::Annotate> out;
    if (snap.welcome && snap.state == net::LinkState::Connected) {
        if (controls.addAtPointer && pointerPick) {
            net::Annotate a;
            a.op = net::Annotate::Op::Add;
            a.position = *pointerPick;
            a.label = controls.label[0] ? std::string(controls.label)
                                        : defaultMarkLabel(snap.annotations);
            out.push_back(std::move(a));
        }
        if (controls.clearAll) {
            undo.clearing(snap.annotations);
            net::Annotate a;
            a.op = net::Annotate::Op::Clear;
            out.push_back(std::move(a));
        }
        if (controls.removeId) {
            undo.removing(snap.annotations, controls.removeId);
            net::Annotate a;
            a.op = net::Annotate::Op::Remove;
            a.id = controls.removeId;
            out.push_back(std::move(a));
        }
        if (controls.undo)
            for (net::Annotate& a : undo.undo())
                out.push_back(std::move(a));
    }
    controls.addAtPointer = controls.clearAll = controls.undo = false;
    controls.removeId = 0;
    controls.undoable = undo.pending();
    return out;
}

} // namespace trephine::ui

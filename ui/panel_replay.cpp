// [Replay] The timeline of a replay the server serves (`trephine replay --serve`), as a video
// player has it: a bar along the bottom of the view with play / pause, the position (drag to
// seek: the seek goes on release, since a seek backwards rebuilds the session), the time and the
// speed. Every window watching shares the one timeline; any of them drives it.
#include "ui/panels.h"

#include <imgui.h>

#include <algorithm>
#include <array>
#include <cstdio>

namespace trephine::ui {

namespace {

constexpr std::array<float, 8> kSpeeds{0.25f, 0.5f, 1.0f, 2.0f, 4.0f, 8.0f, 16.0f, 32.0f};

std::string clock(double s) {
    const int tenths = int(std::max(0.0, s) * 10.0 + 0.5);
    char buf[32];
    std::snprintf(buf, sizeof buf, "%d:%02d.%d", tenths / 600, (tenths / 10) % 60, tenths % 10);
    return buf;
}

} // namespace

uint64_t ReplayControls::shownUs(const net::ReplayState& state, uint64_t positionUs) const {
    if (dragS)
        return uint64_t(*dragS * 1e6);
    if (seekUs && state.seeks < seekAnswered)
        return *seekUs;
    return positionUs;
}

void ReplayControls::seek(const net::ReplayState& state, uint64_t toUs) {
    toUs = std::min(toUs, state.durationUs);
    asked.push_back({net::ReplayControl::Op::Seek, toUs});
    seekUs = toUs;
    seekAnswered =
        state.seeks + 1 + uint32_t(std::count_if(asked.begin(), asked.end() - 1, [](const auto& c) {
            return c.op == net::ReplayControl::Op::Seek;
        }));
}

void ReplayControls::keys(bool playPause, int steps, const net::ReplayState& state,
                          uint64_t positionUs) {
    if (playPause)
        asked.push_back(
            {state.playing ? net::ReplayControl::Op::Pause : net::ReplayControl::Op::Play});
    if (steps != 0) {
        const double to = double(shownUs(state, positionUs)) + steps * kReplayStepS * 1e6;
        seek(state, uint64_t(std::max(0.0, to)));
    }
}

void drawReplayTimeline(const net::ReplayState& state, uint64_t positionUs, ReplayControls& c,
                        const UiRect& view) {
    constexpr float kHeight = 44.0f;
    ImGui::SetNextWindowPos(ImVec2(view.x, view.y + view.h - kHeight), ImGuiCond_Always);
    ImGui::SetNextWindowSize(ImVec2(view.w, kHeight), ImGuiCond_Always);
    ImGui::SetNextWindowBgAlpha(0.78f);
    const ImGuiWindowFlags flags = ImGuiWindowFlags_NoTitleBar | ImGuiWindowFlags_NoResize |
                                   ImGuiWindowFlags_NoMove | ImGuiWindowFlags_NoScrollbar |
                                   ImGuiWindowFlags_NoSavedSettings |
                                   ImGuiWindowFlags_NoFocusOnAppearing;
    if (ImGui::Begin("Replay", nullptr, flags)) {
        // The play state as asked this frame shows at once; the server's answer follows.
        const bool playing = state.playing;
        if (ImGui::Button(playing ? "Pause" : "Play", ImVec2(56, 0)))
            c.asked.push_back(
                {playing ? net::ReplayControl::Op::Pause : net::ReplayControl::Op::Play});
        if (ImGui::IsItemHovered())
            ImGui::SetTooltip("%s the replay every window watches (Space)",
                              playing ? "Pause" : "Play");
        ImGui::SameLine();
        const double durationS = double(state.durationUs) * 1e-6;
        const double shownS = double(c.shownUs(state, positionUs)) * 1e-6;
        const std::string label = clock(shownS) + " / " + clock(durationS);
        const float speedWidth = 72.0f;
        ImGui::SetNextItemWidth(std::max(60.0f, ImGui::GetContentRegionAvail().x - speedWidth -
                                                    ImGui::GetStyle().ItemSpacing.x));
        float at = float(shownS);
        if (ImGui::SliderFloat("##position", &at, 0.0f, float(std::max(durationS, 1e-3)),
                               label.c_str(), ImGuiSliderFlags_NoInput))
            c.dragS = std::clamp(double(at), 0.0, durationS);
        if (ImGui::IsItemDeactivated() && c.dragS) {
            c.seek(state, uint64_t(*c.dragS * 1e6));
            c.dragS.reset();
        }
        if (ImGui::IsItemHovered())
            ImGui::SetTooltip("Drag to seek (Left / Right: 5 s). Back rebuilds the session from "
                              "its start.");
        ImGui::SameLine();
        ImGui::SetNextItemWidth(speedWidth);
        char speedLabel[24];
        std::snprintf(speedLabel, sizeof speedLabel, "%gx", double(state.speed));
        if (ImGui::BeginCombo("##speed", speedLabel)) {
            for (float s : kSpeeds) {
                char item[24];
                std::snprintf(item, sizeof item, "%gx", double(s));
                if (ImGui::Selectable(item, s == state.speed))
                    c.asked.push_back({net::ReplayControl::Op::Speed, 0, s});
            }
            ImGui::EndCombo();
        }
        if (ImGui::IsItemHovered())
            ImGui::SetTooltip("Times the recorded pace");
    }
    ImGui::End();
}

} // namespace trephine::ui

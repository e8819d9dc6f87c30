// [View] panel: orbit and zoom about the site. A change asks the server for a new DBI.
#include "ui/panels.h"

#include <imgui.h>

namespace trephine::ui {

bool drawViewPanel(ViewControls& view, bool waitingForImage, const char* picture,
                   const Camera* camera) {
    bool changed = false;
    if (ImGui::Begin("View")) {
        changed |= ImGui::SliderFloat("orbit", &view.yawDeg, -90.0f, 90.0f, "%.0f deg");
        itemTip("Turn the camera about the site, left and right.");
        changed |= ImGui::SliderFloat("tilt", &view.pitchDeg, -60.0f, 60.0f, "%.0f deg");
        itemTip("Tilt the camera about the site, up and down.");
        changed |= ImGui::SliderFloat("distance", &view.distanceMm, 80.0f, 500.0f, "%.0f mm");
        itemTip("The camera's distance from the site.");
        if (ImGui::Button("reset")) {
            view.reset();
            changed = true;
        }
        itemTip("Back to the view the window opened with.");
        ImGui::SameLine();
        if (waitingForImage)
            ImGui::TextColored(ImVec4(1.0f, 0.75f, 0.2f, 1), "waiting for the new %s...", picture);
        else
            ImGui::TextDisabled("%s up to date", picture);
        if (camera) {
            ImGui::Text("eye (%.0f, %.0f, %.0f) target (%.0f, %.0f, %.0f)", camera->eye.x,
                        camera->eye.y, camera->eye.z, camera->target.x, camera->target.y,
                        camera->target.z);
            if (ImGui::IsItemHovered())
                ImGui::SetTooltip("%s", describe(*camera).c_str());
        } else {
            ImGui::TextDisabled("no image yet");
        }
    }
    ImGui::End();
    if (changed)
        view.dirty = true;
    return changed;
}

} // namespace trephine::ui

// [Network] panel: what the link does now and over the last minute.
#include "ui/panels.h"

#include "net/enet_host.h"

#include <cstdio>
#include <imgui.h>

namespace trephine::ui {

void drawNetworkPanel(const net::ClientSnapshot& snap, const NetworkHistory& history, double now) {
    if (!ImGui::Begin("Network")) {
        ImGui::End();
        return;
    }
    if (snap.rttUs >= 0 && snap.rttP50Us >= 0)
        ImGui::Text("round trip  %.0f us (p50 %.0f us)", snap.rttUs, snap.rttP50Us);
    else if (snap.rttUs >= 0)
        ImGui::Text("round trip  %.0f us (p50 -)", snap.rttUs);
    else
        ImGui::TextDisabled("round trip  - (no pong yet)");
    if (snap.packetLoss >= 0)
        ImGui::Text("loss        %.1f %% (ENet, ~10 s), %llu lost this interval",
                    snap.packetLoss * 100.0, (unsigned long long)snap.packetsLost);
    else
        ImGui::TextDisabled("loss        - (not connected)");
    if (ImGui::IsItemHovered())
        ImGui::SetTooltip("ENet's coarse estimate: the smoothed share of reliable packets that\n"
                          "needed a resend, recomputed by ENet about every 10 s.");
    ImGui::Text("dropped     %llu malformed, %llu updates rejected",
                (unsigned long long)snap.malformed, (unsigned long long)snap.updatesRejected);
    if (snap.viewsRefused > 0)
        ImGui::TextColored(ImVec4(1.0f, 0.75f, 0.2f, 1),
                           "            %llu views the server does not serve",
                           (unsigned long long)snap.viewsRefused);
    ImGui::Text("updates     %.0f /s   %llu applied (%llu full)", history.updateRate(now),
                (unsigned long long)snap.updatesApplied, (unsigned long long)snap.fullUpdates);
    // The codec of the updates the picture takes now: volume mode's boxes and full copies are
    // not image updates (a full copy of a raw-box client travels zstd: encodeVolumeFull).
    if (snap.sync == net::Sync::Volume)
        ImGui::Text("codec       boxes %s, full %s   compression %.1fx", snap.volumeCodec.c_str(),
                    snap.volumeCodec == "raw" ? "zstd" : snap.volumeCodec.c_str(),
                    history.compressionRatio());
    else
        ImGui::Text("codec       %s   compression %.1fx", snap.codec.c_str(),
                    history.compressionRatio());
    if (ImGui::BeginTable("channels", 3, ImGuiTableFlags_BordersInnerH)) {
        ImGui::TableSetupColumn("channel");
        ImGui::TableSetupColumn("in kbit/s");
        ImGui::TableSetupColumn("out kbit/s");
        ImGui::TableHeadersRow();
        for (size_t c = 0; c < size_t(net::Channel::Count); ++c) {
            ImGui::TableNextRow();
            ImGui::TableNextColumn();
            ImGui::TextUnformatted(net::channelName(net::Channel(c)));
            ImGui::TableNextColumn();
            ImGui::Text("%.1f", snap.rates[c].bytesInPerS * 8e-3);
            ImGui::TableNextColumn();
            ImGui::Text("%.1f", snap.rates[c].bytesOutPerS * 8e-3);
        }
        ImGui::EndTable();
    }
    auto plot = [](const char* label, const std::vector<float>& v, const char* unit) {
        char overlay[64];
        if (v.empty() || v.back() < 0.0f) // none measured (a round trip before any pong)
            std::snprintf(overlay, sizeof overlay, "- %s", unit);
        else
            std::snprintf(overlay, sizeof overlay, "%.1f %s", v.back(), unit);
        ImGui::PlotLines(label, v.data(), int(v.size()), 0, overlay, 0.0f, FLT_MAX, ImVec2(0, 38));
    };
    plot("image", history.imageKbitPerS, "kbit/s");
    plot("tool", history.toolKbitPerS, "kbit/s");
    plot("updates", history.updatesPerS, "/s");
    plot("rtt", history.rttMs, "ms");
    const double maxUs = 20000.0;
    auto hist = history.latencyHistogram(20, maxUs);
    const std::string overlay = history.latencyCaption(maxUs);
    // ImGui 1.86's plots take a size literally (only 0 means the default), so -1 (other widgets'
    // "to the right edge") would draw a sliver: ask for the panel's width.
    ImGui::PlotHistogram("##delivery", hist.data(), int(hist.size()), 0, overlay.c_str(), 0.0f,
                         FLT_MAX, ImVec2(ImGui::GetContentRegionAvail().x, 60));
    itemTip("Delivery: from the cause on the server to the update applied here, before it is "
            "drawn.\nUpdate latency (Comparison) also counts the drawing: cause to screen.");
    ImGui::End();
}

} // namespace trephine::ui

// [Comparison] panel: the DBI design against the replicated volume, live (issue 7). One toggle
// switches the client between them; both keep their figures and plots, the inactive one greyed.
#include "ui/panels.h"

#include <cfloat>
#include <cstdio>
#include <imgui.h>

namespace trephine::ui {

namespace {

constexpr float kInactiveAlpha = 0.45f;

// "12.3" or "-" when the design has never been measured (or the figure is not known: < 0).
void cell(bool measured, bool active, const char* fmt, double a, double b = 0) {
    char text[64];
    if (!measured || a < 0)
        std::snprintf(text, sizeof text, "-");
    else
        std::snprintf(text, sizeof text, fmt, a, b);
    if (active)
        ImGui::TextUnformatted(text);
    else
        ImGui::TextDisabled("%s", text);
}

using Series = ComparisonHistory::Series;
constexpr SyncDesign kOrder[kSyncDesignCount] = {SyncDesign::Dbi, SyncDesign::Volume};

// One toggle; the label names the design in use first, or the switch under way. "###" keeps its
// ID across labels. True when clicked.
bool designToggle(SyncDesign& wanted, SyncDesign live) {
    const SyncDesign other = wanted == SyncDesign::Dbi ? SyncDesign::Volume : SyncDesign::Dbi;
    char label[128];
    if (wanted == live)
        std::snprintf(label, sizeof label, "%s  |  switch to %s###design", syncDesignName(live),
                      syncDesignName(other));
    else
        std::snprintf(label, sizeof label, "Switching to %s...  |  back to %s###design",
                      syncDesignName(wanted), syncDesignName(live));
    bool flipped = ImGui::Button(label);
    if (flipped)
        wanted = other;
    if (ImGui::IsItemHovered())
        ImGui::SetTooltip("DBI: the server renders and sends screen rectangles.\n"
                          "Volume: this client holds the volume, receives changed voxels and "
                          "renders locally.");
    return flipped;
}

// The table's first row: whether each design's figures are live, and how old they are if not.
void measuredRow(SyncDesign wanted, SyncDesign live, const ComparisonHistory& history, double now) {
    ImGui::TableNextRow();
    ImGui::TableNextColumn();
    ImGui::TextUnformatted("measured");
    for (SyncDesign d : kOrder) {
        ImGui::TableNextColumn();
        if (d == live)
            ImGui::TextUnformatted(history.measured(d) ? "live" : "waiting");
        else if (d == wanted)
            ImGui::TextDisabled("switching...");
        else if (history.measured(d))
            ImGui::TextDisabled("%.0f s ago", history.ageS(d, now));
        else
            ImGui::TextDisabled("never");
    }
}

// Live plots of one figure: DBI on the left, volume on the right. The caption is the table's
// figure, "-" where none was measured yet.
void plotPair(const ComparisonHistory& history, SyncDesign live, const char* name,
              std::vector<float> Series::*series, double ComparisonFigures::*figure,
              const char* unit) {
    const float w = (ImGui::GetContentRegionAvail().x - ImGui::GetStyle().ItemSpacing.x) * 0.5f;
    for (int i = 0; i < kSyncDesignCount; ++i) {
        SyncDesign d = kOrder[i];
        const std::vector<float>& v = history.series(d).*series;
        const double value = history.series(d).last.*figure;
        char overlay[64], id[64];
        if (history.measured(d) && value >= 0)
            std::snprintf(overlay, sizeof overlay, "%s %s: %.1f %s",
                          d == SyncDesign::Dbi ? "DBI" : "Vol", name, value, unit);
        else
            std::snprintf(overlay, sizeof overlay, "%s %s: -", d == SyncDesign::Dbi ? "DBI" : "Vol",
                          name);
        std::snprintf(id, sizeof id, "##%s%d", name, i);
        if (i > 0)
            ImGui::SameLine();
        ImGui::PushStyleVar(ImGuiStyleVar_Alpha, d == live ? 1.0f : kInactiveAlpha);
        ImGui::PlotLines(id, v.data(), int(v.size()), 0, overlay, 0.0f, FLT_MAX, ImVec2(w, 36));
        ImGui::PopStyleVar();
    }
}

} // namespace

bool drawComparisonPanel(SyncDesign& wanted, SyncDesign live, const ComparisonHistory& history,
                         double now) {
    if (!ImGui::Begin("Comparison")) {
        ImGui::End();
        return false;
    }
    const bool flipped = designToggle(wanted, live);

    using S = Series;
    // Fixed-width figure columns, wide enough for the widest figure: a column that sized itself
    // to its text jumped whenever a figure gained a digit.
    const float figureW = ImGui::CalcTextSize("0000 (raw 00000)").x;
    if (ImGui::BeginTable("figures", 3, ImGuiTableFlags_BordersInnerH)) {
        ImGui::TableSetupColumn("", ImGuiTableColumnFlags_WidthStretch);
        ImGui::TableSetupColumn("DBI", ImGuiTableColumnFlags_WidthFixed, figureW);
        ImGui::TableSetupColumn("Volume", ImGuiTableColumnFlags_WidthFixed, figureW);
        ImGui::TableHeadersRow();
        auto row = [&](const char* name, const char* tip, auto&& draw) {
            ImGui::TableNextRow();
            ImGui::TableNextColumn();
            ImGui::TextUnformatted(name);
            itemTip(tip);
            for (SyncDesign d : kOrder) {
                ImGui::TableNextColumn();
                draw(history.series(d), history.measured(d), d == live);
            }
        };
        measuredRow(wanted, live, history, now);
        row("updates /s", "Updates drawn per second, over the last second.",
            [](const S& s, bool m, bool a) { cell(m, a, "%.1f", s.last.updatesPerS); });
        row("bytes / update",
            "As sent (raw before compression). DBI: the rectangle's pixels. Volume: the changed "
            "voxels, 1 byte each (2 with materials); a small cut changes few voxels though its "
            "screen box is larger.",
            [](const S& s, bool m, bool a) {
                cell(m, a, "%.0f (raw %.0f)", s.last.bytesPerUpdate, s.last.rawBytesPerUpdate);
            });
        row("update latency ms",
            "p50 / p99 over the last second. Update latency: from the cause "
            "on the server to the change on this screen (drawn and swapped).",
            [](const S& s, bool m, bool a) {
                cell(m, a, "%.2f / %.2f", s.last.latencyP50Ms, s.last.latencyP99Ms);
            });
        row("frame ms", "This window's frame: start to swap and glFinish, median of 1 s.",
            [](const S& s, bool m, bool a) { cell(m, a, "%.2f", s.last.frameMs); });
        row("haptic Hz", "Ticks of the 1 kHz haptic loop per second.",
            [](const S& s, bool m, bool a) { cell(m, a, "%.0f", s.last.hapticHz); });
        ImGui::EndTable();
    }

    using F = ComparisonFigures;
    plotPair(history, live, "updates", &S::updatesPerS, &F::updatesPerS, "/s");
    plotPair(history, live, "bytes", &S::bytesPerUpdate, &F::bytesPerUpdate, "B");
    plotPair(history, live, "latency p50", &S::latencyP50Ms, &F::latencyP50Ms, "ms");
    plotPair(history, live, "latency p99", &S::latencyP99Ms, &F::latencyP99Ms, "ms");
    plotPair(history, live, "frame", &S::frameMs, &F::frameMs, "ms");
    plotPair(history, live, "haptic", &S::hapticHz, &F::hapticHz, "Hz");
    ImGui::End();
    return flipped;
}

} // namespace trephine::ui

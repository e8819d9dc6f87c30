#include "ui/layout.h"

#include <algorithm>
#include <cmath>

namespace trephine::ui {

namespace {

constexpr float kViewPanelHeight = 165.0f; // the View panel's content
constexpr float kForcesMinHeight = 120.0f; // Forces under the view below this goes in a column

// Stacks boxes down a column in proportion to `weights`, each a whole number of pixels.
template <size_t N>
void stack(UiRect column, const float (&weights)[N], UiRect* const (&out)[N]) {
    float total = 0;
    for (float w : weights)
        total += w;
    float y = column.y;
    for (size_t i = 0; i < N; ++i) {
        const float h =
            i + 1 == N ? column.y + column.h - y : std::floor(column.h * weights[i] / total);
        *out[i] = {column.x, y, column.w, h};
        y += h;
    }
}

} // namespace

float panelsWidth(int windowWidth, bool fullView) {
    if (fullView)
        return 0.0f;
    const float w = float(windowWidth);
    if (w >= kPanelColumnWidth + kSideColumnWidth + 400.0f)
        return kPanelColumnWidth + kSideColumnWidth;
    return std::clamp(w * 0.4f, std::min(w, kPanelColumnMinWidth), kPanelColumnWidth);
}

WindowLayout windowLayout(int windowWidth, int windowHeight, int viewWidth, int viewHeight,
                          bool fullView) {
    WindowLayout l;
    const float W = float(windowWidth), H = float(windowHeight);
    l.view = {0, 0, float(viewWidth), float(viewHeight)};
    if (fullView) {
        l.panels = false;
        return l;
    }
    PanelLayout& b = l.boxes;
    const float right = std::min(float(viewWidth), W), free = W - right;
    const float below = H - std::min(float(viewHeight), H);
    const bool forcesBelow = below >= kForcesMinHeight && right >= kPanelColumnMinWidth;
    if (forcesBelow)
        b.forces = {0, float(viewHeight), right, below};
    if (free >= 2 * kPanelColumnMinWidth) {
        // Two columns in the default proportions; at the default width, the default layout.
        const float colW = std::clamp(
            std::floor(free * kPanelColumnWidth / (kPanelColumnWidth + kSideColumnWidth)),
            kPanelColumnMinWidth, free - kPanelColumnMinWidth);
        const UiRect mid{right, 0, colW, H}, side{right + colW, 0, free - colW, H};
        const float sessionH = std::floor(H * 0.31f), comparisonH = std::floor(H * 0.535f);
        b.session = {mid.x, 0, mid.w, sessionH};
        b.view = {mid.x, sessionH, mid.w, kViewPanelHeight};
        const float networkY = sessionH + kViewPanelHeight;
        if (forcesBelow) {
            b.network = {mid.x, networkY, mid.w, H - networkY};
        } else {
            const float rest = H - networkY;
            b.network = {mid.x, networkY, mid.w, std::floor(rest * 0.45f)};
            b.forces = {mid.x, networkY + b.network.h, mid.w, rest - b.network.h};
        }
        b.comparison = {side.x, 0, side.w, comparisonH};
        // Dirty boxes share the rest of the right column with Assessment, below it.
        const float boxesH = std::floor((H - comparisonH) * 0.4f);
        b.dirtyBoxes = {side.x, comparisonH, side.w, boxesH};
        b.assessment = {side.x, comparisonH + boxesH, side.w, H - comparisonH - boxesH};
        return l;
    }
    UiRect column;
    if (free >= kPanelColumnMinWidth) {
        column = {right, 0, free, H}; // one column beside the view
    } else if (below >= 2 * kForcesMinHeight) {
        // Under the view, across the window: two columns.
        const float half = std::floor(W * 0.5f), y = float(viewHeight);
        stack({0, y, half, below}, {0.40f, 0.25f, 0.35f}, {&b.session, &b.view, &b.network});
        stack({half, y, W - half, below}, {0.30f, 0.20f, 0.25f, 0.25f},
              {&b.comparison, &b.dirtyBoxes, &b.assessment, &b.forces});
        return l;
    } else {
        // No room beside or under the view: one column over its right-hand side (H hides it).
        l.overlay = true;
        const float w = std::min(W, kPanelColumnMinWidth);
        column = {W - w, 0, w, H};
    }
    if (forcesBelow)
        stack(column, {0.22f, 0.12f, 0.16f, 0.20f, 0.14f, 0.16f},
              {&b.session, &b.view, &b.network, &b.comparison, &b.dirtyBoxes, &b.assessment});
    else
        stack(column, {0.19f, 0.12f, 0.13f, 0.16f, 0.12f, 0.14f, 0.14f},
              {&b.session, &b.view, &b.network, &b.comparison, &b.dirtyBoxes, &b.assessment,
               &b.forces});
    return l;
}

} // namespace trephine::ui

namespace trephine::ui {

namespace {
bool overlaps(const UiRect& a, const UiRect& b) {
    return a.x < b.x + b.w && b.x < a.x + a.w && a.y < b.y + b.h && b.y < a.y + a.h;
}
bool inside(const UiRect& r, const UiRect& bounds) {
    return r.x >= bounds.x && r.y >= bounds.y && r.x + r.w <= bounds.x + bounds.w &&
           r.y + r.h <= bounds.y + bounds.h;
}
} // namespace

std::vector<UiRect> placeLabels(const std::vector<LabelRequest>& labels, const UiRect& bounds) {
    constexpr float kGap = 10.0f;
    std::vector<UiRect> placed;
    placed.reserve(labels.size());
    for (const LabelRequest& l : labels) {
        const float right = l.anchorX + kGap, midY = l.anchorY - l.h * 0.5f;
        std::vector<UiRect> spots = {{right, midY, l.w, l.h},
                                     {right, l.anchorY - l.h - kGap, l.w, l.h},
                                     {right, l.anchorY + kGap, l.w, l.h},
                                     {l.anchorX - kGap - l.w, midY, l.w, l.h}};
        for (int step = 1; step <= 6; ++step) {
            spots.push_back({right, midY - float(step) * (l.h + 4.0f), l.w, l.h});
            spots.push_back({right, midY + float(step) * (l.h + 4.0f), l.w, l.h});
        }
        UiRect chosen = spots.front();
        for (const UiRect& s : spots) {
            const bool free = std::none_of(placed.begin(), placed.end(),
                                           [&](const UiRect& p) { return overlaps(s, p); });
            if (free && inside(s, bounds)) {
                chosen = s;
                break;
            }
        }
        placed.push_back(chosen);
    }
    return placed;
}

} // namespace trephine::ui

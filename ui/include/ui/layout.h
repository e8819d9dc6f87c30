// Where the 3D view and the panels go in a window of any size: the panels take the room the view
// leaves (right of it, then under it), stacked in columns that scroll, or hide for the
// full-window view. One function, so the view's size and the panels' places never disagree.
#pragma once

#include <vector>

namespace trephine::ui {

struct UiRect {
    float x = 0, y = 0, w = 0, h = 0;
    bool empty() const { return w <= 0 || h <= 0; }
    bool operator==(const UiRect&) const = default;
};

struct PanelLayout {
    UiRect session, view, network, comparison, dirtyBoxes, assessment, forces;
};

// The narrowest a panel column gets (its sliders and figures still read), and the default
// columns' widths (the middle column, and the right-hand one).
inline constexpr float kPanelColumnMinWidth = 300.0f;
inline constexpr float kPanelColumnWidth = 380.0f;
inline constexpr float kSideColumnWidth = 400.0f;

struct WindowLayout {
    UiRect view;          // the 3D view, top-left
    bool panels = true;   // drawn (false: the full-window view)
    bool overlay = false; // no room beside or under the view: the panels lie over it
    PanelLayout boxes;
};

// The width the panels take in a window `windowWidth` wide: two default columns where the view
// keeps at least 400 pixels, else one column; 0 in the full-window view. The view's area is
// the rest: [0, windowWidth - panelsWidth) x [0, windowHeight).
float panelsWidth(int windowWidth, bool fullView);
inline UiRect viewArea(int windowWidth, int windowHeight, bool fullView) {
    return {0, 0, float(windowWidth) - panelsWidth(windowWidth, fullView), float(windowHeight)};
}

// The panels' places around a view `viewWidth` x `viewHeight` at the window's top-left. At the
// default window (the view, then 380 + 400 pixels of columns) it is the layout the window always
// had: Session, View and Network in the middle column, Comparison over Dirty boxes on the
// right, Forces under the view.
WindowLayout windowLayout(int windowWidth, int windowHeight, int viewWidth, int viewHeight,
                          bool fullView);

} // namespace trephine::ui

namespace trephine::ui {

// A label to place over the view: its anchor (the point it names, window pixels) and its size.
struct LabelRequest {
    float anchorX = 0, anchorY = 0;
    float w = 0, h = 0;
};
// Places labels so they avoid each other, greedily in order: each takes the first of a few spots
// around its anchor (right, above, below, left, then further up) that overlaps no label placed
// before it and lies in `bounds`; when none does, the right of its anchor.
std::vector<UiRect> placeLabels(const std::vector<LabelRequest>& labels, const UiRect& bounds);

} // namespace trephine::ui

// Study output for people: line plots as standalone SVG files (no plotting library needed, they
// open in any browser and render inline in Markdown viewers) and Markdown tables.
#pragma once

#include <string>
#include <vector>

namespace trephine::study {

struct PlotSeries {
    std::string name;
    std::vector<double> x, y; // same length; non-finite points are skipped
    std::string color;        // CSS colour; empty: the next of a fixed palette
    bool dashed = false;      // e.g. a reference series (the paper's figures)
};

struct PlotSpec {
    std::string title;
    std::string xLabel, yLabel;
    bool logY = false; // decades; non-positive values are skipped
    int width = 640, height = 400;
    std::vector<PlotSeries> series;
};

// A complete SVG document: axes with "nice" ticks, grid, one polyline with markers per series,
// a legend. Text is XML-escaped. Throws nothing: an empty plot still draws its axes.
std::string svgLinePlot(const PlotSpec& spec);

// "Nice" tick values (1, 2, 5 x 10^k steps) covering [lo, hi] with about `count` ticks.
std::vector<double> niceTicks(double lo, double hi, int count);

// A Markdown table: one header row, an alignment row, then the rows (cells are escaped for '|').
std::string markdownTable(const std::vector<std::string>& header,
                          const std::vector<std::vector<std::string>>& rows);

} // namespace trephine::study

#include "study/svg_plot.h"

#include "net/debrief.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <limits>

namespace trephine::study {

namespace {

const char* const kPalette[] = {"#1f77b4", "#d62728", "#2ca02c", "#ff7f0e",
                                "#9467bd", "#8c564b", "#e377c2", "#7f7f7f"};

std::string tickLabel(double v) {
    if (v == 0.0)
        return "0";
    const double a = std::fabs(v);
    if (a >= 1e6)
        return fmt::format("{:g}M", v / 1e6);
    if (a >= 1e4)
        return fmt::format("{:g}k", v / 1e3);
    if (a < 1e-3)
        return fmt::format("{:.0e}", v);
    return fmt::format("{:g}", v);
}

bool usable(double x, double y, bool logY) {
    return std::isfinite(x) && std::isfinite(y) && (!logY || y > 0.0);
}

} // namespace

std::vector<double> niceTicks(double lo, double hi, int count) {
    std::vector<double> ticks;
    if (!std::isfinite(lo) || !std::isfinite(hi) || count < 1)
        return ticks;
    if (hi < lo)
        std::swap(lo, hi);
    if (hi - lo < 1e-12) {
        ticks.push_back(lo);
        return ticks;
    }
    const double raw = (hi - lo) / count;
    const double mag = std::pow(10.0, std::floor(std::log10(raw)));
    double step = mag;
    for (double m : {1.0, 2.0, 5.0, 10.0})
        if (raw <= m * mag) {
            step = m * mag;
            break;
        }
    const double first = std::ceil(lo / step - 1e-9) * step;
    for (double t = first; t <= hi + step * 1e-9; t += step)
        ticks.push_back(std::fabs(t) < step * 1e-9 ? 0.0 : t);
    return ticks;
}

namespace {

// Where the plot area lies in the picture and the data ranges it shows.
struct PlotArea {
    double W, H, left, top, pw, ph; // picture; plot area's left, top, width, height
    double xmin, xmax, ymin, ymax;  // y in log10 when the spec's y is logarithmic
    double px(double x) const { return left + (x - xmin) / (xmax - xmin) * pw; }
    double py(double y) const { return top + ph - (y - ymin) / (ymax - ymin) * ph; }
};

PlotArea plotArea(const PlotSpec& spec) {
    PlotArea a{};
    a.W = std::max(spec.width, 200);
    a.H = std::max(spec.height, 150);
    a.left = 70, a.top = 40;
    const double right = 170, bottom = 55; // right: the legend
    a.pw = a.W - a.left - right, a.ph = a.H - a.top - bottom;
    double xmin = std::numeric_limits<double>::infinity(), xmax = -xmin;
    double ymin = xmin, ymax = -xmin;
    for (const PlotSeries& s : spec.series)
        for (size_t i = 0; i < std::min(s.x.size(), s.y.size()); ++i) {
            if (!usable(s.x[i], s.y[i], spec.logY))
                continue;
            const double y = spec.logY ? std::log10(s.y[i]) : s.y[i];
            xmin = std::min(xmin, s.x[i]);
            xmax = std::max(xmax, s.x[i]);
            ymin = std::min(ymin, y);
            ymax = std::max(ymax, y);
        }
    if (!std::isfinite(xmin)) { // nothing to draw: unit axes
        xmin = 0, xmax = 1, ymin = 0, ymax = 1;
    }
    if (xmax - xmin < 1e-12)
        xmin -= 0.5, xmax += 0.5;
    if (spec.logY) {
        ymin = std::floor(ymin);
        ymax = std::ceil(ymax);
        if (ymax - ymin < 1)
            ymax = ymin + 1;
    } else {
        ymin = std::min(ymin, 0.0); // rates and sizes read best from zero
        if (ymax - ymin < 1e-12)
            ymax = ymin + 1;
        ymax += 0.05 * (ymax - ymin);
    }
    a.xmin = xmin, a.xmax = xmax, a.ymin = ymin, a.ymax = ymax;
    return a;
}

// The title, grid, ticks, frame and axis labels.
std::string svgAxes(const PlotSpec& spec, const PlotArea& a) {
    std::string svg =
        fmt::format("<text x=\"{:.1f}\" y=\"22\" text-anchor=\"middle\" font-size=\"14\" "
                    "font-weight=\"bold\">{}</text>\n",
                    a.left + a.pw / 2, net::escapeXml(spec.title).c_str());
    for (double t : niceTicks(a.xmin, a.xmax, 8)) {
        const double x = a.px(t);
        svg += fmt::format("<line x1=\"{:.1f}\" y1=\"{:.1f}\" x2=\"{:.1f}\" y2=\"{:.1f}\" "
                           "stroke=\"#ddd\"/>\n<text x=\"{:.1f}\" y=\"{:.1f}\" "
                           "text-anchor=\"middle\">{}</text>\n",
                           x, a.top, x, a.top + a.ph, x, a.top + a.ph + 16, tickLabel(t).c_str());
    }
    std::vector<double> yticks;
    if (spec.logY)
        for (double d = a.ymin; d <= a.ymax + 1e-9; d += 1)
            yticks.push_back(d);
    else
        yticks = niceTicks(a.ymin, a.ymax, 6);
    for (double t : yticks) {
        const double y = a.py(t);
        const std::string label = tickLabel(spec.logY ? std::pow(10.0, t) : t);
        svg += fmt::format("<line x1=\"{:.1f}\" y1=\"{:.1f}\" x2=\"{:.1f}\" y2=\"{:.1f}\" "
                           "stroke=\"#ddd\"/>\n<text x=\"{:.1f}\" y=\"{:.1f}\" "
                           "text-anchor=\"end\">{}</text>\n",
                           a.left, y, a.left + a.pw, y, a.left - 6, y + 4, label.c_str());
    }
    svg += fmt::format("<rect x=\"{:.1f}\" y=\"{:.1f}\" width=\"{:.1f}\" height=\"{:.1f}\" "
                       "fill=\"none\" stroke=\"#333\"/>\n",
                       a.left, a.top, a.pw, a.ph);
    svg += fmt::format("<text x=\"{:.1f}\" y=\"{:.1f}\" text-anchor=\"middle\">{}</text>\n",
                       a.left + a.pw / 2, a.H - 12, net::escapeXml(spec.xLabel).c_str());
    svg += fmt::format("<text x=\"16\" y=\"{:.1f}\" text-anchor=\"middle\" "
                       "transform=\"rotate(-90 16 {:.1f})\">{}{}</text>\n",
                       a.top + a.ph / 2, a.top + a.ph / 2, net::escapeXml(spec.yLabel).c_str(),
                       spec.logY ? " (log)" : "");
    return svg;
}

// Each series as a line with markers, and its entry in the legend.
std::string svgSeries(const PlotSpec& spec, const PlotArea& a) {
    std::string svg;
    size_t paletteIndex = 0;
    for (size_t si = 0; si < spec.series.size(); ++si) {
        const PlotSeries& s = spec.series[si];
        const std::string color =
            s.color.empty() ? kPalette[paletteIndex++ % std::size(kPalette)] : s.color;
        std::string points;
        std::string markers;
        for (size_t i = 0; i < std::min(s.x.size(), s.y.size()); ++i) {
            if (!usable(s.x[i], s.y[i], spec.logY))
                continue;
            const double x = a.px(s.x[i]), y = a.py(spec.logY ? std::log10(s.y[i]) : s.y[i]);
            points += fmt::format("{:.1f},{:.1f} ", x, y);
            markers += fmt::format("<circle cx=\"{:.1f}\" cy=\"{:.1f}\" r=\"3\" fill=\"{}\"/>\n", x,
                                   y, color.c_str());
        }
        svg +=
            fmt::format("<polyline fill=\"none\" stroke=\"{}\" stroke-width=\"2\"{} "
                        "points=\"{}\"/>\n",
                        color.c_str(), s.dashed ? " stroke-dasharray=\"6 4\"" : "", points.c_str());
        svg += markers;
        const double ly = a.top + 10 + 20 * double(si);
        svg += fmt::format(
            "<line x1=\"{:.1f}\" y1=\"{:.1f}\" x2=\"{:.1f}\" y2=\"{:.1f}\" stroke=\"{}\" "
            "stroke-width=\"2\"{}/>\n<text x=\"{:.1f}\" y=\"{:.1f}\">{}</text>\n",
            a.left + a.pw + 12, ly, a.left + a.pw + 36, ly, color.c_str(),
            s.dashed ? " stroke-dasharray=\"6 4\"" : "", a.left + a.pw + 42, ly + 4,
            net::escapeXml(s.name).c_str());
    }
    return svg;
}

} // namespace

std::string svgLinePlot(const PlotSpec& spec) {
    const PlotArea a = plotArea(spec);
    std::string svg =
        fmt::format("<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{:.0f}\" height=\"{:.0f}\" "
                    "viewBox=\"0 0 {:.0f} {:.0f}\" font-family=\"sans-serif\" font-size=\"12\">\n"
                    "<rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n",
                    a.W, a.H, a.W, a.H);
    svg += svgAxes(spec, a);
    svg += svgSeries(spec, a);
    svg += "</svg>\n";
    return svg;
}

std::string markdownTable(const std::vector<std::string>& header,
                          const std::vector<std::vector<std::string>>& rows) {
    auto cell = [](const std::string& s) {
        std::string out;
        for (char c : s)
            out += c == '|' ? std::string("\\|") : std::string(1, c);
        return out;
    };
    std::string md = "|";
    for (const std::string& h : header)
        // append, not " " + string: GCC 12 warns falsely (-Wrestrict) on that.
        md.append(" ").append(cell(h)).append(" |");
    md += "\n|";
    for (size_t i = 0; i < header.size(); ++i)
        md += i == 0 ? "---|" : "---:|";
    md += "\n";
    for (const auto& row : rows) {
        md += "|";
        for (size_t i = 0; i < header.size(); ++i)
            md.append(" ").append(i < row.size() ? cell(row[i]) : std::string()).append(" |");
        md += "\n";
    }
    return md;
}

} // namespace trephine::study

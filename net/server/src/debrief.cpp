#include "net/debrief.h"

#include "libsim/error.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>

namespace trephine::net {

namespace {

constexpr double kW = 720, kH = 300, kLeft = 64, kRight = 150, kTop = 34, kBottom = 44;

const char* const kPalette[] = {"#1f77b4", "#d62728", "#9467bd", "#2ca02c",
                                "#8c564b", "#e377c2", "#7f7f7f", "#bcbd22"};

const char* zoneColour(Zone z) {
    switch (z) {
    case Zone::Clear:
        return "#2ca02c";
    case Zone::Caution:
        return "#e6a700";
    case Zone::Danger:
        return "#ff7f0e";
    case Zone::Violation:
        return "#d62728";
    }
    return "#000000";
}

// A file name part from a participant's name: letters, digits, '-' and '_' only.
std::string slug(const std::string& name) {
    std::string s;
    for (char c : name)
        s += std::isalnum(static_cast<unsigned char>(c)) || c == '-' || c == '_' ? c : '_';
    return s.empty() ? "participant" : s.substr(0, 40);
}

void writeText(const std::filesystem::path& path, const std::string& text) {
    std::ofstream f(path, std::ios::binary | std::ios::trunc);
    f << text;
    if (!f.good())
        throw Error("debrief: cannot write " + path.string());
}

// A round step near range / 5 for the axis ticks.
double tickStep(double range) {
    if (!(range > 0))
        return 1;
    const double raw = range / 5, mag = std::pow(10.0, std::floor(std::log10(raw)));
    for (double m : {1.0, 2.0, 5.0, 10.0})
        if (raw <= m * mag)
            return m * mag;
    return 10 * mag;
}

} // namespace

std::string escapeXml(const std::string& s) {
    std::string out;
    for (char c : s) {
        switch (c) {
        case '<':
            out += "&lt;";
            break;
        case '>':
            out += "&gt;";
            break;
        case '&':
            out += "&amp;";
            break;
        case '"':
            out += "&quot;";
            break;
        default:
            out += c;
        }
    }
    return out;
}

std::string svgPlot(const std::string& title, const std::string& xLabel, const std::string& yLabel,
                    const std::vector<PlotSeries>& series, const std::vector<PlotMark>& marks,
                    const std::vector<PlotLine>& lines) {
    double x0 = 0, x1 = 1, y0 = 0, y1 = 1;
    bool any = false;
    for (const PlotSeries& s : series)
        for (size_t i = 0; i < s.x.size() && i < s.y.size(); ++i) {
            x1 = any ? std::max(x1, s.x[i]) : std::max(1.0, s.x[i]);
            y1 = any ? std::max(y1, s.y[i]) : std::max(1e-3, s.y[i]);
            y0 = std::min(y0, s.y[i]);
            any = true;
        }
    for (const PlotLine& l : lines)
        y1 = std::max(y1, l.y);
    y1 *= 1.05;
    const double pw = kW - kLeft - kRight, ph = kH - kTop - kBottom;
    auto px = [&](double x) { return kLeft + (x - x0) / (x1 - x0) * pw; };
    auto py = [&](double y) { return kTop + ph - (y - y0) / (y1 - y0) * ph; };
    std::string svg =
        fmt::format("<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{}\" height=\"{}\" "
                    "viewBox=\"0 0 {} {}\" font-family=\"sans-serif\" font-size=\"12\">\n"
                    "<rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n"
                    "<text x=\"{}\" y=\"20\" font-size=\"14\" font-weight=\"bold\">{}</text>\n",
                    kW, kH, kW, kH, kLeft, escapeXml(title));
    // Axes and ticks.
    svg += fmt::format("<rect x=\"{}\" y=\"{}\" width=\"{}\" height=\"{}\" fill=\"none\" "
                       "stroke=\"#444\"/>\n",
                       kLeft, kTop, pw, ph);
    const double xs = tickStep(x1 - x0), ys = tickStep(y1 - y0);
    for (double x = std::ceil(x0 / xs) * xs; x <= x1 + 1e-9; x += xs)
        svg += fmt::format("<text x=\"{:.1f}\" y=\"{:.1f}\" text-anchor=\"middle\">{:g}</text>\n",
                           px(x), kTop + ph + 16, x);
    for (double y = std::ceil(y0 / ys) * ys; y <= y1 + 1e-9; y += ys)
        svg += fmt::format("<text x=\"{:.1f}\" y=\"{:.1f}\" text-anchor=\"end\">{:g}</text>\n"
                           "<line x1=\"{:.1f}\" y1=\"{:.1f}\" x2=\"{:.1f}\" y2=\"{:.1f}\" "
                           "stroke=\"#eee\"/>\n",
                           kLeft - 4, py(y) + 4, y, kLeft, py(y), kLeft + pw, py(y));
    svg += fmt::format("<text x=\"{:.1f}\" y=\"{:.1f}\" text-anchor=\"middle\">{}</text>\n",
                       kLeft + pw / 2, kH - 8, escapeXml(xLabel));
    svg += fmt::format("<text transform=\"translate(14 {:.1f}) rotate(-90)\" "
                       "text-anchor=\"middle\">{}</text>\n",
                       kTop + ph / 2, escapeXml(yLabel));
    for (const PlotLine& l : lines)
        svg += fmt::format("<line x1=\"{:.1f}\" y1=\"{:.1f}\" x2=\"{:.1f}\" y2=\"{:.1f}\" "
                           "stroke=\"{}\" stroke-dasharray=\"6 4\"/>\n"
                           "<text x=\"{:.1f}\" y=\"{:.1f}\" fill=\"{}\">{}</text>\n",
                           kLeft, py(l.y), kLeft + pw, py(l.y), l.colour, kLeft + pw + 4,
                           py(l.y) + 4, l.colour, escapeXml(l.label));
    for (const PlotMark& m : marks)
        svg += fmt::format("<line x1=\"{0:.1f}\" y1=\"{1:.1f}\" x2=\"{0:.1f}\" y2=\"{2:.1f}\" "
                           "stroke=\"{3}\" stroke-width=\"1.5\" opacity=\"0.8\">"
                           "<title>{4}</title></line>\n",
                           px(m.x), kTop, kTop + ph, m.colour, escapeXml(m.label));
    double legendY = kTop + 10;
    for (const PlotSeries& s : series) {
        std::string points;
        for (size_t i = 0; i < s.x.size() && i < s.y.size(); ++i)
            points += fmt::format("{:.1f},{:.1f} ", px(s.x[i]), py(s.y[i]));
        svg += fmt::format("<polyline fill=\"none\" stroke=\"{}\" stroke-width=\"1.5\" "
                           "points=\"{}\"/>\n",
                           s.colour, points);
        svg += fmt::format("<rect x=\"{:.1f}\" y=\"{:.1f}\" width=\"12\" height=\"3\" "
                           "fill=\"{}\"/><text x=\"{:.1f}\" y=\"{:.1f}\">{}</text>\n",
                           kLeft + pw + 8, legendY - 4, s.colour, kLeft + pw + 24, legendY,
                           escapeXml(s.name));
        legendY += 16;
    }
    svg += "</svg>\n";
    return svg;
}

std::vector<std::string> writeDebriefs(const std::string& dir, const Assessment& assessment,
                                       const std::map<uint16_t, ParticipantMetrics>& metrics,
                                       const std::map<uint16_t, Timeline>& timelines) {
    namespace fs = std::filesystem;
    std::error_code ec;
    fs::create_directories(dir, ec);
    if (!fs::is_directory(dir))
        throw Error("debrief: " + dir + " is not a folder that can be made");
    const StructureFields& fields = assessment.fields();
    const AssessmentConfig& cfg = assessment.config();
    std::vector<std::string> written;
    for (const auto& [id, m] : metrics) {
        const std::string base = fmt::format("{}-{}", id, slug(m.name));
        const Timeline empty;
        auto tl = timelines.find(id);
        const Timeline& t = tl == timelines.end() ? empty : tl->second;
        std::vector<PlotMark> marks;
        for (const WarningMark& w : t.warnings)
            if (w.zone > w.previous)
                marks.push_back({w.t, zoneColour(w.zone),
                                 fmt::format("{} {} {:.2f} mm at {:.2f} s", zoneName(w.zone),
                                             w.structure, w.distanceMm, w.t)});
        std::vector<PlotSeries> dist;
        for (size_t i = 0; i < fields.size(); ++i) {
            PlotSeries s{fields.structure(i).name, kPalette[i % 8], {}, {}};
            for (const TimelineSample& x : t.samples) {
                s.x.push_back(x.t);
                s.y.push_back(std::max(0.0, double(x.distanceMm[i])));
            }
            dist.push_back(std::move(s));
        }
        PlotSeries force{"force", kPalette[0], {}, {}}, removed{"bone", kPalette[4], {}, {}};
        for (const TimelineSample& x : t.samples) {
            force.x.push_back(x.t);
            force.y.push_back(x.forceN);
            removed.x.push_back(x.t);
            removed.y.push_back(x.removedMm3);
        }
        const std::vector<PlotLine> zones{{cfg.cautionMm, zoneColour(Zone::Caution), "caution"},
                                          {cfg.dangerMm, zoneColour(Zone::Danger), "danger"}};
        writeText(fs::path(dir) / (base + "-distance.svg"),
                  svgPlot("Closest approach to each structure", "time (s)", "distance (mm)", dist,
                          marks, zones));
        writeText(fs::path(dir) / (base + "-force.svg"),
                  svgPlot("Force on the tool", "time (s)", "force (N)", {force}, marks));
        writeText(fs::path(dir) / (base + "-removed.svg"),
                  svgPlot("Bone removed", "time (s)", "volume (mm³)", {removed}, marks));

        std::string md = fmt::format("# Debrief: {}\n\n", m.name);
        md += fmt::format("Role: {}. Session {:.1f} s, drilling {:.1f} s.\n\n",
                          m.role == Role::Instructor ? "instructor" : "trainee", m.sessionS,
                          m.drillingS);
        md += "## Safety\n\n| structure | closest approach (mm) | contacts |\n|---|---|---|\n";
        for (const auto& [name, s] : m.structures)
            md += fmt::format("| {} | {:.2f} | {} |\n", name, s.closestMm, s.contacts);
        md += fmt::format("\nWarnings: {} (caution within {:g} mm, danger within {:g} mm, "
                          "violation on contact).\n\n| zone | time (s) |\n|---|---|\n",
                          m.warnings, cfg.cautionMm, cfg.dangerMm);
        for (int z = 0; z < kZoneCount; ++z)
            md += fmt::format("| {} | {:.2f} |\n", zoneName(Zone(z)), m.zoneS[size_t(z)]);
        if (!t.warnings.empty()) {
            md += "\n| time (s) | warning | structure | distance (mm) |\n|---|---|---|---|\n";
            for (const WarningMark& w : t.warnings)
                md += fmt::format("| {:.2f} | {} → {} | {} | {:.2f} |\n", w.t, zoneName(w.previous),
                                  zoneName(w.zone), w.structure, w.distanceMm);
        }
        md += fmt::format("\n![distance]({}-distance.svg)\n\n## Technique\n\n", base);
        md += "| figure | value |\n|---|---|\n";
        for (const auto& [mat, mm3] : m.removedMm3)
            md += fmt::format("| bone removed, {} | {:.1f} mm³ |\n", mat, mm3);
        md += fmt::format("| maximum force | {:.2f} N |\n| mean force while drilling | {:.2f} N |\n"
                          "| path length while drilling | {:.1f} mm |\n"
                          "| mean speed while drilling | {:.1f} mm/s |\n| strokes | {} |\n",
                          m.maxForceN, m.meanForceN, m.pathLengthMm, m.meanSpeedMmS, m.strokes);
        for (const auto& [tool, s] : m.toolS)
            md += fmt::format("| time with {} | {:.1f} s |\n", tool, s);
        md += fmt::format("\n![force]({0}-force.svg)\n\n![bone removed]({0}-removed.svg)\n", base);
        const fs::path mdPath = fs::path(dir) / (base + ".md");
        writeText(mdPath, md);
        written.push_back(mdPath.string());
    }
    return written;
}

} // namespace trephine::net

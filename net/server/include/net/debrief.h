// The debrief an instructor hands a trainee at the end of a session: one Markdown file per
// participant with its metrics and SVG plots (distance to each structure, force and bone removed
// over time, each warning marked). Written by the server's stop() (ServerConfig::debriefDir).
#pragma once

#include "net/assessment.h"
#include "net/assessment_metrics.h"

#include <map>
#include <string>
#include <vector>

namespace trephine::net {

// Writes `<dir>/<id>-<name>.md` and its plots `<id>-<name>-{distance,force,removed}.svg` for
// every participant of `metrics`; creates `dir`. Returns the Markdown files' paths. Throws
// trephine::Error when a file cannot be written.
std::vector<std::string> writeDebriefs(const std::string& dir, const Assessment& assessment,
                                       const std::map<uint16_t, ParticipantMetrics>& metrics,
                                       const std::map<uint16_t, Timeline>& timelines);

// `s` as XML text or an attribute value (SVG labels): & < > " escaped.
std::string escapeXml(const std::string& s);

// One line plot as SVG text (the debrief's), with vertical marks.
struct PlotSeries {
    std::string name, colour;
    std::vector<double> x, y;
};
struct PlotMark {
    double x = 0;
    std::string colour, label;
};
struct PlotLine {
    double y = 0;
    std::string colour, label;
};
std::string svgPlot(const std::string& title, const std::string& xLabel, const std::string& yLabel,
                    const std::vector<PlotSeries>& series, const std::vector<PlotMark>& marks = {},
                    const std::vector<PlotLine>& lines = {});

} // namespace trephine::net

#include "net/scripts.h"

#include "libsim/error.h"
#include "libsim/tool_catalogue.h"

#include <glm/geometric.hpp>
#include <glm/gtc/constants.hpp>
#include <glm/gtx/quaternion.hpp>

#include <charconv>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <optional>

namespace trephine::net {

// [SECTION] the burr hole

namespace {

glm::vec3 anyPerpendicular(glm::vec3 n) {
    return glm::normalize(
        glm::cross(n, std::abs(n.z) < 0.9f ? glm::vec3(0, 0, 1) : glm::vec3(1, 0, 0)));
}

} // namespace

ScriptPose burrholePose(const SurfaceSite& site, double t) {
    const glm::vec3 n = site.normal, e1 = anyPerpendicular(n), e2 = glm::cross(n, e1);
    const float depth = 2.0f;
    if (t < 1.0) {
        float d = -1.0f + float(t) * (depth + 1.0f);
        return {site.position - n * d, n, true, false};
    }
    if (t < 4.0) {
        float u = float((t - 1.0) / 3.0);
        float r = 6.0f * u, a = glm::two_pi<float>() * 3.0f * u;
        return {site.position - n * depth + (e1 * std::cos(a) + e2 * std::sin(a)) * r, n, true,
                false};
    }
    // Out of the hole along its axis, then over to rest beside it, leaning away so the hole stays
    // in view. A hand lifts the burr out: a jump straight to the rest pose would cross the wall
    // within one tick and spike the extrapolated force.
    const glm::vec3 bottom = site.position - n * depth + e1 * 6.0f; // where the spiral ends
    const glm::vec3 above = site.position + e1 * 6.0f + n * 4.0f;
    const glm::vec3 rest = site.position + e1 * 16.0f + n * 4.0f;
    const glm::vec3 leaning = glm::normalize(n + e1 * 0.7f);
    if (t < 4.3) {
        const float u = float((t - 4.0) / 0.3);
        return {glm::mix(bottom, above, u), n, false, false};
    }
    if (t < 4.6) {
        const float u = float((t - 4.3) / 0.3);
        return {glm::mix(above, rest, u), glm::normalize(glm::mix(n, leaning, u)), false, false};
    }
    return {rest, leaning, false, t > 4.9};
}

std::vector<ScriptSample> burrholeScript(const SurfaceSite& site, double durationS) {
    std::vector<ScriptSample> out;
    const int n = int(std::min(durationS, kBurrholeSeconds) * 100.0 + 0.5);
    for (int i = 0; i <= n; ++i) {
        ScriptSample s;
        s.t = i / 100.0;
        const ScriptPose p = burrholePose(site, s.t);
        s.tool.toolKind = uint8_t(ToolKind::Burr);
        s.tool.diameterMm = kBurrholeDiameterMm;
        s.tool.position = p.position;
        s.tool.orientation = glm::rotation(glm::vec3(0, 0, 1), p.axis);
        s.tool.drilling = p.drilling && i < n;
        s.tool.speed = s.tool.drilling ? 1.0f : 0.0f;
        out.push_back(s);
    }
    return out;
}

// [SECTION] the demo's feed

std::vector<ScriptSample> feedScript(const SurfaceSite& site, float feed, double seconds) {
    std::vector<ScriptSample> out;
    const int n = int(seconds * 100.0);
    for (int i = 0; i <= n; ++i) {
        ScriptSample s;
        s.t = i / 100.0;
        s.tool.toolKind = uint8_t(ToolKind::Perforator);
        s.tool.diameterMm = toolType(ToolKind::Perforator).defaultDiameterMm;
        s.tool.position = site.position - site.normal * (-1.0f + feed * float(s.t));
        s.tool.orientation = glm::rotation(glm::vec3(0, 0, 1), site.normal);
        s.tool.speed = 1.0f;
        s.tool.drilling = true;
        out.push_back(s);
    }
    return out;
}

// [SECTION] CSV trajectories

namespace {

// A whole cell as a decimal number (spaces around it allowed): stod read "0x10" as hex 16 and
// "5mm" or "1.5.2" as their leading number, so a mistyped cell drilled somewhere else.
bool parseNumberCell(const std::string& cell, double& v) {
    const char* p = cell.data();
    const char* end = p + cell.size();
    while (p < end && std::isspace(uint8_t(*p)))
        ++p;
    while (end > p && std::isspace(uint8_t(end[-1])))
        --end;
    if (p < end && *p == '+')
        ++p;
    auto [ptr, ec] = std::from_chars(p, end, v);
    return p < end && ec == std::errc() && ptr == end;
}

// One row's cells as a tool state; `fail` makes the error naming the file and line.
ScriptSample csvRow(const std::string& line, const std::function<Error(const std::string&)>& fail) {
    // Every cell, an empty last one too: "...,burr:5," has 11 columns, not 10.
    std::vector<std::string> cells;
    for (size_t at = 0;;) {
        const size_t comma = line.find(',', at);
        cells.push_back(line.substr(at, comma - at));
        if (comma == std::string::npos)
            break;
        at = comma + 1;
    }
    if (cells.size() != 10)
        throw fail("expected 10 columns time_s,x,y,z,qw,qx,qy,qz,speed,tool, found " +
                   std::to_string(cells.size()));
    double v[9];
    for (int i = 0; i < 9; ++i)
        if (!parseNumberCell(cells[size_t(i)], v[i]))
            throw fail("column " + std::to_string(i + 1) + " is not a number");
    // A number takes nan and inf, and a double beyond a float's range becomes inf as one: a NaN
    // time never ended the run, a huge one overflowed the end time.
    for (int i = 0; i < 9; ++i)
        if (!std::isfinite(float(v[i])))
            throw fail("column " + std::to_string(i + 1) + " is not a finite number");
    if (!(v[0] >= 0.0 && v[0] <= 86400.0))
        throw fail("time must be from 0 to 86400 s");
    if (!(std::abs(v[1]) <= kMaxToolDistanceMm && std::abs(v[2]) <= kMaxToolDistanceMm &&
          std::abs(v[3]) <= kMaxToolDistanceMm))
        throw fail("position beyond 100 m of the volume's centre");
    const glm::quat q = glm::quat(float(v[4]), float(v[5]), float(v[6]), float(v[7]));
    if (!(glm::dot(q, q) > 1e-6f))
        throw fail("the orientation quaternion is zero");
    ScriptSample s;
    s.t = v[0];
    s.tool.position = {float(v[1]), float(v[2]), float(v[3])};
    s.tool.orientation = glm::normalize(q);
    if (!(v[8] >= 0.0 && v[8] <= 1.0))
        throw fail("speed must be in [0, 1]");
    s.tool.speed = float(v[8]);
    s.tool.drilling = v[8] > 0.0;
    std::string tool = cells[9];
    while (!tool.empty() && std::isspace(uint8_t(tool.back())))
        tool.pop_back();
    ToolShape shape;
    auto diameter = [&](size_t from) {
        double d = 0.0;
        if (!parseNumberCell(tool.substr(from), d))
            throw fail("tool diameter in '" + tool + "' is not a number");
        return float(d);
    };
    try {
        // NAME:D, or NAME alone for the tool's usual size (ToolType::name).
        const size_t colon = tool.find(':');
        const std::optional<ToolKind> kind = toolKindNamed(tool.substr(0, colon));
        if (!kind)
            throw fail("tool must be NAME:D or NAME (burr, perforator, diamond), not '" + tool +
                       "'");
        shape = ToolShape::of(*kind, colon == std::string::npos ? toolType(*kind).defaultDiameterMm
                                                                : diameter(colon + 1));
    } catch (const Error& e) {
        if (std::string(e.what()).rfind("script ", 0) == 0)
            throw;
        throw fail(e.what()); // the tool's own complaint, with the file and line
    }
    s.tool.toolKind = uint8_t(shape.kind);
    s.tool.diameterMm = shape.diameterMm;
    return s;
}

} // namespace

std::vector<ScriptSample> csvScript(const std::string& path) {
    std::error_code ec;
    if (std::filesystem::is_directory(path, ec))
        throw Error("script " + path + ": a folder, not a CSV file (use `burrhole` or a CSV file)");
    std::ifstream in(path);
    if (!in)
        throw Error("script " + path + ": cannot open it (use `burrhole` or a CSV file)");
    std::vector<ScriptSample> out;
    std::string line;
    int lineNo = 0;
    auto fail = [&](const std::string& what) {
        return Error("script " + path + " line " + std::to_string(lineNo) + ": " + what);
    };
    // Lines of at most kMaxLine characters: std::getline on a file with no newline (/dev/zero, a
    // binary file) grew one line until memory ran out.
    constexpr size_t kMaxLine = 4096;
    auto readLine = [&] {
        ++lineNo;
        line.clear();
        for (int c; (c = in.get()) != std::char_traits<char>::eof();) {
            if (c == '\n')
                return true;
            if (line.size() == kMaxLine)
                throw fail("longer than " + std::to_string(kMaxLine) +
                           " characters: not a CSV trajectory");
            line += char(c);
        }
        return !line.empty();
    };
    while (readLine()) {
        if (!line.empty() && line.back() == '\r')
            line.pop_back();
        // A UTF-8 byte order mark (spreadsheets write one) is no part of the first cell: kept, it
        // made a first sample unreadable, skipped as a header and lost.
        if (lineNo == 1 && line.rfind("\xEF\xBB\xBF", 0) == 0)
            line.erase(0, 3);
        // Line 1 is a header when its first cell is not a number (" 5.0" and "+5.0" are numbers:
        // judged by the first character, they were skipped as a header and the sample lost).
        double firstCell = 0.0;
        if (line.empty() || line[0] == '#' ||
            (lineNo == 1 && !parseNumberCell(line.substr(0, line.find(',')), firstCell)))
            continue;
        const ScriptSample s = csvRow(line, fail);
        if (!out.empty() && s.t < out.back().t)
            throw fail("times must not decrease");
        out.push_back(s);
    }
    if (out.empty())
        throw Error("script " + path + ": no samples");
    return out;
}

} // namespace trephine::net

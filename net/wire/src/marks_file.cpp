#include "net/marks_file.h"

#include "libsim/error.h"
#include "libsim/replacing_file.h"

#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>

namespace trephine::net {

namespace {

constexpr const char* kHeader = "trephine-marks 1";

std::string quoted(const std::string& label) {
    std::string out = "\"";
    for (unsigned char c : label) {
        switch (c) {
        case '"':
            out += "\\\"";
            break;
        case '\\':
            out += "\\\\";
            break;
        case '\n':
            out += "\\n";
            break;
        case '\t':
            out += "\\t";
            break;
        default:
            if (c < 0x20 || c == 0x7f) {
                char buf[5];
                std::snprintf(buf, sizeof buf, "\\x%02x", c);
                out += buf;
            } else {
                out += char(c);
            }
        }
    }
    return out + "\"";
}

int hexDigit(char c) {
    if (c >= '0' && c <= '9')
        return c - '0';
    if (c >= 'a' && c <= 'f')
        return c - 'a' + 10;
    if (c >= 'A' && c <= 'F')
        return c - 'A' + 10;
    return -1;
}

// The label of `rest` (from its opening quote to the closing one, which must end the line), or
// an error message.
bool unquote(const std::string& rest, std::string& label, std::string& error) {
    size_t i = rest.find_first_not_of(' ');
    if (i == std::string::npos || rest[i] != '"') {
        error = "the label must be in double quotes";
        return false;
    }
    label.clear();
    for (++i; i < rest.size(); ++i) {
        const char c = rest[i];
        if (c == '"') {
            if (rest.find_first_not_of(" \r", i + 1) != std::string::npos) {
                error = "text after the label's closing quote";
                return false;
            }
            return true;
        }
        if (c != '\\') {
            label += c;
            continue;
        }
        if (++i >= rest.size())
            break;
        switch (rest[i]) {
        case '"':
            label += '"';
            break;
        case '\\':
            label += '\\';
            break;
        case 'n':
            label += '\n';
            break;
        case 't':
            label += '\t';
            break;
        case 'x': {
            const int hi = i + 1 < rest.size() ? hexDigit(rest[i + 1]) : -1;
            const int lo = i + 2 < rest.size() ? hexDigit(rest[i + 2]) : -1;
            if (hi < 0 || lo < 0) {
                error = "\\x needs two hex digits";
                return false;
            }
            label += char(hi * 16 + lo);
            i += 2;
            break;
        }
        default:
            error = std::string("unknown escape \\") + rest[i];
            return false;
        }
    }
    error = "the label's closing quote is missing";
    return false;
}

} // namespace

std::string marksPathFor(const std::string& volumePath) {
    return volumePath + ".marks";
}

void checkMarks(const std::vector<AnnotationInfo>& marks, const std::string& what) {
    if (marks.size() > kMaxAnnotations)
        throw Error(what + ": " + std::to_string(marks.size()) + " marks, at most " +
                    std::to_string(kMaxAnnotations));
    for (size_t i = 0; i < marks.size(); ++i) {
        const AnnotationInfo& m = marks[i];
        for (int a = 0; a < 3; ++a)
            if (!(std::abs(m.position[a]) <= kMaxAnnotationDistanceMm))
                throw Error(what + ": mark " + std::to_string(i + 1) +
                            " lies beyond 1e5 mm (or is not a number)");
        if (m.label.size() > kMaxNameLength)
            throw Error(what + ": mark " + std::to_string(i + 1) + "'s label is longer than " +
                        std::to_string(kMaxNameLength) + " bytes");
    }
}

void writeMarksFile(const std::string& path, const std::vector<AnnotationInfo>& marks) {
    checkMarks(marks, path);
    ReplacingFile f(path);
    f.stream() << kHeader << '\n';
    char buf[128];
    for (const AnnotationInfo& m : marks) {
        std::snprintf(buf, sizeof buf, "mark %.9g %.9g %.9g ", double(m.position.x),
                      double(m.position.y), double(m.position.z));
        f.stream() << buf << quoted(m.label) << '\n';
    }
    // (No reason from errno: the stream and the rename leave it unreliable.)
    if (!f.commit())
        throw Error(path +
                    ": cannot write the marks (a full disk, or a folder that takes no file?)");
}

std::vector<AnnotationInfo> readMarksFile(const std::string& path) {
    std::ifstream f(path, std::ios::binary);
    if (!f)
        throw Error(path + ": cannot open the marks file (" + std::strerror(errno) + ")");
    std::vector<AnnotationInfo> out;
    std::string line;
    int n = 0;
    bool header = false;
    auto fail = [&](const std::string& why) {
        throw Error(path + ":" + std::to_string(n) + ": " + why);
    };
    while (std::getline(f, line)) {
        ++n;
        if (!line.empty() && line.back() == '\r')
            line.pop_back();
        if (!header) {
            if (line != kHeader)
                fail("not a marks file (the first line must be \"" + std::string(kHeader) + "\")");
            header = true;
            continue;
        }
        if (line.empty() || line[0] == '#')
            continue;
        std::istringstream in(line);
        std::string word;
        in >> word;
        if (word != "mark")
            fail("expected `mark X Y Z \"LABEL\"`");
        AnnotationInfo a;
        for (int k = 0; k < 3; ++k) {
            std::string v;
            in >> v;
            char* end = nullptr;
            errno = 0;
            const double d = std::strtod(v.c_str(), &end);
            if (v.empty() || *end != '\0' || errno == ERANGE || !std::isfinite(d) ||
                std::abs(d) > kMaxAnnotationDistanceMm)
                fail("coordinate `" + v + "` is not a number within 1e5 mm");
            a.position[k] = float(d);
        }
        std::string rest, error;
        std::getline(in, rest);
        if (!unquote(rest, a.label, error))
            fail(error);
        if (a.label.size() > kMaxNameLength)
            fail("the label is longer than " + std::to_string(kMaxNameLength) + " bytes");
        if (out.size() >= kMaxAnnotations)
            fail("more than " + std::to_string(kMaxAnnotations) + " marks");
        a.id = uint32_t(out.size() + 1);
        out.push_back(std::move(a));
    }
    if (f.bad())
        throw Error(path + ": cannot read the marks file");
    if (!header)
        throw Error(path + ": empty, not a marks file");
    return out;
}

} // namespace trephine::net

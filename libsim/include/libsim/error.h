// User-facing errors: a bad file, spec or flag. The message is one line that names the thing and
// says what is wrong; `trephine` prints it and exits non-zero. Programmer mistakes are asserts.
#pragma once

#include <cstdio>
#include <stdexcept>
#include <string>

namespace trephine {

// `text` on one line: control characters (a newline in a path, say) written as \n, \r, \t or
// \xNN, so an error names the thing exactly and stays one line.
inline std::string oneLine(const std::string& text) {
    std::string out;
    out.reserve(text.size());
    for (char c : text) {
        const auto u = static_cast<unsigned char>(c);
        if (u >= 0x20 && u != 0x7F) {
            out += c;
            continue;
        }
        switch (c) {
        case '\n':
            out += "\\n";
            break;
        case '\r':
            out += "\\r";
            break;
        case '\t':
            out += "\\t";
            break;
        default: {
            char hex[8];
            std::snprintf(hex, sizeof hex, "\\x%02X", unsigned(u));
            out += hex;
        }
        }
    }
    return out;
}

class Error : public std::runtime_error {
public:
    explicit Error(const std::string& message) : std::runtime_error(oneLine(message)) {}
};

} // namespace trephine

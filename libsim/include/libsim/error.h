// User-facing errors: a bad file, spec or flag. The message is one line that names the thing and
// says what is wrong; `trephine` prints it and exits non-zero. Programmer mistakes are asserts.
#pragma once

#include <stdexcept>
#include <string>

namespace trephine {

class Error : public std::runtime_error {
public:
    explicit Error(const std::string& message) : std::runtime_error(message) {}
};

} // namespace trephine

// `--link SPEC` for every mode that joins or serves a session: one option, one meaning
// (net::startLinkEnd runs the emulator on this end), checked as the command line is read.
#pragma once

#include <CLI/CLI.hpp>

#include "libsim/error.h"
#include "net/link_emulator.h"

#include <string>

namespace trephine::app {

// Adds --link to `sub`; `where` says where this mode's end puts the relay.
inline CLI::Option* addLinkOption(CLI::App* sub, std::string& spec, const std::string& where) {
    return sub
        ->add_option("--link", spec,
                     "Emulate a long link on this end (" + where +
                         "): latency=MS,jitter=MS,loss=PERCENT,rate=MBIT, any subset, e.g. "
                         "latency=50,loss=1,rate=20 (docs/session.md)")
        ->check(CLI::Validator(
            [](std::string& text) -> std::string {
                try {
                    net::linkSpecConditions(text);
                } catch (const Error& e) {
                    return e.what();
                }
                return {};
            },
            "SPEC"));
}

} // namespace trephine::app

// What `trephine server` says when it starts, after its port line: the addresses another machine
// joins it at, that the port is UDP, and a warning when nothing of the session is kept at exit.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace trephine::net {

// This machine's IPv4 interface addresses that are up (getifaddrs): others first, loopback
// last; empty when none can be read.
std::vector<std::string> localAddresses();

// The lines (without the "trephine server: " prefix) for `port` and `addresses`. `keepsSession`:
// the session is saved (--save-on-exit) or recorded when the server stops. `traineeCode`: the
// code the join commands carry (empty: an open session).
std::vector<std::string> serverStartLines(uint16_t port, const std::vector<std::string>& addresses,
                                          bool keepsSession, const std::string& traineeCode = "");

} // namespace trephine::net

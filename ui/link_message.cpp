#include "ui/link_message.h"

#include <fmt/format.h>

namespace trephine::ui {

namespace {

std::string portOf(const std::string& address) {
    const size_t colon = address.rfind(':');
    return colon == std::string::npos ? "7777" : address.substr(colon + 1);
}

std::string hints(const std::string& address, int failures, bool lost) {
    return fmt::format("\n\nNo answer after {} attempts. Likely causes:\n"
                       "- the server {} (start it: trephine server)\n"
                       "- a wrong address: the server prints the addresses it listens on\n"
                       "- a wrong port, or a firewall closing UDP port {}",
                       failures, lost ? "has stopped" : "is not running", portOf(address));
}

} // namespace

LinkMessage linkMessage(net::LinkState state, int attempts, int attemptsWhenConnected,
                        const std::string& closeReason, const std::string& address,
                        bool havePicture) {
    LinkMessage m;
    if (state == net::LinkState::Connected || state == net::LinkState::Stopped)
        return m;
    const bool lost = attemptsWhenConnected >= 0;
    // The attempt under way has not failed yet while connecting; a retry follows a failure.
    const int failures = std::max(0, attempts - std::max(attemptsWhenConnected, 0) -
                                         (state == net::LinkState::Connecting ? 1 : 0));
    if (lost)
        m.text = fmt::format("Lost the server at {}{}{}\nReconnecting (attempt {})...", address,
                             closeReason.empty() ? "" : ": ", closeReason, attempts);
    else if (state == net::LinkState::Retrying && !closeReason.empty())
        m.text = fmt::format("Not connected to {}: {}\nRetrying (attempt {})...", address,
                             closeReason, attempts);
    else
        // While connecting, the reason is the last attempt's, or what the server said of this
        // one (busy: the client tries again by itself).
        m.text = fmt::format("Connecting to {} (attempt {})...{}{}", address, attempts,
                             closeReason.empty() ? "" : "\n", closeReason);
    // The hints are for a server that may not be there: a busy one answered.
    if (failures >= kHintAfterFailures && closeReason.find("is busy") == std::string::npos)
        m.text += hints(address, failures, lost);
    m.dim = havePicture;
    return m;
}

} // namespace trephine::ui

#include "net/server_banner.h"

#include <arpa/inet.h>
#include <ifaddrs.h>
#include <net/if.h>
#include <netinet/in.h>

#include <algorithm>
#include <fmt/format.h>

namespace trephine::net {

std::vector<std::string> localAddresses() {
    std::vector<std::string> others, loopback;
    ifaddrs* list = nullptr;
    if (getifaddrs(&list) != 0)
        return {};
    for (const ifaddrs* i = list; i; i = i->ifa_next) {
        if (!i->ifa_addr || i->ifa_addr->sa_family != AF_INET || !(i->ifa_flags & IFF_UP))
            continue;
        char text[INET_ADDRSTRLEN] = "";
        const auto* in = reinterpret_cast<const sockaddr_in*>(i->ifa_addr);
        if (!inet_ntop(AF_INET, &in->sin_addr, text, sizeof text))
            continue;
        auto& into = (i->ifa_flags & IFF_LOOPBACK) ? loopback : others;
        if (std::find(into.begin(), into.end(), text) == into.end())
            into.push_back(text);
    }
    freeifaddrs(list);
    others.insert(others.end(), loopback.begin(), loopback.end());
    return others;
}

std::vector<std::string> serverStartLines(uint16_t port, const std::vector<std::string>& addresses,
                                          bool keepsSession, const std::string& traineeCode) {
    std::vector<std::string> lines;
    lines.push_back(fmt::format("listening on UDP port {} on every interface (a firewall must "
                                "let UDP {} in for other machines)",
                                port, port));
    bool first = true;
    for (const std::string& a : addresses) {
        const bool loop = a.rfind("127.", 0) == 0;
        lines.push_back(fmt::format("  {}: trephine trainee --connect {}:{}{}",
                                    loop    ? "from this machine"
                                    : first ? "from another machine"
                                            : "or",
                                    a, port, traineeCode.empty() ? "" : " --code " + traineeCode));
        first = first && loop;
    }
    if (addresses.empty())
        lines.push_back(fmt::format("  cannot list this machine's addresses: join at HOST:{}, "
                                    "HOST being this machine's name or address",
                                    port));
    if (!keepsSession)
        lines.push_back("warning: the session (the drilled skull and the marks) is discarded when "
                        "the server stops; --save-on-exit FILE keeps it, --record FILE logs it");
    return lines;
}

} // namespace trephine::net

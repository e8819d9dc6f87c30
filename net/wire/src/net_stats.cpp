#include "net/net_stats.h"

#include <chrono>

namespace trephine::net {

uint64_t steadyNowUs() {
    using namespace std::chrono;
    return uint64_t(duration_cast<microseconds>(steady_clock::now().time_since_epoch()).count());
}

void NetStats::countIn(Channel c, size_t bytes) {
    auto& k = m_channels[size_t(c)];
    k.bytesIn.fetch_add(bytes, std::memory_order_relaxed);
    k.msgsIn.fetch_add(1, std::memory_order_relaxed);
}

void NetStats::countOut(Channel c, size_t bytes) {
    auto& k = m_channels[size_t(c)];
    k.bytesOut.fetch_add(bytes, std::memory_order_relaxed);
    k.msgsOut.fetch_add(1, std::memory_order_relaxed);
}

void NetStats::tick(uint64_t nowUs) {
    if (m_firstTickUs.load() == 0) {
        m_lastTickUs = nowUs;
        m_firstTickUs = nowUs;
        for (size_t c = 0; c < m_channels.size(); ++c)
            m_lastTick[c] = {m_channels[c].bytesIn.load(), m_channels[c].bytesOut.load(),
                             m_channels[c].msgsIn.load(), m_channels[c].msgsOut.load()};
        return;
    }
    double dt = double(nowUs - m_lastTickUs) * 1e-6;
    if (dt <= 0)
        return;
    std::array<ChannelRates, size_t(Channel::Count)> rates{};
    for (size_t c = 0; c < m_channels.size(); ++c) {
        std::array<uint64_t, 4> now = {m_channels[c].bytesIn.load(), m_channels[c].bytesOut.load(),
                                       m_channels[c].msgsIn.load(), m_channels[c].msgsOut.load()};
        rates[c] = {double(now[0] - m_lastTick[c][0]) / dt, double(now[1] - m_lastTick[c][1]) / dt,
                    double(now[2] - m_lastTick[c][2]) / dt, double(now[3] - m_lastTick[c][3]) / dt};
        m_lastTick[c] = now;
    }
    m_history.push_back(rates);
    if (m_history.size() > kHistoryLength)
        m_history.pop_front();
    m_lastTickUs = nowUs;
}

ChannelRates NetStats::averageRates(Channel c) const {
    const uint64_t first = m_firstTickUs.load(), last = m_lastTickUs.load();
    double dt = first && last > first ? double(last - first) * 1e-6 : 0.0;
    if (dt <= 0)
        return {};
    const auto& k = m_channels[size_t(c)];
    return {double(k.bytesIn.load()) / dt, double(k.bytesOut.load()) / dt,
            double(k.msgsIn.load()) / dt, double(k.msgsOut.load()) / dt};
}

void ModeStats::add(const UpdateRecord& r) {
    ++updates;
    fullUpdates += r.full;
    bytes.add(double(r.bytes));
    rawBytes.add(double(r.rawBytes));
    auto put = [](SampleWindow& w, double v) {
        if (v >= 0)
            w.add(v);
    };
    if (!r.full)
        put(latencyUs, r.latencyUs);
    put(transmitUs, r.transmitUs);
    put(applyUs, r.applyUs);
    put(clientRenderUs, r.clientRenderUs);
    put(erodeUs, r.erodeUs);
    put(serverRenderUs, r.serverRenderUs);
    put(encodeUs, r.encodeUs);
}

} // namespace trephine::net

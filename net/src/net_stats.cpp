#include "net/net_stats.h"

#include <chrono>
#include <cstdio>

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

std::string jsonModeStats(const ModeStats& m) {
    return "{\"updates\": " + std::to_string(m.updates) +
           ", \"full_updates\": " + std::to_string(m.fullUpdates) +
           ", \"bytes\": " + jsonWindow(m.bytes) + ", \"raw_bytes\": " + jsonWindow(m.rawBytes) +
           ", \"latency_us\": " + jsonWindow(m.latencyUs) +
           ", \"erode_us\": " + jsonWindow(m.erodeUs) +
           ", \"server_render_us\": " + jsonWindow(m.serverRenderUs) +
           ", \"encode_us\": " + jsonWindow(m.encodeUs) +
           ", \"transmit_us\": " + jsonWindow(m.transmitUs) +
           ", \"client_apply_us\": " + jsonWindow(m.applyUs) +
           ", \"client_render_us\": " + jsonWindow(m.clientRenderUs) + "}";
}

std::string jsonString(const std::string& s) {
    std::string out = "\"";
    for (char ch : s) {
        if (ch == '"' || ch == '\\') {
            out += '\\';
            out += ch;
        } else if (uint8_t(ch) < 0x20) {
            char buf[8];
            std::snprintf(buf, sizeof buf, "\\u%04x", unsigned(uint8_t(ch)));
            out += buf;
        } else {
            out += ch;
        }
    }
    return out + "\"";
}

std::string jsonNumber(double v) {
    char buf[64];
    std::snprintf(buf, sizeof buf, "%.6g", v);
    return buf;
}

std::string jsonWindow(const SampleWindow& w) {
    return "{\"count\": " + std::to_string(w.totalCount()) + ", \"mean\": " + jsonNumber(w.mean()) +
           ", \"min\": " + jsonNumber(w.min()) + ", \"p50\": " + jsonNumber(w.percentile(50)) +
           ", \"p99\": " + jsonNumber(w.percentile(99)) + ", \"max\": " + jsonNumber(w.max()) + "}";
}

std::string reportJson(const ReportInfo& info, const NetStats& stats) {
    std::string j = "{\n";
    j += "  \"server\": " + jsonString(info.server) + ",\n";
    j += "  \"codec\": " + jsonString(info.codec) + ",\n";
    j += "  \"sync\": " + jsonString(info.sync) + ",\n";
    j += "  \"view\": " + jsonString(info.view) + ",\n";
    j += "  \"camera\": " + jsonString(info.camera) + ",\n";
    j += "  \"script\": " + jsonString(info.script) + ",\n";
    j += "  \"duration_s\": " + jsonNumber(info.durationS) + ",\n";
    j += "  \"updates_applied\": " + std::to_string(info.updatesApplied) + ",\n";
    j += "  \"full_updates\": " + std::to_string(info.fullUpdates) + ",\n";
    j += "  \"tool_states_sent\": " + std::to_string(info.toolStatesSent) + ",\n";
    j += "  \"relays_received\": " + std::to_string(info.relaysReceived) + ",\n";
    j += "  \"malformed_dropped\": " + std::to_string(stats.malformed()) + ",\n";
    j += "  \"updates_rejected\": " + std::to_string(info.updatesRejected) + ",\n";
    j += "  \"clock_offset_us\": " + std::to_string(stats.clockOffsetUs) + ",\n";
    j += "  \"packet_loss\": " + jsonNumber(stats.packetLoss) + ",\n";
    j += "  \"packets_lost\": " + std::to_string(stats.packetsLost) + ",\n";
    j += "  \"rtt_us\": " + jsonWindow(stats.rttUs) + ",\n";
    j += "  \"update_bytes\": " + jsonWindow(stats.updateBytes) + ",\n";
    j += "  \"update_raw_bytes\": " + jsonWindow(stats.updateRawBytes) + ",\n";
    j += "  \"update_latency_us\": " + jsonWindow(stats.updateLatencyUs) + ",\n";
    j += "  \"apply_us\": " + jsonWindow(stats.applyUs) + ",\n";
    j += "  \"haptic_round_trip_us\": " + jsonWindow(stats.hapticRoundTripUs) + ",\n";
    j += "  \"modes\": {\"dbi\": " + jsonModeStats(stats.modes[size_t(Sync::Dbi)]) +
         ",\n            \"volume\": " + jsonModeStats(stats.modes[size_t(Sync::Volume)]) + "},\n";
    if (info.hapticLoop) {
        j +=
            "  \"haptics\": {\"tool_rate_hz\": " + jsonNumber(info.toolRateHz) +
            ", \"rate_hz\": " + jsonNumber(info.hapticRateHz) +
            ", \"achieved_rate_hz\": " + jsonNumber(info.achievedRateHz) +
            ", \"lateness_p50_ms\": " + jsonNumber(info.latenessP50Ms) +
            ", \"lateness_p99_ms\": " + jsonNumber(info.latenessP99Ms) +
            ", \"ticks\": " + std::to_string(info.hapticTicks) +
            ", \"models_received\": " + std::to_string(info.hapticModels) +
            ", \"models_applied\": " + std::to_string(info.modelsApplied) +
            ", \"models_dropped\": " + std::to_string(info.modelsDropped) +
            ", \"force_round_trip_p50_us\": " + jsonNumber(stats.hapticRoundTripUs.percentile(50)) +
            ", \"force_round_trip_p99_us\": " + jsonNumber(stats.hapticRoundTripUs.percentile(99)) +
            "},\n";
    }
    j += "  \"channels\": " + jsonChannels(stats);
    j += "\n}\n";
    return j;
}

std::string jsonChannels(const NetStats& stats) {
    std::string j = "{";
    for (size_t c = 0; c < size_t(Channel::Count); ++c) {
        Channel ch = Channel(c);
        ChannelRates r = stats.averageRates(ch);
        j += std::string(c ? "," : "") + "\n    " + jsonString(channelName(ch)) + ": {" +
             "\"bytes_in\": " + std::to_string(stats.totalBytesIn(ch)) +
             ", \"bytes_out\": " + std::to_string(stats.totalBytesOut(ch)) +
             ", \"messages_in\": " + std::to_string(stats.totalMessagesIn(ch)) +
             ", \"messages_out\": " + std::to_string(stats.totalMessagesOut(ch)) +
             ", \"bytes_in_per_s\": " + jsonNumber(r.bytesInPerS) +
             ", \"bytes_out_per_s\": " + jsonNumber(r.bytesOutPerS) +
             ", \"messages_in_per_s\": " + jsonNumber(r.messagesInPerS) +
             ", \"messages_out_per_s\": " + jsonNumber(r.messagesOutPerS) + "}";
    }
    return j + "\n  }";
}

} // namespace trephine::net

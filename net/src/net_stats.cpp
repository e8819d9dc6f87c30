#include "net/net_stats.h"

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include <chrono>

namespace trephine::net {

namespace {

// Names and scripts come from peers and users: a byte that is not UTF-8 is replaced, not thrown.
constexpr auto kReplaceInvalidUtf8 = nlohmann::json::error_handler_t::replace;

} // namespace

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

nlohmann::ordered_json windowJson(const SampleWindow& w) {
    return {{"count", w.totalCount()}, {"mean", w.mean()},        {"min", w.min()},
            {"p50", w.percentile(50)}, {"p99", w.percentile(99)}, {"max", w.max()}};
}

nlohmann::ordered_json modeStatsJson(const ModeStats& m) {
    return {{"updates", m.updates},
            {"full_updates", m.fullUpdates},
            {"bytes", windowJson(m.bytes)},
            {"raw_bytes", windowJson(m.rawBytes)},
            {"latency_us", windowJson(m.latencyUs)},
            {"erode_us", windowJson(m.erodeUs)},
            {"server_render_us", windowJson(m.serverRenderUs)},
            {"encode_us", windowJson(m.encodeUs)},
            {"transmit_us", windowJson(m.transmitUs)},
            {"client_apply_us", windowJson(m.applyUs)},
            {"client_render_us", windowJson(m.clientRenderUs)}};
}

nlohmann::ordered_json channelsJson(const NetStats& stats) {
    nlohmann::ordered_json j = nlohmann::ordered_json::object();
    for (size_t c = 0; c < size_t(Channel::Count); ++c) {
        const Channel ch = Channel(c);
        const ChannelRates r = stats.averageRates(ch);
        j[channelName(ch)] = {{"bytes_in", stats.totalBytesIn(ch)},
                              {"bytes_out", stats.totalBytesOut(ch)},
                              {"messages_in", stats.totalMessagesIn(ch)},
                              {"messages_out", stats.totalMessagesOut(ch)},
                              {"bytes_in_per_s", r.bytesInPerS},
                              {"bytes_out_per_s", r.bytesOutPerS},
                              {"messages_in_per_s", r.messagesInPerS},
                              {"messages_out_per_s", r.messagesOutPerS}};
    }
    return j;
}

nlohmann::ordered_json reportJsonValue(const ReportInfo& info, const NetStats& stats) {
    nlohmann::ordered_json j = {{"server", info.server},
                                {"codec", info.codec},
                                {"sync", info.sync},
                                {"view", info.view},
                                {"camera", info.camera},
                                {"script", info.script},
                                {"duration_s", info.durationS},
                                {"updates_applied", info.updatesApplied},
                                {"full_updates", info.fullUpdates},
                                {"tool_states_sent", info.toolStatesSent},
                                {"relays_received", info.relaysReceived},
                                {"malformed_dropped", stats.malformed()},
                                {"updates_rejected", info.updatesRejected},
                                {"clock_offset_us", stats.clockOffsetUs},
                                {"packet_loss", stats.packetLoss},
                                {"packets_lost", stats.packetsLost},
                                {"rtt_us", windowJson(stats.rttUs)},
                                {"update_bytes", windowJson(stats.updateBytes)},
                                {"update_raw_bytes", windowJson(stats.updateRawBytes)},
                                {"update_latency_us", windowJson(stats.updateLatencyUs)},
                                {"apply_us", windowJson(stats.applyUs)},
                                {"haptic_round_trip_us", windowJson(stats.hapticRoundTripUs)},
                                {"modes",
                                 {{"dbi", modeStatsJson(stats.modes[size_t(Sync::Dbi)])},
                                  {"volume", modeStatsJson(stats.modes[size_t(Sync::Volume)])}}}};
    if (info.hapticLoop)
        j["haptics"] = {{"tool_rate_hz", info.toolRateHz},
                        {"rate_hz", info.hapticRateHz},
                        {"achieved_rate_hz", info.achievedRateHz},
                        {"lateness_p50_ms", info.latenessP50Ms},
                        {"lateness_p99_ms", info.latenessP99Ms},
                        {"ticks", info.hapticTicks},
                        {"models_received", info.hapticModels},
                        {"models_applied", info.modelsApplied},
                        {"models_dropped", info.modelsDropped},
                        {"force_round_trip_p50_us", stats.hapticRoundTripUs.percentile(50)},
                        {"force_round_trip_p99_us", stats.hapticRoundTripUs.percentile(99)}};
    j["channels"] = channelsJson(stats);
    return j;
}

std::string reportJson(const ReportInfo& info, const NetStats& stats) {
    return reportJsonValue(info, stats).dump(2, ' ', false, kReplaceInvalidUtf8) + "\n";
}

// The text forms below keep the layout of the server's report, which is still built as text.

std::string jsonString(const std::string& s) {
    return nlohmann::json(s).dump(-1, ' ', false, kReplaceInvalidUtf8);
}

std::string jsonNumber(double v) {
    return fmt::format("{:.6g}", v);
}

std::string jsonWindow(const SampleWindow& w) {
    return fmt::format(R"({{"count": {}, "mean": {}, "min": {}, "p50": {}, "p99": {}, "max": {}}})",
                       w.totalCount(), jsonNumber(w.mean()), jsonNumber(w.min()),
                       jsonNumber(w.percentile(50)), jsonNumber(w.percentile(99)),
                       jsonNumber(w.max()));
}

std::string jsonChannels(const NetStats& stats) {
    std::string j = "{";
    for (size_t c = 0; c < size_t(Channel::Count); ++c) {
        const Channel ch = Channel(c);
        const ChannelRates r = stats.averageRates(ch);
        j += fmt::format("{}\n    {}: {{\"bytes_in\": {}, \"bytes_out\": {}, \"messages_in\": {}, "
                         "\"messages_out\": {}, \"bytes_in_per_s\": {}, \"bytes_out_per_s\": {}, "
                         "\"messages_in_per_s\": {}, \"messages_out_per_s\": {}}}",
                         c ? "," : "", jsonString(channelName(ch)), stats.totalBytesIn(ch),
                         stats.totalBytesOut(ch), stats.totalMessagesIn(ch),
                         stats.totalMessagesOut(ch), jsonNumber(r.bytesInPerS),
                         jsonNumber(r.bytesOutPerS), jsonNumber(r.messagesInPerS),
                         jsonNumber(r.messagesOutPerS));
    }
    return j + "\n  }";
}

} // namespace trephine::net

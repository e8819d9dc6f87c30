#include "net/server_report.h"

namespace trephine::net {

namespace {

using Json = nlohmann::ordered_json;

Json window(const SampleWindow& w) {
    return {{"count", w.totalCount()}, {"mean", w.mean()},        {"min", w.min()},
            {"p50", w.percentile(50)}, {"p99", w.percentile(99)}, {"max", w.max()}};
}

Json channels(const NetStats& stats) {
    Json j = Json::object();
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

Json availability(const AvailabilityCounters& a) {
    return {{"connects_rate_limited", a.admission.rateLimited},
            {"connects_address_busy", a.admission.addressBusy},
            {"connects_pool_full", a.admission.poolFull},
            {"handshakes_reset", a.admission.handshakesReset},
            {"connects_displaced", a.admission.displaced},
            {"connects_cookieless", a.admission.cookieless},
            {"refused_busy", a.refusedBusy},
            {"idle_timeouts", a.idleTimeouts},
            {"views_deferred", a.viewsDeferred},
            {"views_coalesced", a.viewsCoalesced},
            {"views_over_total", a.viewsOverTotal},
            {"refused_view_total", a.refusedViewTotal},
            {"control_coalesced", a.controlCoalesced},
            {"control_dropped", a.controlDropped},
            {"names_repaired", a.namesRepaired},
            {"received_dropped", a.receivedDropped},
            {"peak_control_bytes", a.peakControlBytes}};
}

const char* syncName(Sync mode) {
    return mode == Sync::Dbi ? "dbi" : "volume";
}

} // namespace

ModeTotals ServerReport::modeTotals(Sync mode) const {
    ModeTotals t = modes[size_t(mode)].sent;
    t.clients = 0;
    for (const auto& [id, p] : peers)
        t.clients += p.participating() && p.sync == mode;
    return t;
}

nlohmann::ordered_json toJson(const ServerReport& r, const NetStats& stats) {
    const ServerCounters& c = r.counters;
    Json j = {{"port", r.port},
              {"volume", r.volume},
              {"max_clients", r.maxClients},
              {"clients", c.clients},
              {"tool_states_applied", c.toolStatesApplied},
              {"tool_states_dropped", c.toolStatesDropped},
              {"renders", c.renders},
              {"views_reused", c.viewsReused},
              {"pixels_kept", c.pixelsKept},
              {"renderer_fallbacks", c.rendererFallbacks},
              {"codings_shared", c.codingsShared},
              {"send_waits", c.sendWaits},
              {"send_waits_bounded", c.sendWaitsBounded},
              {"haptic_models_sent", c.hapticModelsSent},
              {"haptic_relays_sent", c.hapticRelaysSent},
              {"malformed_dropped", stats.malformed()},
              {"disconnected_for_malformed", c.malformedKicks},
              {"refused_server_full", c.refusedFull},
              {"hello_timeouts", c.helloTimeouts},
              {"views_refused", c.viewsRefused},
              {"annotations_refused", c.annotationsRefused},
              {"take_overs_refused", c.takeOversRefused},
              {"hand_links_refused", c.handLinksRefused},
              {"replay_controls_refused", c.replayControlsRefused},
              {"drilling_paused", c.drillingPaused},
              {"peak_in_flight_bytes", c.peakInFlightBytes},
              {"channels", channels(stats)},
              {"force_compute_us", window(r.forceComputeUs)}};
    Json modes = Json::object();
    for (Sync mode : {Sync::Dbi, Sync::Volume}) {
        const ModeTotals t = r.modeTotals(mode);
        const ModeReport& m = r.modes[size_t(mode)];
        modes[syncName(mode)] = {{"clients", t.clients},
                                 {"updates_sent", t.updates},
                                 {"full_updates_sent", t.fullUpdates},
                                 {"bytes_sent", t.bytes},
                                 {"raw_bytes_sent", t.rawBytes},
                                 {"erode_us", window(m.erodeUs)},
                                 {"render_us", window(m.renderUs)},
                                 {"encode_us", window(m.encodeUs)}};
    }
    j["modes"] = std::move(modes);
    j["availability"] = availability(r.availability);
    j["haptic_service_us"] = window(r.hapticServiceUs);
    j["security"] = securityJson(r.security);
    Json peers = Json::array();
    for (const auto& [id, p] : r.peers)
        peers.push_back({{"id", id},
                         {"name", p.name},
                         {"role", p.role == Role::Instructor ? "instructor" : "trainee"},
                         {"hello", p.hello},
                         {"connected", p.disconnectedUs == 0},
                         {"bytes_in", p.bytesIn},
                         {"bytes_out", p.bytesOut},
                         {"messages_in", p.messagesIn},
                         {"messages_out", p.messagesOut},
                         {"tool_states", p.toolStates},
                         {"haptic_models", p.hapticModels},
                         {"haptic_relays", p.hapticRelays},
                         {"malformed", p.malformed},
                         {"view_requests", p.viewRequests},
                         {"views_refused", p.viewsRefused},
                         {"charged_us", p.chargedUs},
                         {"net_charged_us", p.netChargedUs},
                         {"sync", syncName(p.sync)},
                         {"sync_switches", p.syncSwitches},
                         {"kicked", p.kicked}});
    j["peers"] = std::move(peers);
    j["assessment"] = toJson(r.assessment);
    j["participants"] = toJson(r.participants);
    return j;
}

std::string toJsonText(const ServerReport& report, const NetStats& stats) {
    return jsonText(toJson(report, stats));
}

std::string jsonText(const nlohmann::ordered_json& j) {
    return j.dump(2, ' ', false, Json::error_handler_t::replace) + "\n";
}

} // namespace trephine::net

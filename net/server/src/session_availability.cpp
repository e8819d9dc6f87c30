// The session policy's availability rules (net/session_policy.h): places go to admitted peers
// only, silent participants are sent away, a peer's view requests spend a render budget, and all
// views together stay under a pixel total, so the server's memory has a bound whatever peers send.
#include "net/session_policy.h"

#include "net/view.h"

#include <algorithm>

namespace trephine::net {

namespace {

int64_t pixelsOf(const ViewSpec& v) {
    return int64_t(v.width) * int64_t(v.height);
}

} // namespace

bool SessionPolicy::admitted(uint16_t id) const {
    auto it = m_peers.find(id);
    return it != m_peers.end() && it->second.hello && !it->second.kicked;
}

size_t SessionPolicy::admittedCount() const {
    return size_t(std::count_if(m_peers.begin(), m_peers.end(), [](const auto& kv) {
        return kv.second.hello && !kv.second.kicked;
    }));
}

// The pixels a view of peer `id` may have: the total less every other admitted peer's views.
int64_t SessionPolicy::freeViewPixels(uint16_t id) const {
    int64_t free = m_config.maxTotalViewPixels;
    for (const auto& [other, p] : m_peers)
        if (other != id && p.hello && !p.kicked)
            free -= p.pixels;
    return free;
}

// Whether peer `id` viewing `v` would take every admitted peer's views past the total.
bool SessionPolicy::overViewTotal(uint16_t id, const ViewSpec& v) const {
    return pixelsOf(v) > freeViewPixels(id);
}

void SessionPolicy::refuseView(uint16_t id, uint32_t requestId, PolicyOutput& out) {
    m_book.record([&](ServerReport& rep) {
        ++rep.availability.viewsOverTotal;
        ++rep.peers[id].viewsRefused;
    });
    ViewRefused refused{requestId,
                        uint32_t(std::clamp<int64_t>(freeViewPixels(id), 0, UINT32_MAX))};
    out.messages.push_back({{id}, Channel::Control, encodeMessage(refused)});
}

// A view request within the limits: to the simulation now if the peer's render budget covers
// it, else it waits (replacing any older waiting one) until update() finds it due.
bool SessionPolicy::viewRequest(uint16_t id, Peer& p, const ViewRequest& r, uint64_t now,
                                PolicyOutput& out) {
    if (overViewTotal(id, r.view)) {
        refuseView(id, r.requestId, out);
        return true;
    }
    const bool replaced = p.waitingView.has_value();
    if (!replaced && p.viewPixels.take(double(pixelsOf(r.view)), now)) {
        applyView(id, p, r, out);
        return true;
    }
    p.waitingView = r;
    walkBy(p.viewPixels.dueUs(double(pixelsOf(r.view)), now));
    m_book.record([&](ServerReport& rep) {
        ++rep.availability.viewsDeferred;
        rep.availability.viewsCoalesced += replaced;
    });
    return true;
}

void SessionPolicy::applyView(uint16_t id, Peer& p, const ViewRequest& r, PolicyOutput& out) {
    p.pixels = pixelsOf(r.view);
    walkBy(0); // a waiting view may no longer fit the total
    out.events.push_back({0, ViewEvent{id, r.view, r.requestId}});
    ParticipantView seen{id, r.view};
    const std::vector<uint16_t> followers = m_follow.setView(id, r.view);
    if (!followers.empty()) // instructors viewing as this one
        out.messages.push_back({followers, Channel::Control, encodeMessage(seen)});
}

void SessionPolicy::updateAvailability(uint64_t now, PolicyOutput& out) {
    const uint64_t idleUs = idleTimeoutUs();
    for (auto& [id, p] : m_peers) {
        if (!p.hello || p.kicked)
            continue;
        if (now > p.heardUs && now - p.heardUs > idleUs) {
            m_book.record([](ServerReport& r) { ++r.availability.idleTimeouts; });
            kick(id, p, RefuseReason::Idle, out, now);
            continue;
        }
        walkBy(p.heardUs + idleUs + 1);
        if (!p.waitingView)
            continue;
        // Refused before it is charged: a view the total has no room for costs no budget.
        const ViewRequest r = *p.waitingView;
        if (overViewTotal(id, r.view)) {
            p.waitingView.reset();
            refuseView(id, r.requestId, out);
        } else if (p.viewPixels.take(double(pixelsOf(r.view)), now)) {
            p.waitingView.reset();
            applyView(id, p, r, out);
        } else {
            walkBy(p.viewPixels.dueUs(double(pixelsOf(r.view)), now));
        }
    }
}

// The hello's name, valid and not another participant's (net/budgets.h, admitName).
std::string SessionPolicy::uniqueName(uint16_t id, const std::string& name) {
    std::set<std::string> taken;
    for (const auto& [other, p] : m_peers)
        if (other != id && p.hello && !p.kicked)
            taken.insert(p.helloMsg.name);
    bool repaired = false;
    std::string out = admitName(name, taken, kMaxNameLength, &repaired);
    if (repaired)
        m_book.record([](ServerReport& r) { ++r.availability.namesRepaired; });
    return out;
}

} // namespace trephine::net

#include "net/fair_share.h"

#include <algorithm>
#include <cassert>

namespace trephine::net {

// A peer's start tag: its finish time, or the virtual time if it fell behind it while idle (so
// idle time is not saved up as credit to spend later in a burst).
uint64_t FairShare::tag(uint16_t peer) const {
    auto it = m_finish.find(peer);
    return std::max(it == m_finish.end() ? 0 : it->second, m_virtual);
}

size_t FairShare::pick(std::span<const uint16_t> ready) {
    assert(!ready.empty() && "FairShare::pick needs a peer with work");
    size_t best = 0;
    for (size_t i = 1; i < ready.size(); ++i)
        if (tag(ready[i]) < tag(ready[best]))
            best = i;
    m_virtual = tag(ready[best]);
    return best;
}

void FairShare::charge(std::span<const uint16_t> peers, uint64_t us) {
    if (peers.empty())
        return;
    const uint64_t each = us / peers.size();
    for (uint16_t p : peers)
        charge(p, each);
}

void FairShare::charge(uint16_t peer, uint64_t us) {
    m_finish[peer] = tag(peer) + us;
    m_total[peer] += us;
}

uint64_t FairShare::charged(uint16_t peer) const {
    auto it = m_total.find(peer);
    return it == m_total.end() ? 0 : it->second;
}

// [SECTION] the network thread's inbox

bool FairInbox::push(uint16_t peer, Channel channel, std::span<const uint8_t> bytes) {
    auto it = m_queues.find(peer);
    const size_t count = it == m_queues.end() ? 0 : it->second.messages.size();
    const size_t held = it == m_queues.end() ? 0 : it->second.bytes;
    if (count >= m_maxWaiting || held + bytes.size() > m_maxWaitingBytes)
        return false;
    Queue& q = it == m_queues.end() ? m_queues[peer] : it->second;
    q.messages.push_back({channel, {bytes.begin(), bytes.end()}});
    q.bytes += bytes.size();
    ++m_waiting;
    return true;
}

size_t FairInbox::waiting(uint16_t peer) const {
    auto it = m_queues.find(peer);
    return it == m_queues.end() ? 0 : it->second.messages.size();
}

// The handler may queue more, or drain another peer: the message is taken out first.
void FairInbox::handleOne(uint16_t peer, const Handler& handle) {
    auto it = m_queues.find(peer);
    Message m = std::move(it->second.messages.front());
    it->second.messages.pop_front();
    it->second.bytes -= m.bytes.size();
    --m_waiting;
    if (it->second.messages.empty())
        m_queues.erase(it);
    const uint64_t t0 = m_share.now();
    handle(peer, m.channel, m.bytes);
    m_share.charge(peer, m_share.now() - t0);
}

size_t FairInbox::serve(uint64_t sliceUs, const Handler& handle) {
    const uint64_t start = m_share.now();
    size_t handled = 0;
    std::vector<uint16_t> ready;
    while (m_waiting > 0 && (handled == 0 || m_share.now() - start < sliceUs)) {
        ready.clear();
        for (const auto& [peer, q] : m_queues)
            ready.push_back(peer);
        handleOne(ready[m_share.pick(ready)], handle);
        ++handled;
    }
    return handled;
}

size_t FairInbox::drain(uint16_t peer, const Handler& handle) {
    for (size_t handled = 0; handled < kDrainMessages && waiting(peer) > 0; ++handled)
        handleOne(peer, handle);
    const size_t dropped = waiting(peer);
    if (auto it = m_queues.find(peer); it != m_queues.end()) {
        m_waiting -= it->second.messages.size();
        m_queues.erase(it);
    }
    m_share.forget(peer);
    return dropped;
}

} // namespace trephine::net

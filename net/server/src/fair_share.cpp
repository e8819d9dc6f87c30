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

} // namespace trephine::net

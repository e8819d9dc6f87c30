// The simulation thread's time shared fairly among peers (docs/session.md, "Availability"):
// start-time fair queuing over each peer's queue of work, every piece charged in measured time to
// the peers it was done for. A peer alone gets all the time; a peer that asks for more than its
// share waits behind the others, and only its own work piles up.
#pragma once

#include "net/outbox.h"

#include <cstdint>
#include <map>
#include <span>

namespace trephine::net {

class FairShare {
public:
    // `clock` measures the work (microseconds, any origin): the steady clock on a server, a fake
    // one in tests. The pumped server's time stands still within a pass, so it is not that one.
    explicit FairShare(ServerClock clock) : m_clock(std::move(clock)) {}

    uint64_t now() const { return m_clock(); }
    // Which of `ready` (peers with work waiting, at least one) goes next: the one whose charged
    // time, lifted to the session's virtual time when it was idle, is least; ties by position.
    // A peer that was idle banks nothing: it starts level with the busiest, so it goes first.
    size_t pick(std::span<const uint16_t> ready);
    // The picked piece of work is done: `us` is charged to `peers` in equal parts.
    void charge(std::span<const uint16_t> peers, uint64_t us);
    // Work done for one peer outside the queue (a volume transfer, an update's coding).
    void charge(uint16_t peer, uint64_t us);
    void forget(uint16_t peer) {
        m_finish.erase(peer);
        m_total.erase(peer); // a later peer given the same id starts from nothing
    }
    // The time charged to `peer` in all (what the report shows).
    uint64_t charged(uint16_t peer) const;

private:
    uint64_t tag(uint16_t peer) const;

    ServerClock m_clock;
    // Per peer: its virtual finish time (charged time, lifted on each idle spell), and in all.
    std::map<uint16_t, uint64_t> m_finish, m_total;
    uint64_t m_virtual = 0; // the start tag of the piece picked last
};

} // namespace trephine::net

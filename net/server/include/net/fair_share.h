// The server's time shared fairly among peers (docs/session.md, "Availability"): start-time fair
// queuing over each peer's queue of work, every piece charged in measured time to the peers it
// was done for; FairShare on the simulation thread, FairInbox (the same rule over what peers
// send) on the network thread. A peer alone gets all the time; a peer that asks for more than
// its share waits behind the others, and only its own work piles up.
#pragma once

#include "net/enet_host.h"
#include "net/outbox.h"

#include <cstdint>
#include <deque>
#include <functional>
#include <map>
#include <span>
#include <vector>

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
    // Where `peer` stands in the fair order (less goes first): its start tag, the order pick()
    // uses. Unlike charged(), work done while no other peer was waiting does not put it behind a
    // newcomer for good.
    uint64_t standing(uint16_t peer) const { return tag(peer); }

private:
    uint64_t tag(uint16_t peer) const;

    ServerClock m_clock;
    // Per peer: its virtual finish time (charged time, lifted on each idle spell), and in all.
    std::map<uint16_t, uint64_t> m_finish, m_total;
    uint64_t m_virtual = 0; // the start tag of the piece picked last
};

// The network thread's side of the same rule: what peers send waits in a queue per peer and is
// handled in fair order, each message's handling (opening or refusing it, the policy, what it
// sends) charged to its sender in measured time, and so is other work done for a peer there (its
// updates' sealing and sending, its new codes). A peer whose messages cost more falls behind in
// its own queue; an honest peer's message waits behind at most one message of another's.
class FairInbox {
public:
    using Handler = std::function<void(uint16_t peer, Channel, std::span<const uint8_t>)>;
    // The most bytes a peer may have queued. A client's messages are a few kB at most (a hello,
    // a mark's label, a list of hand links), so an honest queue never nears it; a flood of large
    // packets costs its sender's messages, not the server's memory (72 peers: 72 MiB at most).
    static constexpr size_t kMaxWaitingBytes = size_t(1) << 20;
    // `clock` as FairShare's; a peer with `maxWaiting` messages or `maxWaitingBytes` queued has
    // the next dropped.
    explicit FairInbox(ServerClock clock, size_t maxWaiting = 4096,
                       size_t maxWaitingBytes = kMaxWaitingBytes)
        : m_share(std::move(clock)), m_maxWaiting(maxWaiting), m_maxWaitingBytes(maxWaitingBytes) {}

    // Queues what `peer` sent; false when its queue is full (the message is dropped).
    bool push(uint16_t peer, Channel channel, std::span<const uint8_t> bytes);
    // Handles waiting messages, the least charged peer's first, until none waits or `sliceUs`
    // of work is done (at least one is handled); returns how many were.
    size_t serve(uint64_t sliceUs, const Handler& handle);
    // Handles the first kDrainMessages `peer` has waiting, in order (it is leaving), drops the
    // rest and forgets it; returns how many were dropped. An honest peer's queue is served
    // every pass, so it leaves with a few at most; a flood then gone is not handled at once,
    // outside the fair order.
    static constexpr size_t kDrainMessages = 64;
    size_t drain(uint16_t peer, const Handler& handle);
    // Work done for `peer` outside its messages; `us` measured by the caller.
    void charge(uint16_t peer, uint64_t us) { m_share.charge(peer, us); }
    uint64_t now() const { return m_share.now(); }
    size_t waiting() const { return m_waiting; }
    size_t waiting(uint16_t peer) const;
    uint64_t charged(uint16_t peer) const { return m_share.charged(peer); }
    uint64_t standing(uint16_t peer) const { return m_share.standing(peer); }

private:
    struct Message {
        Channel channel;
        std::vector<uint8_t> bytes;
    };
    struct Queue {
        std::deque<Message> messages;
        size_t bytes = 0;
    };
    void handleOne(uint16_t peer, const Handler& handle);

    FairShare m_share;
    size_t m_maxWaiting, m_maxWaitingBytes;
    std::map<uint16_t, Queue> m_queues; // only peers with something waiting
    size_t m_waiting = 0;
};

} // namespace trephine::net

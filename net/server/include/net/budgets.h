// Per-peer budgets of the session server, so one peer cannot take what the others need: a token
// bucket (RateBudget: the view pixels a peer may have rendered per second), the control channel's
// byte budget with latest-state coalescing (ControlBudget), and hello names made valid and unique
// (admitName). Plain classes with time passed in; the policy and the server's network thread use
// them. docs/session.md ("Availability") gives the figures.
#pragma once

#include <cstdint>
#include <functional>
#include <map>
#include <set>
#include <span>
#include <string>
#include <utility>
#include <vector>

namespace trephine::net {

// `perS` units a second, at most `burst` saved up; starts full.
class RateBudget {
public:
    RateBudget(double perS, double burst) : m_perS(perS), m_burst(burst), m_tokens(burst) {}
    // Takes `amount` at `nowUs` when the budget holds it; false (nothing taken) otherwise.
    bool take(double amount, uint64_t nowUs);
    bool covers(double amount, uint64_t nowUs);
    // Takes `amount` whatever the budget holds (work measured once done): a debt delays what
    // comes next.
    void spend(double amount, uint64_t nowUs);
    // When the budget will hold `amount` (`nowUs` when it does now).
    uint64_t dueUs(double amount, uint64_t nowUs);

private:
    void refill(uint64_t nowUs);
    double m_perS, m_burst, m_tokens;
    uint64_t m_lastUs = 0;
    bool m_started = false;
};

// The control channel (reliable) of each peer holds at most `budgetBytes` in ENet's hands. Past
// it, a message that is a latest state (newest wins in net/protocol.h's list: roster, marks, a
// followed view, the codes) waits as the newest of its kind and goes once the backlog drains; a
// pong is dropped (the client pings again); anything else (a welcome, a scene: once per join) is
// sent: the session cannot go on without it.
class ControlBudget {
public:
    enum class Action { Send, Hold, Drop };
    struct Counts {
        uint64_t coalesced = 0, dropped = 0;
    };

    explicit ControlBudget(int64_t budgetBytes) : m_budget(budgetBytes) {}
    // Decides for `message` to `peer`, whose control bytes ENet holds come to `held`. A message
    // sent supersedes any of its kind held for the peer.
    Action offer(uint16_t peer, std::span<const uint8_t> message, int64_t held);
    // The held messages of peers whose backlog is now under budget, to send, oldest kind first.
    std::vector<std::pair<uint16_t, std::vector<uint8_t>>>
    due(const std::function<int64_t(uint16_t)>& held);
    void forget(uint16_t peer) { m_held.erase(peer); }
    bool holding() const { return !m_held.empty(); }
    const Counts& counts() const { return m_counts; }

private:
    int64_t m_budget;
    std::map<uint16_t, std::map<uint8_t, std::vector<uint8_t>>> m_held; // peer -> type -> message
    Counts m_counts;
};

// A hello's name as the session lists it: bytes that are not UTF-8 become U+FFFD, control
// characters become spaces, and a name another participant has ("alice") becomes "alice (2)"
// (the lowest free number), cut to fit `maxBytes`. `repaired` says whether it changed.
std::string admitName(const std::string& name, const std::set<std::string>& taken, size_t maxBytes,
                      bool* repaired = nullptr);

} // namespace trephine::net

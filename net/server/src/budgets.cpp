#include "net/budgets.h"

#include "net/messages.h"

#include <algorithm>
#include <cmath>

namespace trephine::net {

// [SECTION] RateBudget

void RateBudget::refill(uint64_t nowUs) {
    if (!m_started) {
        m_started = true;
        m_lastUs = nowUs;
        return;
    }
    if (nowUs > m_lastUs) {
        m_tokens = std::min(m_burst, m_tokens + double(nowUs - m_lastUs) * 1e-6 * m_perS);
        m_lastUs = nowUs;
    }
}

bool RateBudget::covers(double amount, uint64_t nowUs) {
    refill(nowUs);
    return m_tokens >= amount;
}

void RateBudget::spend(double amount, uint64_t nowUs) {
    refill(nowUs);
    m_tokens -= amount;
}

uint64_t RateBudget::dueUs(double amount, uint64_t nowUs) {
    refill(nowUs);
    if (m_tokens >= amount)
        return nowUs;
    if (m_perS <= 0.0)
        return UINT64_MAX;
    // Less a millionth of a microsecond, the refill's float error is no microsecond more; and
    // what it does not yet cover is due a microsecond on at the soonest.
    return nowUs +
           std::max<uint64_t>(1, uint64_t(std::ceil((amount - m_tokens) / m_perS * 1e6 - 1e-6)));
}

bool RateBudget::take(double amount, uint64_t nowUs) {
    if (!covers(amount, nowUs))
        return false;
    m_tokens -= amount;
    return true;
}

// [SECTION] ControlBudget

namespace {

// Control messages whose newest copy says all an older one said (the list's newest wins).
bool latestState(uint8_t type) {
    const MessageInfo* m = messageInfo(type);
    return m && m->newestWins && m->channel == Channel::Control;
}

} // namespace

ControlBudget::Action ControlBudget::offer(uint16_t peer, std::span<const uint8_t> message,
                                           int64_t held) {
    const uint8_t type = message.empty() ? 0 : message[0];
    auto peerHeld = m_held.find(peer);
    if (held < m_budget) {
        if (latestState(type) && peerHeld != m_held.end() && peerHeld->second.erase(type)) {
            ++m_counts.coalesced;
            if (peerHeld->second.empty())
                m_held.erase(peerHeld);
        }
        return Action::Send;
    }
    if (latestState(type)) {
        auto& slot = m_held[peer][type];
        m_counts.coalesced += !slot.empty();
        slot.assign(message.begin(), message.end());
        return Action::Hold;
    }
    if (MessageType(type) == MessageType::Pong) {
        ++m_counts.dropped;
        return Action::Drop;
    }
    return Action::Send;
}

std::vector<std::pair<uint16_t, std::vector<uint8_t>>>
ControlBudget::due(const std::function<int64_t(uint16_t)>& held) {
    std::vector<std::pair<uint16_t, std::vector<uint8_t>>> out;
    for (auto it = m_held.begin(); it != m_held.end();) {
        if (held(it->first) >= m_budget) {
            ++it;
            continue;
        }
        for (auto& [type, message] : it->second)
            out.emplace_back(it->first, std::move(message));
        it = m_held.erase(it);
    }
    return out;
}

// [SECTION] names

namespace {

// The length of the UTF-8 sequence at s[i] when it is valid (no overlong forms, no surrogates,
// at most U+10FFFF), else 0.
size_t utf8Length(const std::string& s, size_t i) {
    const auto b = [&](size_t k) { return uint8_t(s[i + k]); };
    const size_t left = s.size() - i;
    const uint8_t c = b(0);
    if (c < 0x80)
        return 1;
    auto cont = [&](size_t k) { return k < left && (b(k) & 0xC0) == 0x80; };
    if (c >= 0xC2 && c <= 0xDF)
        return cont(1) ? 2 : 0;
    if (c >= 0xE0 && c <= 0xEF) {
        if (!cont(1) || !cont(2))
            return 0;
        if ((c == 0xE0 && b(1) < 0xA0) || (c == 0xED && b(1) > 0x9F))
            return 0;
        return 3;
    }
    if (c >= 0xF0 && c <= 0xF4) {
        if (!cont(1) || !cont(2) || !cont(3))
            return 0;
        if ((c == 0xF0 && b(1) < 0x90) || (c == 0xF4 && b(1) > 0x8F))
            return 0;
        return 4;
    }
    return 0;
}

// Valid UTF-8 with control characters as spaces.
std::string validText(const std::string& s) {
    std::string out;
    for (size_t i = 0; i < s.size();) {
        const size_t n = utf8Length(s, i);
        if (n == 0) {
            out += "\xEF\xBF\xBD";
            ++i;
        } else if (n == 1 && (uint8_t(s[i]) < 0x20 || s[i] == 0x7F)) {
            out += ' ';
            ++i;
        } else {
            out.append(s, i, n);
            i += n;
        }
    }
    return out;
}

// The longest prefix of valid UTF-8 `s` of at most `maxBytes` that ends on a character.
std::string cut(const std::string& s, size_t maxBytes) {
    if (s.size() <= maxBytes)
        return s;
    size_t end = maxBytes;
    while (end > 0 && (uint8_t(s[end]) & 0xC0) == 0x80)
        --end;
    return s.substr(0, end);
}

} // namespace

std::string admitName(const std::string& name, const std::set<std::string>& taken, size_t maxBytes,
                      bool* repaired) {
    const std::string base = cut(validText(name), maxBytes);
    std::string out = base;
    for (int n = 2; taken.count(out); ++n) {
        const std::string suffix = " (" + std::to_string(n) + ")";
        out = cut(base, maxBytes > suffix.size() ? maxBytes - suffix.size() : 0) + suffix;
    }
    if (repaired)
        *repaired = out != name;
    return out;
}

} // namespace trephine::net

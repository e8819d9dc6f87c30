#include "net/view_follow.h"

namespace trephine::net {

std::vector<uint16_t> ViewFollowers::setView(uint16_t id, const ViewSpec& view) {
    m_views[id] = view;
    std::vector<uint16_t> out;
    for (const auto& [follower, target] : m_following)
        if (target == id)
            out.push_back(follower);
    return out;
}

std::optional<ViewSpec> ViewFollowers::follow(uint16_t follower, uint16_t target) {
    m_following.erase(follower);
    if (target == 0 || target == follower)
        return std::nullopt;
    const auto it = m_views.find(target);
    if (it == m_views.end())
        return std::nullopt; // nobody of that id said hello: nothing to follow
    m_following[follower] = target;
    return it->second;
}

void ViewFollowers::leave(uint16_t id) {
    m_views.erase(id);
    m_following.erase(id);
    std::erase_if(m_following, [&](const auto& f) { return f.second == id; });
}

uint16_t ViewFollowers::following(uint16_t follower) const {
    const auto it = m_following.find(follower);
    return it == m_following.end() ? 0 : it->second;
}

} // namespace trephine::net

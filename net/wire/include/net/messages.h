// The message list (TREPHINE_MESSAGES, net/protocol.h) as a table and a type list, and the one
// dispatch every receiver goes through: a receiver that lacks a handler for a message the table
// says it receives does not compile, and a type it only sends is refused as malformed.
#pragma once

#include "net/assessment_protocol.h"
#include "net/enet_host.h"
#include "net/handlers.h"
#include "net/protocol.h"
#include "net/replay_protocol.h"
#include "net/scene.h"

#include <array>
#include <cstdint>
#include <map>
#include <optional>
#include <span>
#include <string_view>
#include <tuple>
#include <type_traits>
#include <variant>
#include <vector>

namespace trephine::net {

// Who sends a message.
enum class Direction : uint8_t { ClientToServer, ServerToClient, Both };
// The end that receives one.
enum class Side : uint8_t { Client, Server };

struct MessageInfo {
    MessageType type;
    std::string_view name;
    Direction direction;
    Channel channel;
    bool newestWins;
    uint32_t since; // the protocol version it came in
};

inline constexpr std::array kMessages = {
#define TREPHINE_MESSAGE_INFO(name, id, dir, ch, newest, version)                                  \
    MessageInfo{MessageType::name, #name, Direction::dir, Channel::ch, newest, version},
    TREPHINE_MESSAGES(TREPHINE_MESSAGE_INFO)
#undef TREPHINE_MESSAGE_INFO
};

// The entry of a type byte, or null for a byte no message has.
constexpr const MessageInfo* messageInfo(uint8_t type) {
    for (const MessageInfo& m : kMessages)
        if (uint8_t(m.type) == type)
            return &m;
    return nullptr;
}
constexpr const MessageInfo& messageInfo(MessageType type) {
    return *messageInfo(uint8_t(type));
}

constexpr bool receives(Side side, Direction d) {
    return d == Direction::Both ||
           d == (side == Side::Server ? Direction::ClientToServer : Direction::ServerToClient);
}

// peekMessageType refuses bytes at and past kMessageTypeCount only, so the bytes below it are
// all taken.
static_assert(
    [] {
        for (size_t i = 0; i < kMessages.size(); ++i)
            if (uint8_t(kMessages[i].type) != i + 1)
                return false;
        return kMessages.size() + 1 == kMessageTypeCount;
    }(),
    "message types are 1, 2, 3, ... in the order of the list");

template <typename... Ms>
struct MessageList {};

namespace detail {
template <typename First, typename... Rest>
MessageList<Rest...> dropFirst(MessageList<First, Rest...>);
} // namespace detail

// Every message struct, in the order of the list.
using AllMessages = decltype(detail::dropFirst(
#define TREPHINE_MESSAGE_TYPE(name, id, dir, ch, newest, version) , name
    MessageList<void TREPHINE_MESSAGES(TREPHINE_MESSAGE_TYPE)>{}
#undef TREPHINE_MESSAGE_TYPE
    ));

namespace detail {
template <typename... Ms>
constexpr bool typesMatch(MessageList<Ms...>) {
    size_t i = 0;
    return ((Ms::kType == kMessages[i++].type) && ...);
}
} // namespace detail
static_assert(detail::typesMatch(AllMessages{}), "a struct's kType differs from its list entry");

// What a handler is called with: the message's struct as a type, nothing decoded yet.
template <typename M>
struct MessageTag {
    using Type = M;
};

namespace detail {
template <typename M, typename R, typename H>
void dispatchTo(H& handler, R& result) {
    static_assert(std::is_invocable_r_v<R, H&, MessageTag<M>>,
                  "the handler has no overload for a message this side receives (net/messages.h)");
    result = handler(MessageTag<M>{});
}
} // namespace detail

// Calls handler(MessageTag<M>{}) for the message `type` names when `side` receives it (the
// table's direction) and returns what it returns; `otherwise` for a byte of no message or of one
// only `side` sends.
template <Side side, typename R, typename H>
R dispatchReceived(uint8_t type, H&& handler, R otherwise) {
    R result = otherwise;
    [&]<typename... Ms>(MessageList<Ms...>) {
        (void)((uint8_t(Ms::kType) == type
                    ? (
                          [&] {
                              if constexpr (receives(side, messageInfo(Ms::kType).direction))
                                  detail::dispatchTo<Ms>(handler, result);
                          }(),
                          true)
                    : false) ||
               ...);
    }(AllMessages{});
    return result;
}

// As dispatchReceived, for every message whoever sends it (tests, tools that read any packet).
template <typename R, typename H>
R dispatchAny(uint8_t type, H&& handler, R otherwise) {
    R result = otherwise;
    [&]<typename... Ms>(MessageList<Ms...>) {
        (void)((uint8_t(Ms::kType) == type ? (detail::dispatchTo<Ms>(handler, result), true)
                                           : false) ||
               ...);
    }(AllMessages{});
    return result;
}

// The newest message of each kind a receiver keeps whole, by type: state whose newer message says
// all an older one said (the table's newest wins), held as its wire bytes so that a store is a
// value (equal stores hold the same messages).
class MessageStore {
public:
    // Keeps `data` as the newest M; false (nothing kept) when it does not decode as one.
    template <typename M>
    bool put(std::span<const uint8_t> data) {
        M m;
        if (!decodeMessage(data, m))
            return false;
        m_bytes[M::kType].assign(data.begin(), data.end());
        return true;
    }
    template <typename M>
    std::optional<M> get() const {
        auto it = m_bytes.find(M::kType);
        M m;
        if (it == m_bytes.end() || !decodeMessage(std::span<const uint8_t>(it->second), m))
            return std::nullopt;
        return m;
    }
    bool empty() const { return m_bytes.empty(); }
    bool operator==(const MessageStore&) const = default;

private:
    std::map<MessageType, std::vector<uint8_t>> m_bytes;
};

namespace detail {
template <template <typename> typename Keep, typename... Ms>
auto variantOf(MessageList<Ms...>) -> decltype(std::tuple_cat(
    std::conditional_t<Keep<Ms>::value, std::tuple<Ms>, std::tuple<>>{}...));
template <typename Tuple>
struct VariantOfTuple;
template <typename... Ms>
struct VariantOfTuple<std::tuple<Ms...>> {
    using Type = std::variant<Ms...>;
};
} // namespace detail

// A variant of the messages of the list that `Keep<M>::value` selects, in the list's order.
template <template <typename> typename Keep>
using MessageVariant =
    typename detail::VariantOfTuple<decltype(detail::variantOf<Keep>(AllMessages{}))>::Type;

} // namespace trephine::net

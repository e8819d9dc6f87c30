// A visitor made of lambdas, one overload per type: std::visit(Handlers{...}, event) for events
// (net/events.h), dispatchReceived(type, Handlers{...}) for messages (net/messages.h).
#pragma once

namespace trephine::net {

template <typename... Fs>
struct Handlers : Fs... {
    using Fs::operator()...;
};
template <typename... Fs>
Handlers(Fs...) -> Handlers<Fs...>;

} // namespace trephine::net

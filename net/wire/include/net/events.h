// The session's events, one type each with its serialize: what the simulation applies (a join,
// a view, a tool state, a cut ...) and what the session policy decides (a hello, a mark, a
// take-over ...). The server queues them for the simulation step (net/sim_step.h) and writes
// the same values to the session log (net/session_log.h); a replay plays them back.
// docs/recording.md lists their encodings.
#pragma once

#include "libsim/box.h"
#include "net/handlers.h"
#include "net/protocol.h"
#include "net/serialize.h"

#include <atomic>
#include <cstdint>
#include <memory>
#include <string>
#include <type_traits>
#include <utility>
#include <variant>
#include <vector>

namespace trephine::net {

// The session log's format, which every event's encoding is part of. 1: the first format
// (docs/recording.md). 2: the header's assessment zones, each Tool event's haptic force.
inline constexpr uint32_t kLogVersion = 2;
// A log frame's payload is at most this long (a Voxels event of the largest volume fits).
inline constexpr uint32_t kMaxLogRecordBytes = 1u << 30;

// Every member has an initializer: an event made from its first fields ({id}, {.client = id}) is
// whole, and -Wextra agrees.

// [SECTION] what the simulation applies, in the order it applies it

struct JoinEvent {
    uint16_t client = 0;
    ViewSpec view{};
    Codec codec = Codec::Raw;
    Sync sync = Sync::Dbi;
    Codec volumeCodec = Codec::Raw;
    // Not logged: the Hello before it holds the name and role the assessment lists it by, and
    // the count of its bytes ENet holds (Host::InFlight) is the live process's (none: no limit).
    Role role = Role::Trainee;
    std::string name{};
    std::shared_ptr<std::atomic<int64_t>> inFlight{};

    template <typename S>
    bool serialize(S& s, uint32_t) {
        return s.integer(client) && view.serialize(s) && s.ranged(codec, Codec::Raw, Codec::Zstd) &&
               s.ranged(sync, Sync::Dbi, Sync::Volume) &&
               s.ranged(volumeCodec, Codec::Raw, Codec::Zstd);
    }
};

struct ViewEvent {
    uint16_t client = 0;
    ViewSpec view{};
    uint32_t viewId = 0;

    template <typename S>
    bool serialize(S& s, uint32_t) {
        return s.integer(client) && view.serialize(s) && s.integer(viewId);
    }
};

// As the simulation gets it: drilling cleared while an instructor holds the trainee.
struct ToolEvent {
    uint16_t client = 0;
    ToolState tool{};
    float forceN = -1.0f; // the haptic answer's force magnitude (< 0: none; format 1: none)

    template <typename S>
    bool serialize(S& s, uint32_t version) {
        return s.integer(client) && tool.serialize(s) &&
               (version < 2 || serializeFinite(s, forceN));
    }
};

struct LeaveEvent {
    uint16_t client = 0;

    template <typename S>
    bool serialize(S& s, uint32_t) {
        return s.integer(client);
    }
};

template <typename S>
bool serializeBox(S& s, Box3i& box) {
    return s.integer(box.lo.x) && s.integer(box.lo.y) && s.integer(box.lo.z) &&
           s.integer(box.hi.x) && s.integer(box.hi.y) && s.integer(box.hi.z);
}

// An instructor's or the host's cut: the box is emptied to Air.
struct CutEvent {
    Box3i box{};

    template <typename S>
    bool serialize(S& s, uint32_t) {
        return serializeBox(s, box);
    }
};

// A design switch (DBI or replicated volume).
struct SyncEvent {
    uint16_t client = 0;
    Sync sync = Sync::Dbi;
    Codec volumeCodec = Codec::Raw;

    template <typename S>
    bool serialize(S& s, uint32_t) {
        return s.integer(client) && s.ranged(sync, Sync::Dbi, Sync::Volume) &&
               s.ranged(volumeCodec, Codec::Raw, Codec::Zstd);
    }
};

// Voxels written wholesale, x fastest: box.count() densities and materials.
struct VoxelsEvent {
    Box3i box{};
    std::vector<uint8_t> density{}, material{};

    template <typename S>
    bool serialize(S& s, uint32_t) {
        return serializeBox(s, box) && s.blob(density, kMaxLogRecordBytes / 2) &&
               s.blob(material, kMaxLogRecordBytes / 2) && density.size() == material.size();
    }
};

// [SECTION] what the session policy decided

// A participant, listed from here on.
struct HelloEvent {
    uint16_t client = 0;
    Role role = Role::Trainee;
    std::string name{};

    template <typename S>
    bool serialize(S& s, uint32_t) {
        return s.integer(client) && s.ranged(role, Role::Trainee, Role::Instructor) &&
               s.string(name, kMaxNameLength);
    }
};

// Add: the mark with the id and author the server gave it. Remove: mark.id. Clear: all.
struct MarkEvent {
    Annotate::Op op = Annotate::Op::Add;
    AnnotationInfo mark{};

    template <typename S>
    bool serialize(S& s, uint32_t) {
        return s.ranged(op, Annotate::Op::Add, Annotate::Op::Clear) &&
               (op == Annotate::Op::Clear || mark.serialize(s));
    }
};

// Instructor `client` takes over `trainee`.
struct HoldEvent {
    uint16_t client = 0;
    uint16_t trainee = 0;

    template <typename S>
    bool serialize(S& s, uint32_t) {
        return s.integer(client) && s.integer(trainee);
    }
};

// `client` hands back whoever it held or was held by.
struct ReleaseEvent {
    uint16_t client = 0;

    template <typename S>
    bool serialize(S& s, uint32_t) {
        return s.integer(client);
    }
};

// A server resumed the log (`--resume`): everyone before it had gone, and the marks were
// renumbered 1..n, author 0, as a server starting with them does.
struct ResumeEvent {
    uint64_t unixUs = 0; // wall clock

    template <typename S>
    bool serialize(S& s, uint32_t) {
        return s.integer(unixUs);
    }
};

// [SECTION] an event, and a record of one

// The order is the log's: an event's kind on disk is its index + 1. The simulation's come first.
using Event =
    std::variant<JoinEvent, ViewEvent, ToolEvent, LeaveEvent, CutEvent, SyncEvent, VoxelsEvent,
                 HelloEvent, MarkEvent, HoldEvent, ReleaseEvent, ResumeEvent>;

namespace detail {
template <typename T, size_t... I>
constexpr size_t eventIndex(std::index_sequence<I...>) {
    return ((std::is_same_v<T, std::variant_alternative_t<I, Event>> ? I : 0) + ...);
}
template <size_t... I>
Event eventAt(size_t index, std::index_sequence<I...>) {
    Event e;
    ((I == index ? (void)e.emplace<I>() : (void)0), ...);
    return e;
}
} // namespace detail

// The kind an event of type T is written as.
template <typename T>
inline constexpr uint8_t kEventKind =
    uint8_t(detail::eventIndex<T>(std::make_index_sequence<std::variant_size_v<Event>>()) + 1);

// The kinds on disk (docs/recording.md): a new event goes at the end.
static_assert(kEventKind<JoinEvent> == 1 && kEventKind<VoxelsEvent> == 7 &&
              kEventKind<HelloEvent> == 8 && kEventKind<ResumeEvent> == 12);

// True for what the simulation applies; the policy's decisions it has nothing to do with.
inline bool isSimulation(const Event& e) {
    return e.index() < kEventKind<VoxelsEvent>;
}

// The participant an event is of; 0 for a cut, voxels, a mark or a resume (nobody's).
inline uint16_t clientOf(const Event& e) {
    return std::visit(
        [](const auto& v) -> uint16_t {
            if constexpr (requires { v.client; })
                return v.client;
            else
                return 0;
        },
        e);
}

// An event at a server time: what the server queues for the simulation and what the session log
// holds, one per frame. The time is the server's steady clock when the event arrived (0 in a
// queue: stamped when queued); a Resume restarts it.
struct LogRecord {
    uint64_t timeUs = 0;
    Event event{};

    template <typename T>
    bool is() const {
        return std::holds_alternative<T>(event);
    }
    template <typename T>
    const T* as() const {
        return std::get_if<T>(&event);
    }
    template <typename T>
    T* as() {
        return std::get_if<T>(&event);
    }
    uint8_t kind() const { return uint8_t(event.index() + 1); }

    // `version`: the log's format (a reader passes the file's).
    template <typename S>
    bool serialize(S& s, uint32_t version = kLogVersion) {
        constexpr uint8_t kKinds = uint8_t(std::variant_size_v<Event>);
        uint8_t k = kind();
        if (!(s.ranged(k, uint8_t(1), kKinds) && s.integer(timeUs)))
            return false;
        if constexpr (S::kReading)
            event = detail::eventAt(k - 1u, std::make_index_sequence<kKinds>());
        return std::visit([&](auto& e) { return e.serialize(s, version); }, event);
    }
};

} // namespace trephine::net

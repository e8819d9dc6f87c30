// Network statistics as data (Tracy's way): the network thread bumps atomic counters per channel,
// tick() folds them into a fixed-length history of per-second rates, and the report writer and
// any UI only read the model. Latencies are microseconds from our own steady clock (ENet's round
// trip is whole milliseconds).
#pragma once

#include "libsim/stats.h"
#include "net/enet_host.h"
#include "net/protocol.h"

#include <array>
#include <atomic>
#include <cstdint>
#include <deque>
#include <glm/vec3.hpp>
#include <span>
#include <string>

namespace trephine::net {

// Microseconds of std::chrono::steady_clock. On Linux this is CLOCK_MONOTONIC, shared by every
// process on the machine, so a server and a client on one host (tests, loopback benchmarks)
// read the same clock; across machines the client corrects with the offset estimated from pings.
uint64_t steadyNowUs();

struct ChannelRates {
    double bytesInPerS = 0, bytesOutPerS = 0, messagesInPerS = 0, messagesOutPerS = 0;
};

// Image bytes received per second: full images (Channel::Image) and drilling rectangles
// (Channel::ImageLossy) together.
inline double imageBytesInPerS(std::span<const ChannelRates> perChannel) {
    double sum = 0;
    for (Channel c : {Channel::Image, Channel::ImageLossy})
        if (size_t(c) < perChannel.size())
            sum += perChannel[size_t(c)].bytesInPerS;
    return sum;
}

// One applied image or volume update, with its stage breakdown (microseconds; -1 where unknown),
// so that a study can compute medians per stage: erode, render (DBI only) and encode at the
// server (sent in the update), transmit (server sent -> client received), client apply (decode +
// write: rectangle into the DBI, or voxels + rendering-data update), client render (volume mode:
// the local re-render of the whole view; 0 for DBI and when the client does not render), and
// end-to-end latency (cause at the server -> applied and rendered here).
struct UpdateRecord {
    Sync mode = Sync::Dbi;
    uint32_t sequence = 0;
    bool full = false;
    uint32_t bytes = 0;    // payload on the wire
    uint32_t rawBytes = 0; // before compression
    glm::ivec3 box{0};     // volume: box size in voxels; DBI: rectangle w, h, 1
    double erodeUs = -1, serverRenderUs = -1, encodeUs = -1, transmitUs = -1;
    double applyUs = -1, clientRenderUs = -1, latencyUs = -1;
    // The brick-grid update inside the stage that holds it: the server's render (DBI) or the
    // client's apply (volume); -1 when none was timed.
    double gridUs = -1;
    uint64_t appliedUs = 0; // steadyNowUs() when done
};

// Per-sync-mode figures of a client (NetStats::modes, indexed by Sync). Full updates count in
// updates/fullUpdates and bytes, never in latency (their cause is a join, switch or view change).
struct ModeStats {
    uint64_t updates = 0, fullUpdates = 0;
    SampleWindow bytes{65536}, rawBytes{65536};
    SampleWindow latencyUs{65536}, transmitUs{65536}, applyUs{65536}, clientRenderUs{65536};
    SampleWindow erodeUs{65536}, serverRenderUs{65536}, encodeUs{65536};
    void add(const UpdateRecord& r);
};

class NetStats {
public:
    static constexpr size_t kHistoryLength = 120; // ticks kept (seconds, with a 1 s tick)

    // Called by the thread that sends or receives; cheap and lock-free.
    void countIn(Channel c, size_t bytes);
    void countOut(Channel c, size_t bytes);
    void countMalformed() { m_malformed.fetch_add(1, std::memory_order_relaxed); }

    // Folds the counters since the last tick into rates and appends them to the history.
    void tick(uint64_t nowUs);

    uint64_t totalBytesIn(Channel c) const { return m_channels[size_t(c)].bytesIn.load(); }
    uint64_t totalBytesOut(Channel c) const { return m_channels[size_t(c)].bytesOut.load(); }
    uint64_t totalMessagesIn(Channel c) const { return m_channels[size_t(c)].msgsIn.load(); }
    uint64_t totalMessagesOut(Channel c) const { return m_channels[size_t(c)].msgsOut.load(); }
    uint64_t malformed() const { return m_malformed.load(); }
    // The history of rates per channel, oldest first.
    const std::deque<std::array<ChannelRates, size_t(Channel::Count)>>& history() const {
        return m_history;
    }
    // Rates over the whole time from the first count to the last tick.
    ChannelRates averageRates(Channel c) const;

    // Owned by one thread (the one that polls the client); not thread-safe.
    SampleWindow rttUs{4096};              // ping round trip, our own microseconds
    SampleWindow updateBytes{65536};       // payload bytes per image update
    SampleWindow updateRawBytes{65536};    // bytes before compression
    SampleWindow updateLatencyUs{65536};   // cause at server -> rectangle applied at client
    SampleWindow applyUs{65536};           // decode + apply time at the client
    SampleWindow hapticRoundTripUs{65536}; // tool state sent -> its HapticModel received
    // The same per sync mode, with stage times (the windows above take updates of both modes).
    std::array<ModeStats, 2> modes;
    int64_t clockOffsetUs = 0; // server clock - client clock, from the best (lowest-RTT) ping
    // ENet's coarse loss estimate for the peer (peer->packetLoss / ENET_PEER_PACKET_LOSS_SCALE):
    // a smoothed fraction of our reliable packets that needed a resend, recomputed by ENet about
    // every 10 s (-1 until connected), and peer->packetsLost, its count in ENet's current 10 s
    // interval (reset when the estimate is refreshed).
    double packetLoss = -1;
    uint64_t packetsLost = 0;
    double bestRttUs = -1;

private:
    struct Counters {
        std::atomic<uint64_t> bytesIn{0}, bytesOut{0}, msgsIn{0}, msgsOut{0};
    };
    std::array<Counters, size_t(Channel::Count)> m_channels;
    std::array<std::array<uint64_t, 4>, size_t(Channel::Count)> m_lastTick{};
    std::atomic<uint64_t> m_malformed{0};
    // Atomic: averageRates (a server's reportJson) may read them while the network thread ticks.
    std::atomic<uint64_t> m_firstTickUs{0}, m_lastTickUs{0};
    std::deque<std::array<ChannelRates, size_t(Channel::Count)>> m_history;
};

} // namespace trephine::net

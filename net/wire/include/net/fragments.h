// Messages on Channel::ImageLossy travel as fragments of our own, each one datagram, with
// Reed-Solomon parity fragments (ISA-L's erasure code) per stripe of data fragments. ENet's
// unreliable fragments lose a whole message with any one of them (a 92 kB image of ~68 datagrams
// arrives whole at 1 % loss half the time); with m parity fragments, any m of a stripe's datagrams
// may be lost. m follows the loss the receiver measures (ImageAck::lossPermille): the fewest
// that lose a stripe at most once in kStripeLossTarget, none on a link that loses nothing.
// A fragment: message u32 (the sender's count, per peer), index u16 (data fragments first, then
// each stripe's parity fragments in stripe order), data count u16 (>= 1), stripe u8 (data
// fragments a stripe holds, >= 1; the last may hold fewer), parity u8 (per stripe; 0: none),
// length u32 (the message's bytes), then its bytes. Data fragments split the message evenly: each
// ceil(length / data count) bytes but the last; parity fragments are that long, coding the
// stripe's data fragments padded with zeros. No ENet here: the host applies these.
#pragma once

#include <cstddef>
#include <cstdint>
#include <map>
#include <optional>
#include <span>
#include <vector>

namespace trephine::net {

inline constexpr size_t kFragmentHeaderBytes = 14;
// Data fragments a stripe holds at most, the parity a stripe has at most, and how rarely a
// stripe may be lost at the loss reported.
inline constexpr int kMaxStripe = 32, kMaxParity = 16;
inline constexpr double kStripeLossTarget = 1e-3;
// The least a data fragment of a message of several holds: a sender fills at least half of a
// datagram's room (ENet's smallest MTU, 576, leaves ~530).
inline constexpr size_t kMinFragmentBytes = 128;

// The parity fragments for a stripe of `data` fragments at a loss of `lossPermille` per
// thousand datagrams: 0 below 1 per thousand, else the fewest that lose all `data` of them with
// probability at most kStripeLossTarget (2 for 11 at 1 %, 3 for 23; 4 for 11 at 5 %).
int parityFor(int data, uint32_t lossPermille);

// `message` as fragments of at most `maxFragmentBytes` (header included), with the parity
// parityFor gives each stripe at `lossPermille` (0: none). Each fragment is one datagram. Empty
// when the message needs more than 65535 fragments.
std::vector<std::vector<uint8_t>> splitMessage(std::span<const uint8_t> message, uint32_t messageId,
                                               size_t maxFragmentBytes, uint32_t lossPermille);

// One peer's messages put back together from their fragments, newest wins: a message older than
// the newest one delivered is never delivered, and at most kMaxPartial incomplete ones are kept
// (a newer one's first fragment evicts the oldest; an older one's is dropped). Memory follows
// the datagrams received, never what a header claims. Counts the datagrams lost, for the receiver's
// loss figure: those missing below the highest index seen of each message completed or dropped,
// and one for each message of which none came.
class FragmentAssembler {
public:
    static constexpr size_t kMaxPartial = 4;
    explicit FragmentAssembler(size_t maxMessageBytes) : m_maxMessageBytes(maxMessageBytes) {}

    enum class Result { Incomplete, Complete, Stale, Refused };
    // Takes one datagram; on Complete, `out` holds the message. Refused: not a fragment (a bad
    // header, a size that does not match it, a message over maxMessageBytes).
    Result add(std::span<const uint8_t> datagram, std::vector<uint8_t>& out);

    uint64_t received() const { return m_received; }
    uint64_t lost() const { return m_lost; }
    // Lost datagrams per thousand, smoothed over the last few hundred.
    uint32_t lossPermille() const { return uint32_t(m_lossRate * 1000.0 + 0.5); }

private:
    // What every fragment of a message says alike.
    struct Shape {
        uint32_t length = 0;
        uint16_t dataCount = 0;
        uint8_t stripe = 0, parity = 0;
        bool operator==(const Shape&) const = default;
    };
    struct Partial {
        uint32_t id = 0;
        Shape shape;
        size_t fragmentBytes = 0;
        std::map<int, std::vector<uint8_t>> fragments; // by index, as they came (or rebuilt)
        int highest = -1, have = 0;
    };
    bool complete(Partial& p, std::vector<uint8_t>& out) const;
    void retire(const Partial& p);
    void count(int lost, int received);

    size_t m_maxMessageBytes;
    std::vector<Partial> m_partial;
    std::optional<uint32_t> m_delivered; // the newest message delivered
    std::optional<uint32_t> m_newest;    // the newest message a fragment of which came
    uint64_t m_received = 0, m_lost = 0;
    double m_lossRate = 0;
};

} // namespace trephine::net

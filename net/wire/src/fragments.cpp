#include "net/fragments.h"

#include <isa-l/erasure_code.h>

#include <algorithm>
#include <cmath>

namespace trephine::net {

namespace {

void put(std::vector<uint8_t>& out, uint64_t v, int bytes) {
    for (int i = 0; i < bytes; ++i)
        out.push_back(uint8_t(v >> (8 * i)));
}

uint64_t get(const uint8_t* p, int bytes) {
    uint64_t v = 0;
    for (int i = 0; i < bytes; ++i)
        v |= uint64_t(p[i]) << (8 * i);
    return v;
}

int stripeCount(int dataCount, int stripe) {
    return (dataCount + stripe - 1) / stripe;
}

// Bytes of data fragment i of a message of `length` split `fragmentBytes` a fragment.
size_t dataBytes(size_t length, size_t fragmentBytes, int i) {
    return std::min(fragmentBytes, length - size_t(i) * fragmentBytes);
}

// Newer by serial arithmetic: message counts wrap.
bool newer(uint32_t a, uint32_t b) {
    return int32_t(a - b) > 0;
}

// Codes `outputs` from `inputs` (each `bytes` long) with the rows of `matrix` (outputs x inputs).
void code(std::vector<uint8_t>& matrix, std::vector<uint8_t*>& inputs,
          std::vector<uint8_t*>& outputs, size_t bytes) {
    const int k = int(inputs.size()), rows = int(outputs.size());
    std::vector<uint8_t> tables(size_t(32 * k * rows));
    ec_init_tables(k, rows, matrix.data(), tables.data());
    ec_encode_data(int(bytes), k, rows, tables.data(), inputs.data(), outputs.data());
}

// The Cauchy generator of a stripe of k data and m parity fragments: (k + m) x k, identity first.
std::vector<uint8_t> generator(int k, int m) {
    std::vector<uint8_t> a(size_t((k + m) * k));
    gf_gen_cauchy1_matrix(a.data(), k + m, k);
    return a;
}

} // namespace

int parityFor(int data, uint32_t lossPermille) {
    if (lossPermille < 1 || data < 1)
        return 0;
    const double p = std::min(lossPermille, 1000u) / 1000.0;
    for (int m = 1; m < kMaxParity; ++m) {
        // P(more than m of the data + m datagrams lost).
        const int n = data + m;
        double term = std::pow(1 - p, n), kept = 0; // P(j lost), j from 0
        for (int j = 0; j <= m; ++j) {
            kept += term;
            term *= double(n - j) / double(j + 1) * p / (1 - p);
        }
        if (1 - kept <= kStripeLossTarget)
            return m;
    }
    return kMaxParity;
}

std::vector<std::vector<uint8_t>> splitMessage(std::span<const uint8_t> message, uint32_t messageId,
                                               size_t maxFragmentBytes, uint32_t lossPermille) {
    const size_t room =
        std::max<size_t>(maxFragmentBytes, kFragmentHeaderBytes + 1) - kFragmentHeaderBytes;
    const size_t length = message.size();
    const int dataCount = int(std::max<size_t>(1, (length + room - 1) / room));
    const int stripe =
        (dataCount + stripeCount(dataCount, kMaxStripe) - 1) / stripeCount(dataCount, kMaxStripe);
    const int parity = length == 0 ? 0 : parityFor(stripe, lossPermille);
    if (dataCount + stripeCount(dataCount, stripe) * parity > 65535)
        return {}; // past what a fragment's index can name
    const size_t fragmentBytes = length == 0 ? 0 : (length + dataCount - 1) / dataCount;
    const auto header = [&](int index) {
        std::vector<uint8_t> f;
        f.reserve(kFragmentHeaderBytes + fragmentBytes);
        put(f, messageId, 4);
        put(f, uint64_t(index), 2);
        put(f, uint64_t(dataCount), 2);
        put(f, uint64_t(stripe), 1);
        put(f, uint64_t(parity), 1);
        put(f, length, 4);
        return f;
    };
    std::vector<std::vector<uint8_t>> out;
    for (int first = 0; first < dataCount; first += stripe) {
        const int k = std::min(stripe, dataCount - first);
        std::vector<std::vector<uint8_t>> padded(size_t(parity > 0 ? k : 0));
        std::vector<uint8_t*> inputs;
        for (int i = first; i < first + k; ++i) {
            const size_t n = length == 0 ? 0 : dataBytes(length, fragmentBytes, i);
            const uint8_t* src = message.data() + size_t(i) * fragmentBytes;
            std::vector<uint8_t> f = header(i);
            f.insert(f.end(), src, src + n);
            out.push_back(std::move(f));
            if (parity > 0) {
                padded[size_t(i - first)].assign(src, src + n);
                padded[size_t(i - first)].resize(fragmentBytes, 0);
                inputs.push_back(padded[size_t(i - first)].data());
            }
        }
        if (parity == 0)
            continue;
        std::vector<std::vector<uint8_t>> coded(size_t(parity),
                                                std::vector<uint8_t>(fragmentBytes, 0));
        std::vector<uint8_t*> outputs;
        for (auto& c : coded)
            outputs.push_back(c.data());
        std::vector<uint8_t> a = generator(k, parity);
        std::vector<uint8_t> rows(a.begin() + k * k, a.end());
        code(rows, inputs, outputs, fragmentBytes);
        for (int j = 0; j < parity; ++j) {
            std::vector<uint8_t> f = header(dataCount + first / stripe * parity + j);
            f.insert(f.end(), coded[size_t(j)].begin(), coded[size_t(j)].end());
            out.push_back(std::move(f));
        }
    }
    return out;
}

FragmentAssembler::Result FragmentAssembler::add(std::span<const uint8_t> datagram,
                                                 std::vector<uint8_t>& out) {
    if (datagram.size() < kFragmentHeaderBytes)
        return Result::Refused;
    const uint8_t* d = datagram.data();
    const uint32_t message = uint32_t(get(d, 4));
    const uint16_t index = uint16_t(get(d + 4, 2));
    const Shape h{uint32_t(get(d + 10, 4)), uint16_t(get(d + 6, 2)), d[8], d[9]};
    if (h.dataCount == 0 || h.stripe == 0 || h.stripe > kMaxStripe || h.parity > kMaxParity ||
        h.length > m_maxMessageBytes)
        return Result::Refused;
    const int total = h.dataCount + stripeCount(h.dataCount, h.stripe) * h.parity;
    const size_t fragmentBytes = (size_t(h.length) + h.dataCount - 1) / h.dataCount;
    // Only the sender's split: every data fragment at least a byte (one empty message aside), at
    // least kMinFragmentBytes when there are several (a hostile header naming thousands of
    // one-byte fragments costs nothing to send), and stripes as even as splitMessage makes them.
    const bool splitsEvenly =
        h.dataCount == 1 ||
        (size_t(h.dataCount - 1) * fragmentBytes < h.length && fragmentBytes >= kMinFragmentBytes);
    const int stripes = stripeCount(h.dataCount, kMaxStripe);
    if (!splitsEvenly || h.stripe != (h.dataCount + stripes - 1) / stripes || index >= total)
        return Result::Refused;
    const size_t expected =
        index < h.dataCount ? dataBytes(h.length, fragmentBytes, index) : fragmentBytes;
    if (datagram.size() - kFragmentHeaderBytes != expected)
        return Result::Refused;
    if (m_delivered && !newer(message, *m_delivered))
        return Result::Stale;
    // Messages skipped in the sender's count were lost whole: a datagram each, at least (a
    // one-datagram acknowledgement or small rectangle shows its loss no other way).
    if (m_newest && newer(message, *m_newest))
        count(int(std::min<uint32_t>(message - *m_newest - 1, 64)), 0);
    if (!m_newest || newer(message, *m_newest))
        m_newest = message;

    auto it = std::find_if(m_partial.begin(), m_partial.end(),
                           [&](const Partial& p) { return p.id == message; });
    if (it == m_partial.end()) {
        const bool older = std::all_of(m_partial.begin(), m_partial.end(),
                                       [&](const Partial& p) { return newer(p.id, message); });
        if (m_partial.size() >= kMaxPartial && older)
            return Result::Stale; // a late one does not evict newer ones
        if (m_partial.size() >= kMaxPartial) {
            auto oldest = std::min_element(
                m_partial.begin(), m_partial.end(),
                [](const Partial& a, const Partial& b) { return newer(b.id, a.id); });
            retire(*oldest);
            m_partial.erase(oldest);
        }
        m_partial.push_back(Partial{message, h, fragmentBytes, {}, -1, 0});
        it = m_partial.end() - 1;
    } else if (!(it->shape == h)) {
        return Result::Refused;
    }
    Partial& p = *it;
    if (p.fragments.count(index))
        return Result::Incomplete; // a duplicate
    p.fragments[index].assign(d + kFragmentHeaderBytes, d + datagram.size());
    p.highest = std::max(p.highest, int(index));
    ++p.have;
    if (!complete(p, out))
        return Result::Incomplete;
    // Delivered: it and every older one are done.
    const uint32_t id = p.id;
    m_delivered = id;
    for (auto q = m_partial.begin(); q != m_partial.end();) {
        if (!newer(q->id, id)) {
            retire(*q);
            q = m_partial.erase(q);
        } else {
            ++q;
        }
    }
    return Result::Complete;
}

// The message once every stripe has its data, or as many of its data and parity fragments as it
// has data: the missing data are rebuilt from the generator's rows of those that came.
bool FragmentAssembler::complete(Partial& p, std::vector<uint8_t>& out) const {
    const Shape& s = p.shape;
    struct Rebuild {
        int first = 0, k = 0;
        std::vector<int> missing;
    };
    std::vector<Rebuild> rebuilds;
    for (int first = 0; first < s.dataCount; first += s.stripe) {
        Rebuild r{first, std::min<int>(s.stripe, s.dataCount - first), {}};
        int came = 0;
        for (int i = first; i < first + r.k; ++i)
            p.fragments.count(i) ? ++came : (r.missing.push_back(i), 0);
        if (r.missing.empty())
            continue;
        for (int j = 0; j < s.parity; ++j)
            came += int(p.fragments.count(s.dataCount + first / s.stripe * s.parity + j));
        if (came < r.k)
            return false;
        rebuilds.push_back(std::move(r));
    }
    for (const Rebuild& r : rebuilds) {
        const std::vector<uint8_t> a = generator(r.k, s.parity);
        // The first k fragments that came, data padded to full length, and their rows.
        std::vector<std::vector<uint8_t>> padded;
        std::vector<uint8_t*> inputs;
        std::vector<uint8_t> rows;
        for (int row = 0; row < r.k + s.parity && int(padded.size()) < r.k; ++row) {
            const int index =
                row < r.k ? r.first + row : s.dataCount + r.first / s.stripe * s.parity + row - r.k;
            auto got = p.fragments.find(index);
            if (got == p.fragments.end())
                continue;
            padded.push_back(got->second);
            padded.back().resize(p.fragmentBytes, 0);
            rows.insert(rows.end(), a.begin() + row * r.k, a.begin() + (row + 1) * r.k);
        }
        for (auto& f : padded)
            inputs.push_back(f.data());
        std::vector<uint8_t> inverse(rows.size());
        if (gf_invert_matrix(rows.data(), inverse.data(), r.k) != 0)
            return false; // never for a Cauchy generator's rows
        std::vector<uint8_t> decode;
        std::vector<std::vector<uint8_t>> rebuilt(r.missing.size(),
                                                  std::vector<uint8_t>(p.fragmentBytes));
        std::vector<uint8_t*> outputs;
        for (size_t m = 0; m < r.missing.size(); ++m) {
            const int i = r.missing[m] - r.first;
            decode.insert(decode.end(), inverse.begin() + i * r.k, inverse.begin() + (i + 1) * r.k);
            outputs.push_back(rebuilt[m].data());
        }
        code(decode, inputs, outputs, p.fragmentBytes);
        for (size_t m = 0; m < r.missing.size(); ++m) {
            rebuilt[m].resize(dataBytes(s.length, p.fragmentBytes, r.missing[m]));
            p.fragments[size_t(r.missing[m])] = std::move(rebuilt[m]);
        }
    }
    out.clear();
    out.reserve(s.length);
    for (int i = 0; i < s.dataCount; ++i)
        out.insert(out.end(), p.fragments[i].begin(), p.fragments[i].end());
    return true;
}

// A message done with (delivered, or dropped): the datagrams below the highest seen that never
// came were lost (fragments arrive in order; the tail of a dropped one is not counted).
void FragmentAssembler::retire(const Partial& p) {
    count(p.highest + 1 - p.have, p.have);
}

void FragmentAssembler::count(int lost, int received) {
    m_lost += uint64_t(std::max(lost, 0));
    m_received += uint64_t(std::max(received, 0));
    // Smoothed over ~256 datagrams: steady at the link's loss, one loss on a clean link
    // raises it to 4 per thousand, decaying back under 1 within ~350 datagrams.
    constexpr double a = 1.0 / 256;
    m_lossRate *= std::pow(1 - a, std::max(received, 0));
    const double kept = std::pow(1 - a, std::max(lost, 0));
    m_lossRate = m_lossRate * kept + (1 - kept); // each lost one moves it `a` towards 1
}

} // namespace trephine::net

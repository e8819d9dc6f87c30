#include "net/image_delta.h"

#include <algorithm>
#include <bit>
#include <cstring>

namespace trephine::net {

namespace {

// Median edge detector over the left (a), lower (b) and lower-left (c) neighbours; outside the
// rectangle a neighbour counts as 0. The median of a, b and a + b - c, written as a clamp so that
// it compiles without branches (and vectorises in residualRow): c >= max(a, b) gives min(a, b),
// c <= min(a, b) gives max(a, b), else a + b - c.
template <typename I>
inline I medPredict(I a, I b, I c) {
    return std::clamp(I(a + b - c), std::min(a, b), std::max(a, b));
}

// The prediction of pixel x of a row from its own row (`cur`) and the row below (`below`, null
// for the bottom row); `stride` elements a pixel (4 for RGBA colour, 1 for depth codes).
template <typename T>
inline int predictAt(const T* cur, const T* below, int x, int stride) {
    const int a = x > 0 ? int(cur[(x - 1) * stride]) : 0;
    const int b = below ? int(below[x * stride]) : 0;
    const int c = below && x > 0 ? int(below[(x - 1) * stride]) : 0;
    return medPredict(a, b, c);
}

// out[i] = cur[i] - prediction for the n elements of a row, S elements a pixel (the whole row at
// once: the encoder knows every pixel of the new picture). `below` is the row below, or zeros for
// the bottom row. I is wide enough for a + b - c (int16_t for bytes, int32_t for codes).
template <typename T, typename I, int S>
void residualRow(const T* __restrict cur, const T* __restrict below, T* __restrict out, size_t n) {
    for (size_t i = 0; i < std::min(n, size_t(S)); ++i)
        out[i] = T(cur[i] - below[i]); // a = c = 0: the prediction is b
    for (size_t i = S; i < n; ++i)
        out[i] = T(cur[i] - medPredict(I(cur[i - S]), I(below[i]), I(below[i - S])));
}

size_t maskBytes(size_t pixels) {
    return (pixels + 7) / 8;
}

// Set bits in n bytes, eight bytes a count (baseline x86-64 has no popcnt instruction: each
// std::popcount is a call).
size_t countBits(const uint8_t* bytes, size_t n) {
    size_t count = 0, k = 0;
    for (; k + 8 <= n; k += 8) {
        uint64_t word;
        std::memcpy(&word, bytes + k, 8);
        count += size_t(std::popcount(word));
    }
    for (; k < n; ++k)
        count += size_t(std::popcount(bytes[k]));
    return count;
}

// The pixels' hash: four FNV-1a lanes of 64 bits, column x in lane x % 4, carried from row to row
// in raster order; a pixel is one word, R | G << 8 | B << 16 | depth code << 24. Four lanes keep
// four multiplications in flight where one chain would wait on each.
// The lanes, after the width and height, go through one more FNV-1a pass, folded to 32 bits.
class PixelHash {
public:
    static constexpr uint64_t kBasis = 14695981039346656037ull, kPrime = 1099511628211ull;

    void row(const uint8_t* rgba, const uint16_t* codes, int w) {
        int x = 0;
        for (; x + 4 <= w; x += 4)
            for (int l = 0; l < 4; ++l)
                m_lane[l] = (m_lane[l] ^ word(rgba + 4 * (x + l), codes[x + l])) * kPrime;
        for (; x < w; ++x)
            m_lane[x & 3] = (m_lane[x & 3] ^ word(rgba + 4 * x, codes[x])) * kPrime;
    }
    uint32_t finish(int w, int h) const {
        uint64_t f = kBasis;
        for (uint64_t v : {uint64_t(w), uint64_t(h), m_lane[0], m_lane[1], m_lane[2], m_lane[3]})
            f = (f ^ v) * kPrime;
        return uint32_t(f ^ (f >> 32));
    }

private:
    static uint64_t word(const uint8_t* rgba, uint16_t q) {
        return uint64_t(rgba[0]) | uint64_t(rgba[1]) << 8 | uint64_t(rgba[2]) << 16 |
               uint64_t(q) << 24;
    }
    uint64_t m_lane[4] = {kBasis, kBasis ^ 1, kBasis ^ 2, kBasis ^ 3};
};

// Depth codes of every pixel of `image`, and the hash of its colour and codes.
uint32_t codesAndHash(const Dbi& image, const DepthQuantizer& quantizer,
                      std::vector<uint16_t>& codes) {
    const int w = image.width(), h = image.height();
    codes.resize(size_t(w) * size_t(h));
    quantizer.quantizeRow(image.depth(), codes.data(), codes.size());
    PixelHash hash;
    for (int y = 0; y < h; ++y) {
        const size_t row = size_t(y) * size_t(w);
        hash.row(image.color() + 4 * row, codes.data() + row, w);
    }
    return hash.finish(w, h);
}

} // namespace

uint32_t basePixelHash(const Dbi& image, const DepthQuantizer& quantizer) {
    std::vector<uint16_t> codes;
    return codesAndHash(image, quantizer, codes);
}

PredictedImage encodePredicted(const Dbi& next, const Dbi& base, Codec codec,
                               const DepthQuantizer& quantizer) {
    PredictedImage out;
    if (next.width() != base.width() || next.height() != base.height() || codec == Codec::Raw)
        return out;
    const int w = next.width(), h = next.height();
    const size_t n = size_t(w) * size_t(h);
    std::vector<uint8_t> mask(maskBytes(n), 0);
    // Bit j: the j-th changed pixel is predicted exactly (its five residuals are 0), as the
    // background seen through a hole mostly is: it stores no residuals.
    std::vector<uint8_t> exact(maskBytes(n), 0);
    // One raster pass: the hash of the base, the masks, and the residuals of changed pixels into
    // per-plane scratch.
    std::vector<uint8_t> scratch(5 * n);
    uint8_t *sr = scratch.data(), *sg = sr + n, *sb = sg + n, *sHi = sb + n, *sLo = sHi + n;
    // Codes of the new picture (two rows kept) and of the base, a row at a time; residuals of
    // a row (colour RGBA, codes), and zeros standing for the row below the bottom one.
    std::vector<uint16_t> rows(2 * size_t(w)), was(w), resD(w), zeroCodes(w, 0);
    std::vector<uint8_t> resC(4 * size_t(w)), zeroColor(4 * size_t(w), 0);
    PixelHash hash;
    size_t m = 0, stored = 0;
    for (int y = 0; y < h; ++y) {
        uint16_t* qCur = rows.data() + size_t(y & 1) * size_t(w);
        const uint16_t* qBelow =
            y > 0 ? rows.data() + size_t((y - 1) & 1) * size_t(w) : zeroCodes.data();
        const size_t row = size_t(y) * size_t(w);
        const uint8_t* cNow = next.color() + 4 * row;
        const uint8_t* cBelow = y > 0 ? cNow - 4 * size_t(w) : zeroColor.data();
        const uint8_t* cWas = base.color() + 4 * row;
        const float* dNow = next.depth() + row;
        const float* dWas = base.depth() + row;
        quantizer.quantizeRow(dNow, qCur, size_t(w));
        // The base's codes: quantising again only where its depth differs.
        for (int x = 0; x < w; ++x)
            was[x] = dWas[x] == dNow[x] ? qCur[x] : quantizer.quantize(dWas[x]);
        hash.row(cWas, was.data(), w);
        residualRow<uint8_t, int16_t, 4>(cNow, cBelow, resC.data(), 4 * size_t(w));
        residualRow<uint16_t, int32_t, 1>(qCur, qBelow, resD.data(), size_t(w));
        for (int x = 0; x < w; ++x) {
            const uint8_t* now = cNow + 4 * x;
            const uint8_t* old = cWas + 4 * x;
            if (was[x] == qCur[x] && now[0] == old[0] && now[1] == old[1] && now[2] == old[2])
                continue;
            const size_t i = row + size_t(x);
            mask[i / 8] |= uint8_t(1u << (i % 8));
            const uint8_t er = resC[4 * size_t(x)], eg = resC[4 * size_t(x) + 1],
                          eb = resC[4 * size_t(x) + 2];
            const uint16_t ed = resD[size_t(x)];
            if ((er | eg | eb | ed) == 0) {
                exact[m / 8] |= uint8_t(1u << (m % 8));
            } else {
                sr[stored] = er;
                sg[stored] = uint8_t(eg - er);
                sb[stored] = uint8_t(eb - er);
                sHi[stored] = uint8_t(ed >> 8);
                sLo[stored] = uint8_t(ed & 0xff);
                ++stored;
            }
            ++m;
        }
    }
    std::vector<uint8_t> raw(mask.size() + maskBytes(m) + 5 * stored);
    std::memcpy(raw.data(), mask.data(), mask.size());
    std::memcpy(raw.data() + mask.size(), exact.data(), maskBytes(m));
    uint8_t* dst = raw.data() + mask.size() + maskBytes(m);
    for (const uint8_t* plane : {sr, sg, sb, sHi, sLo}) {
        std::memcpy(dst, plane, stored);
        dst += stored;
    }
    out.rawBytes = uint32_t(raw.size());
    out.changedPixels = int(m);
    out.payload = compressBytes(raw, codec);
    out.baseHash = hash.finish(w, h);
    return out;
}

PredictedStatus decodePredicted(std::span<const uint8_t> payload, uint32_t rawBytes, Codec codec,
                                uint32_t baseHash, const DepthQuantizer& quantizer, Dbi& image) {
    constexpr PredictedStatus kMalformed = PredictedStatus::Malformed;
    const int w = image.width(), h = image.height();
    const size_t n = size_t(w) * size_t(h);
    if (codec == Codec::Raw || n == 0 || rawBytes < maskBytes(n))
        return kMalformed;
    std::vector<uint8_t> raw;
    if (!decompressBytes(payload, codec, rawBytes, raw))
        return kMalformed;
    const uint8_t* mask = raw.data();
    const size_t m = countBits(mask, maskBytes(n));
    // Bits past the last pixel must be clear, in both masks, and the residuals must be exactly
    // 5 per changed pixel not predicted exactly.
    if (n % 8 && (mask[maskBytes(n) - 1] >> (n % 8)) != 0)
        return kMalformed;
    if (raw.size() < maskBytes(n) + maskBytes(m))
        return kMalformed;
    const uint8_t* exact = raw.data() + maskBytes(n);
    if (m % 8 && (exact[maskBytes(m) - 1] >> (m % 8)) != 0)
        return kMalformed;
    const size_t stored = m - countBits(exact, maskBytes(m));
    if (raw.size() != maskBytes(n) + maskBytes(m) + 5 * stored)
        return kMalformed;
    const uint8_t* r = exact + maskBytes(m);
    const uint8_t *g = r + stored, *b = g + stored, *dHi = b + stored, *dLo = dHi + stored;

    std::vector<uint16_t> q;
    if (codesAndHash(image, quantizer, q) != baseHash)
        return PredictedStatus::BaseMismatch;
    // Nothing can fail from here: decode in place, in raster order, so every prediction reads
    // the new picture (decoded pixels below and to the left, our own pixels elsewhere).
    size_t j = 0, k = 0; // changed pixels so far; stored residuals so far
    std::vector<float> depths(static_cast<size_t>(w));
    for (int y = 0; y < h; ++y) {
        const size_t row = size_t(y) * size_t(w);
        uint8_t* cCur = image.color() + 4 * row;
        const uint8_t* cBelow = y > 0 ? cCur - 4 * size_t(w) : nullptr;
        uint16_t* qCur = q.data() + row;
        const uint16_t* qBelow = y > 0 ? qCur - w : nullptr;
        for (int x = 0; x < w; ++x) {
            const size_t i = row + size_t(x);
            if (!(mask[i / 8] & (1u << (i % 8))))
                continue;
            const bool predicted = exact[j / 8] & (1u << (j % 8));
            ++j;
            const uint8_t er = predicted ? 0 : r[k];
            const uint8_t eg = predicted ? 0 : uint8_t(g[k] + er);
            const uint8_t eb = predicted ? 0 : uint8_t(b[k] + er);
            const uint16_t ed = predicted ? 0 : uint16_t((dHi[k] << 8) | dLo[k]);
            k += predicted ? 0 : 1;
            uint8_t* c = cCur + 4 * x;
            c[0] = uint8_t(predictAt<uint8_t>(cCur, cBelow, x, 4) + er);
            c[1] = uint8_t(predictAt<uint8_t>(cCur + 1, cBelow ? cBelow + 1 : nullptr, x, 4) + eg);
            c[2] = uint8_t(predictAt<uint8_t>(cCur + 2, cBelow ? cBelow + 2 : nullptr, x, 4) + eb);
            qCur[x] = uint16_t(predictAt<uint16_t>(qCur, qBelow, x, 1) + ed);
            c[3] = qCur[x] == DepthQuantizer::kBackground ? 0 : 255;
        }
        // The row's depths from its codes, four at a time, kept where the mask says.
        quantizer.dequantizeRow(qCur, depths.data(), size_t(w));
        float* depth = image.depth() + row;
        for (int x = 0; x < w; ++x) {
            const size_t i = row + size_t(x);
            if (mask[i / 8] & (1u << (i % 8)))
                depth[x] = depths[size_t(x)];
        }
    }
    return PredictedStatus::Ok;
}

} // namespace trephine::net

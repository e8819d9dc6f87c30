#include "net/image_delta.h"

#include <algorithm>
#include <bit>
#include <cstring>

namespace trephine::net {

namespace {

// Median edge detector over the left (a), lower (b) and lower-left (c) neighbours; outside the
// rectangle a neighbour counts as 0.
inline int medPredict(int a, int b, int c) {
    if (c >= std::max(a, b))
        return std::min(a, b);
    if (c <= std::min(a, b))
        return std::max(a, b);
    return a + b - c;
}

// The five planes of a rectangle the predictor works on: R, G, B and 16-bit depth.
struct Planes {
    int w = 0, h = 0;
    std::vector<uint8_t> c[3];
    std::vector<uint16_t> q;

    // `same`: the planes of `other`, an image of the same size whose depth codes are reused
    // wherever the two images' depths are bit-identical (quantising is most of the cost).
    Planes(const Dbi& image, const DepthQuantizer& quantizer, const Dbi* other = nullptr,
           const Planes* same = nullptr)
        : w(image.width()), h(image.height()) {
        const size_t n = size_t(w) * size_t(h);
        for (auto& p : c)
            p.resize(n);
        q.resize(n);
        for (size_t i = 0; i < n; ++i) {
            for (int k = 0; k < 3; ++k)
                c[k][i] = image.color()[4 * i + size_t(k)];
            const float d = image.depth()[i];
            q[i] = same && other->depth()[i] == d ? same->q[i] : quantizer.quantize(d);
        }
    }
    template <typename T>
    static int predict(const std::vector<T>& p, int w, int x, int y) {
        const size_t i = size_t(y) * size_t(w) + size_t(x);
        const int a = x > 0 ? int(p[i - 1]) : 0;
        const int b = y > 0 ? int(p[i - size_t(w)]) : 0;
        const int c = x > 0 && y > 0 ? int(p[i - size_t(w) - 1]) : 0;
        return medPredict(a, b, c);
    }
};

size_t maskBytes(size_t pixels) {
    return (pixels + 7) / 8;
}

uint32_t hashPlanes(const Planes& p) {
    // FNV-1a over two 32-bit words a pixel: packed R, G, B, then the depth code.
    uint32_t h = 2166136261u;
    auto mix = [&](uint32_t v) {
        h ^= v;
        h *= 16777619u;
    };
    mix(uint32_t(p.w));
    mix(uint32_t(p.h));
    for (size_t i = 0; i < p.q.size(); ++i) {
        mix(uint32_t(p.c[0][i]) | uint32_t(p.c[1][i]) << 8 | uint32_t(p.c[2][i]) << 16);
        mix(p.q[i]);
    }
    return h;
}

} // namespace

uint32_t basePixelHash(const Dbi& image, const DepthQuantizer& quantizer) {
    return hashPlanes(Planes(image, quantizer));
}

PredictedImage encodePredicted(const Dbi& next, const Dbi& base, Codec codec,
                               const DepthQuantizer& quantizer) {
    PredictedImage out;
    if (next.width() != base.width() || next.height() != base.height() || codec == Codec::Raw)
        return out;
    const Planes now(next, quantizer), was(base, quantizer, &next, &now);
    const int w = now.w, h = now.h;
    const size_t n = size_t(w) * size_t(h);
    std::vector<uint8_t> mask(maskBytes(n), 0);
    // One raster pass: the mask, and the residuals of changed pixels into per-plane scratch.
    std::vector<uint8_t> scratch(5 * n);
    uint8_t *sr = scratch.data(), *sg = sr + n, *sb = sg + n, *sHi = sb + n, *sLo = sHi + n;
    size_t m = 0;
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
            const size_t i = size_t(y) * size_t(w) + size_t(x);
            if (now.q[i] == was.q[i] && now.c[0][i] == was.c[0][i] && now.c[1][i] == was.c[1][i] &&
                now.c[2][i] == was.c[2][i])
                continue;
            mask[i / 8] |= uint8_t(1u << (i % 8));
            const uint8_t er = uint8_t(now.c[0][i] - Planes::predict(now.c[0], w, x, y));
            const uint8_t eg = uint8_t(now.c[1][i] - Planes::predict(now.c[1], w, x, y));
            const uint8_t eb = uint8_t(now.c[2][i] - Planes::predict(now.c[2], w, x, y));
            const uint16_t ed = uint16_t(now.q[i] - Planes::predict(now.q, w, x, y));
            sr[m] = er;
            sg[m] = uint8_t(eg - er);
            sb[m] = uint8_t(eb - er);
            sHi[m] = uint8_t(ed >> 8);
            sLo[m] = uint8_t(ed & 0xff);
            ++m;
        }
    std::vector<uint8_t> raw(mask.size() + 5 * m);
    std::memcpy(raw.data(), mask.data(), mask.size());
    uint8_t* dst = raw.data() + mask.size();
    for (const uint8_t* plane : {sr, sg, sb, sHi, sLo}) {
        std::memcpy(dst, plane, m);
        dst += m;
    }
    out.rawBytes = uint32_t(raw.size());
    out.changedPixels = int(m);
    out.payload = compressBytes(raw, codec);
    out.baseHash = hashPlanes(was);
    return out;
}

PredictedStatus decodePredicted(std::span<const uint8_t> payload, uint32_t rawBytes, Codec codec,
                                uint32_t baseHash, const DepthQuantizer& quantizer, Dbi& image) {
    constexpr PredictedStatus kMalformed = PredictedStatus::Malformed;
    const int w = image.width(), h = image.height();
    const size_t n = size_t(w) * size_t(h);
    if (codec == Codec::Raw || n == 0 || rawBytes < maskBytes(n) ||
        (rawBytes - maskBytes(n)) % 5 != 0)
        return kMalformed;
    std::vector<uint8_t> raw;
    if (!decompressBytes(payload, codec, rawBytes, raw))
        return kMalformed;
    const uint8_t* mask = raw.data();
    size_t m = 0;
    for (size_t k = 0; k < maskBytes(n); ++k)
        m += size_t(std::popcount(mask[k]));
    // Bits past the last pixel must be clear, and the residuals must be exactly 5 per pixel.
    if (n % 8 && (mask[maskBytes(n) - 1] >> (n % 8)) != 0)
        return kMalformed;
    if (raw.size() != maskBytes(n) + 5 * m)
        return kMalformed;
    const uint8_t* r = raw.data() + maskBytes(n);
    const uint8_t *g = r + m, *b = g + m, *dHi = b + m, *dLo = dHi + m;

    Planes p(image, quantizer);
    if (hashPlanes(p) != baseHash)
        return PredictedStatus::BaseMismatch;
    size_t k = 0;
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
            const size_t i = size_t(y) * size_t(w) + size_t(x);
            if (!(mask[i / 8] & (1u << (i % 8))))
                continue;
            const uint8_t er = r[k];
            p.c[0][i] = uint8_t(Planes::predict(p.c[0], w, x, y) + er);
            p.c[1][i] = uint8_t(Planes::predict(p.c[1], w, x, y) + uint8_t(g[k] + er));
            p.c[2][i] = uint8_t(Planes::predict(p.c[2], w, x, y) + uint8_t(b[k] + er));
            p.q[i] = uint16_t(Planes::predict(p.q, w, x, y) + ((dHi[k] << 8) | dLo[k]));
            ++k;
        }
    // Everything decoded: write the changed pixels back.
    for (size_t i = 0; i < n; ++i) {
        if (!(mask[i / 8] & (1u << (i % 8))))
            continue;
        uint8_t* c = image.color() + 4 * i;
        c[0] = p.c[0][i];
        c[1] = p.c[1][i];
        c[2] = p.c[2][i];
        image.depth()[i] = quantizer.dequantize(p.q[i]);
        c[3] = image.depth()[i] >= kBackgroundDepth ? 0 : 255;
    }
    return PredictedStatus::Ok;
}

} // namespace trephine::net

#include "net/codec.h"

#include "libsim/error.h"

#include <lz4.h>
#include <zstd.h>

#include <algorithm>
#include <cmath>
#include <cstring>

namespace trephine::net {

const char* codecName(Codec c) {
    switch (c) {
    case Codec::Raw:
        return "raw";
    case Codec::Lz4:
        return "lz4";
    case Codec::Zstd:
        return "zstd";
    }
    return "?";
}

Codec parseCodec(const std::string& text) {
    if (text == "raw")
        return Codec::Raw;
    if (text == "lz4")
        return Codec::Lz4;
    if (text == "zstd")
        return Codec::Zstd;
    throw Error("unknown codec '" + text + "' (use raw, lz4 or zstd)");
}

DepthQuantizer::DepthQuantizer(const Camera& camera)
    : m_camera(camera), m_near(camera.nearMm), m_far(camera.farMm) {}

uint16_t DepthQuantizer::quantize(float windowDepth) const {
    if (windowDepth >= kBackgroundDepth)
        return kBackground;
    double dist = -eyeZFromWindowDepth(m_camera, windowDepth);
    double t = (dist - m_near) / (m_far - m_near);
    return uint16_t(std::clamp(std::lround(t * 65534.0), 0l, 65534l));
}

float DepthQuantizer::dequantize(uint16_t q) const {
    if (q == kBackground)
        return kBackgroundDepth;
    double dist = m_near + double(q) / 65534.0 * (m_far - m_near);
    // Window depth of eye z = -dist under glm::perspective (GL clip conventions).
    double n = m_near, f = m_far, z = -dist;
    double ndc = (-(f + n) / (f - n) * z - 2.0 * f * n / (f - n)) / -z;
    return float(std::min(ndc * 0.5 + 0.5, std::nextafter(1.0, 0.0)));
}

namespace {

size_t planarBytes(size_t pixels) {
    return pixels * 5;
}

std::vector<uint8_t> toPlanar(const Dbi& image, const Camera& camera) {
    const int w = image.width(), h = image.height();
    const size_t n = size_t(w) * size_t(h);
    std::vector<uint8_t> out(planarBytes(n));
    uint8_t* r = out.data();
    uint8_t* g = r + n;
    uint8_t* b = g + n;
    uint8_t* dHi = b + n;
    uint8_t* dLo = dHi + n;
    DepthQuantizer q(camera);
    for (int y = 0; y < h; ++y) {
        uint16_t prev = 0;
        for (int x = 0; x < w; ++x) {
            size_t i = image.index(x, y);
            const uint8_t* c = image.color(x, y);
            r[i] = c[0];
            g[i] = c[1];
            b[i] = c[2];
            uint16_t d = q.quantize(image.depth(x, y));
            uint16_t delta = uint16_t(d - prev); // wraps; undone exactly on decode
            prev = d;
            dHi[i] = uint8_t(delta >> 8);
            dLo[i] = uint8_t(delta);
        }
    }
    return out;
}

void fromPlanar(std::span<const uint8_t> in, int w, int h, const Camera& camera, Dbi& out) {
    const size_t n = size_t(w) * size_t(h);
    const uint8_t* r = in.data();
    const uint8_t* g = r + n;
    const uint8_t* b = g + n;
    const uint8_t* dHi = b + n;
    const uint8_t* dLo = dHi + n;
    DepthQuantizer q(camera);
    out = Dbi(w, h);
    for (int y = 0; y < h; ++y) {
        uint16_t prev = 0;
        for (int x = 0; x < w; ++x) {
            size_t i = out.index(x, y);
            uint16_t d = uint16_t(prev + uint16_t((dHi[i] << 8) | dLo[i]));
            prev = d;
            float depth = q.dequantize(d);
            uint8_t* c = out.color(x, y);
            c[0] = r[i];
            c[1] = g[i];
            c[2] = b[i];
            c[3] = d == DepthQuantizer::kBackground ? kBackgroundRgba[3] : 255;
            out.depth()[i] = depth;
        }
    }
}

} // namespace

EncodedImage encodeImage(const Dbi& image, Codec codec, const Camera& camera) {
    EncodedImage e;
    const size_t n = size_t(image.width()) * size_t(image.height());
    if (codec == Codec::Raw) {
        e.payload.resize(n * 8);
        std::memcpy(e.payload.data(), image.color(), n * 4);
        std::memcpy(e.payload.data() + n * 4, image.depth(), n * 4);
        e.rawBytes = uint32_t(e.payload.size());
        return e;
    }
    std::vector<uint8_t> planar = toPlanar(image, camera);
    e.rawBytes = uint32_t(planar.size());
    if (codec == Codec::Lz4) {
        e.payload.resize(size_t(LZ4_compressBound(int(planar.size()))));
        int written = LZ4_compress_default(reinterpret_cast<const char*>(planar.data()),
                                           reinterpret_cast<char*>(e.payload.data()),
                                           int(planar.size()), int(e.payload.size()));
        e.payload.resize(size_t(std::max(written, 0)));
    } else {
        e.payload.resize(ZSTD_compressBound(planar.size()));
        size_t written =
            ZSTD_compress(e.payload.data(), e.payload.size(), planar.data(), planar.size(), 1);
        e.payload.resize(ZSTD_isError(written) ? 0 : written);
    }
    return e;
}

bool decodeImage(std::span<const uint8_t> payload, uint32_t rawBytes, Codec codec, int width,
                 int height, const Camera& camera, Dbi& out) {
    if (width <= 0 || height <= 0 || width > kMaxWindowSize || height > kMaxWindowSize)
        return false;
    const size_t n = size_t(width) * size_t(height);
    if (codec == Codec::Raw) {
        if (payload.size() != n * 8 || rawBytes != payload.size())
            return false;
        out = Dbi(width, height);
        std::memcpy(out.color(), payload.data(), n * 4);
        std::memcpy(out.depth(), payload.data() + n * 4, n * 4);
        return true;
    }
    if (rawBytes != planarBytes(n))
        return false;
    std::vector<uint8_t> planar(rawBytes);
    if (codec == Codec::Lz4) {
        int got = LZ4_decompress_safe(reinterpret_cast<const char*>(payload.data()),
                                      reinterpret_cast<char*>(planar.data()), int(payload.size()),
                                      int(planar.size()));
        if (got != int(planar.size()))
            return false;
    } else {
        size_t got = ZSTD_decompress(planar.data(), planar.size(), payload.data(), payload.size());
        if (ZSTD_isError(got) || got != planar.size())
            return false;
    }
    fromPlanar(planar, width, height, camera, out);
    return true;
}

} // namespace trephine::net

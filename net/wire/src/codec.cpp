#include "net/codec.h"

#include "libsim/error.h"

#include <lz4.h>
#include <zstd.h>

#include <algorithm>
#include <bit>
#include <cfloat>
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
    : m_near(camera.nearMm), m_far(camera.farMm), m_twoFarNear(2.0 * m_far * m_near),
      m_farPlusNear(m_far + m_near), m_farMinusNear(m_far - m_near),
      m_codesPerMm(65534.0 / (m_far - m_near)) {}

float DepthQuantizer::dequantize(uint16_t q) const {
    if (q == kBackground)
        return kBackgroundDepth;
    double dist = m_near + double(q) / 65534.0 * (m_far - m_near);
    // Window depth of eye z = -dist under glm::perspective (GL clip conventions).
    double n = m_near, f = m_far, z = -dist;
    double ndc = (-(f + n) / (f - n) * z - 2.0 * f * n / (f - n)) / -z;
    // At most the largest float below 1, so the far plane never reads back as the background; at
    // least 0: code 0 (the near plane) rounds to ndc just below -1 for many near/far pairs, which
    // read back as -1.1e-16 (down to -3.8e-12), a depth outside [0, 1].
    return std::clamp(float(ndc * 0.5 + 0.5), 0.0f, std::nextafter(1.0f, 0.0f));
}

// GCC vectors (two SSE2 registers on baseline x86-64): every operation is the scalar one lane by
// lane, in the scalar order, and x86-64 has no FMA to contract them, so the bits are the same.
typedef double v4df __attribute__((vector_size(32)));
typedef float v4sf __attribute__((vector_size(16)));
typedef int32_t v4si __attribute__((vector_size(16)));

void DepthQuantizer::quantizeRow(const float* windowDepth, uint16_t* codes, size_t n) const {
    // Scalar: out of order, the divisions of neighbouring values overlap already; GCC's 4-lane
    // version (selects and conversions on SSE2) measured 1.7x slower.
    for (size_t i = 0; i < n; ++i)
        codes[i] = quantize(windowDepth[i]);
}

void DepthQuantizer::dequantizeRow(const uint16_t* codes, float* windowDepth, size_t n) const {
    const double n0 = m_near, f0 = m_far;
    const float below1 = std::nextafter(1.0f, 0.0f);
    size_t i = 0;
    for (; i + 4 <= n; i += 4) {
        const v4si q{codes[i], codes[i + 1], codes[i + 2], codes[i + 3]};
        const v4df dist = n0 + __builtin_convertvector(q, v4df) / 65534.0 * (f0 - n0);
        const v4df z = -dist;
        const v4df ndc = (-(f0 + n0) / (f0 - n0) * z - 2.0 * f0 * n0 / (f0 - n0)) / -z;
        v4sf d = __builtin_convertvector(ndc * 0.5 + 0.5, v4sf);
        d = d < below1 ? d : v4sf{below1, below1, below1, below1};
        d = d < 0.0f ? v4sf{0.0f, 0.0f, 0.0f, 0.0f} : d; // as std::clamp in dequantize
        d = q == int32_t(kBackground)
                ? v4sf{kBackgroundDepth, kBackgroundDepth, kBackgroundDepth, kBackgroundDepth}
                : d;
        std::memcpy(windowDepth + i, &d, sizeof d);
    }
    for (; i < n; ++i)
        windowDepth[i] = dequantize(codes[i]);
}

namespace {

// The largest zstd window a payload may ask for (2^20, 1 MiB): level 1 writes at most 2^19. A
// frame asking more is refused: the streaming decoder would allocate its window.
constexpr int kZstdWindowLogMax = 20;

// One zstd context per thread, kept: creating one per call cost ~9 us a compression and ~8 us a
// decompression, a tenth of a small stroke's update (measured on 5 kB). ZSTD_compress and
// ZSTD_decompress are exactly these calls on a fresh context.
struct ZstdContexts {
    ZSTD_CCtx* c = ZSTD_createCCtx();
    ZSTD_DCtx* d = ZSTD_createDCtx();
    ZstdContexts() {
        if (d)
            ZSTD_DCtx_setParameter(d, ZSTD_d_windowLogMax, kZstdWindowLogMax);
    }
    ~ZstdContexts() {
        ZSTD_freeCCtx(c);
        ZSTD_freeDCtx(d);
    }
};

ZstdContexts& zstdContexts() {
    thread_local ZstdContexts contexts;
    return contexts;
}

size_t zstdCompress(void* dst, size_t capacity, const void* src, size_t size) {
    ZstdContexts& z = zstdContexts();
    return z.c ? ZSTD_compressCCtx(z.c, dst, capacity, src, size, 1)
               : ZSTD_compress(dst, capacity, src, size, 1);
}

// Whether `payload` can decompress to `rawBytes` at all: LZ4 writes fewer than 255 bytes per input
// byte (a match grows by at most 255 a length byte) and zstd at most a 128 KiB block per 4 bytes
// (a block header and an RLE byte). A larger claim is refused at once; a smaller one can still be
// hundreds of MiB, so decompressInto allocates only what the payload proves it holds.
bool canHold(std::span<const uint8_t> payload, Codec codec, size_t rawBytes) {
    const uint64_t most = codec == Codec::Lz4 ? 255 : 32768;
    return uint64_t(payload.size()) * most >= uint64_t(rawBytes);
}

// Claims up to this are allocated at once (a hostile one costs at most this, freed at once); a
// larger buffer is only allocated as the payload proves it holds that much (decompressInto).
constexpr size_t kEagerBytes = size_t(1) << 20;

// zstd: exactly one frame (magic number first, nothing after it) whose header states its content
// size, equal to the claim. ZSTD_compressCCtx always writes the size (Codec.ZstdFramesStateTheir
// ContentSize), so only a hostile or broken peer's frame fails this.
bool zstdFrameClaims(std::span<const uint8_t> payload, size_t rawBytes) {
    if (payload.size() < 4)
        return false;
    uint32_t magic;
    std::memcpy(&magic, payload.data(), 4);
    return magic == ZSTD_MAGICNUMBER &&
           ZSTD_findFrameCompressedSize(payload.data(), payload.size()) == payload.size() &&
           ZSTD_getFrameContentSize(payload.data(), payload.size()) == uint64_t(rawBytes);
}

// The exact number of bytes an LZ4 block decodes to, read from its sequences without decoding
// them (literals skipped, match lengths added), or SIZE_MAX for a block that cannot decode: a
// length running past the end, a match offset of 0 or before the start of the output, a block
// not ending in literals, or more output than `limit`. O(sequences), no allocation.
size_t lz4DecodedSize(std::span<const uint8_t> block, size_t limit) {
    const uint8_t* p = block.data();
    const uint8_t* const end = p + block.size();
    auto length = [&](size_t n, size_t& out) {
        out = n;
        if (n != 15)
            return true;
        uint8_t b;
        do {
            if (p == end)
                return false;
            b = *p++;
            out += b;
        } while (b == 255);
        return true;
    };
    size_t out = 0;
    while (p < end) {
        const unsigned token = *p++;
        size_t literals, match;
        if (!length(token >> 4, literals) || size_t(end - p) < literals)
            return SIZE_MAX;
        p += literals;
        out += literals;
        if (out > limit)
            return SIZE_MAX;
        if (p == end)
            return out; // the last sequence: literals only
        if (end - p < 2)
            return SIZE_MAX;
        const size_t offset = size_t(p[0]) | size_t(p[1]) << 8;
        p += 2;
        if (offset == 0 || offset > out || !length(token & 15, match))
            return SIZE_MAX;
        out += match + 4;
        if (out > limit)
            return SIZE_MAX;
    }
    return SIZE_MAX; // empty, or ended with a match
}

// Decompresses `payload` into `out`, resized to exactly rawBytes; false when it does not give
// exactly that. The allocation follows what the payload really holds, not what its sender claims:
// up to kEagerBytes at once; beyond, lz4 is allocated once its sequences have been added up to
// exactly rawBytes, and zstd (whose compressed blocks do not state their output) decodes as a
// stream into a buffer that starts at kEagerBytes and grows eightfold, capped at rawBytes, each
// time real output fills it (at most 8 times the output, 1.25 times rawBytes at the peak of an
// honest payload). zstd's own window buffer is bounded by kZstdWindowLogMax.
bool decompressInto(std::span<const uint8_t> payload, Codec codec, size_t rawBytes,
                    std::vector<uint8_t>& out) {
    if (codec == Codec::Lz4) {
        if (rawBytes > kEagerBytes && lz4DecodedSize(payload, rawBytes) != rawBytes)
            return false;
        out.resize(rawBytes);
        const int got = LZ4_decompress_safe(reinterpret_cast<const char*>(payload.data()),
                                            reinterpret_cast<char*>(out.data()),
                                            int(payload.size()), int(out.size()));
        return got == int(out.size());
    }
    if (!zstdFrameClaims(payload, rawBytes))
        return false;
    ZstdContexts& z = zstdContexts();
    if (rawBytes <= kEagerBytes || !z.d) {
        out.resize(rawBytes);
        const size_t got =
            z.d ? ZSTD_decompressDCtx(z.d, out.data(), out.size(), payload.data(), payload.size())
                : ZSTD_decompress(out.data(), out.size(), payload.data(), payload.size());
        return !ZSTD_isError(got) && got == out.size();
    }
    ZSTD_DCtx_reset(z.d, ZSTD_reset_session_only);
    out.resize(kEagerBytes);
    ZSTD_inBuffer in{payload.data(), payload.size(), 0};
    ZSTD_outBuffer o{out.data(), out.size(), 0};
    for (;;) {
        const size_t inWas = in.pos, outWas = o.pos;
        const size_t left = ZSTD_decompressStream(z.d, &o, &in);
        if (ZSTD_isError(left))
            return false;
        if (left == 0) // the frame is complete (zstd checked its content size)
            return o.pos == rawBytes && in.pos == in.size;
        if (o.pos == o.size) {
            if (o.size == rawBytes)
                return false; // more than claimed
            out.resize(std::min(rawBytes, 8 * out.size()));
            o.dst = out.data();
            o.size = out.size();
        } else if (in.pos == inWas && o.pos == outWas) {
            return false; // the frame wants input that is not there
        }
    }
}

// Whether the n float32 depths at `bytes` (a raw update's, host order as the codec sends them)
// are depths a renderer writes: +0, or a normal float in (0, 1] (1 is the background). NaN, the
// infinities, negative numbers, -0, subnormals and values above 1 are not (docs/protocol.md).
// Bits as unsigned: +0 is 0, the positive normal floats up to 1 one interval; no branch a value.
bool depthsInRange(const uint8_t* bytes, size_t n) {
    constexpr uint32_t kLo = std::bit_cast<uint32_t>(FLT_MIN), kHi = std::bit_cast<uint32_t>(1.0f);
    uint32_t bad = 0;
    for (size_t i = 0; i < n; ++i) {
        uint32_t b;
        std::memcpy(&b, bytes + 4 * i, 4);
        bad |= uint32_t(b != 0) & uint32_t(b - kLo > kHi - kLo);
    }
    return bad == 0;
}

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
            zstdCompress(e.payload.data(), e.payload.size(), planar.data(), planar.size());
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
        if (payload.size() != n * 8 || rawBytes != payload.size() ||
            !depthsInRange(payload.data() + n * 4, n))
            return false;
        out = Dbi(width, height);
        std::memcpy(out.color(), payload.data(), n * 4);
        std::memcpy(out.depth(), payload.data() + n * 4, n * 4);
        return true;
    }
    if (rawBytes != planarBytes(n) || !canHold(payload, codec, rawBytes))
        return false;
    std::vector<uint8_t> planar;
    if (!decompressInto(payload, codec, rawBytes, planar))
        return false;
    fromPlanar(planar, width, height, camera, out);
    return true;
}

// [SECTION] volume

std::vector<uint8_t> compressBytes(std::span<const uint8_t> raw, Codec codec) {
    std::vector<uint8_t> out;
    if (codec == Codec::Raw) {
        out.assign(raw.begin(), raw.end());
    } else if (codec == Codec::Lz4) {
        out.resize(size_t(LZ4_compressBound(int(raw.size()))));
        int written = LZ4_compress_default(reinterpret_cast<const char*>(raw.data()),
                                           reinterpret_cast<char*>(out.data()), int(raw.size()),
                                           int(out.size()));
        out.resize(size_t(std::max(written, 0)));
    } else {
        out.resize(ZSTD_compressBound(raw.size()));
        size_t written = zstdCompress(out.data(), out.size(), raw.data(), raw.size());
        out.resize(ZSTD_isError(written) ? 0 : written);
    }
    return out;
}

bool decompressBytes(std::span<const uint8_t> payload, Codec codec, size_t rawBytes,
                     std::vector<uint8_t>& out) {
    if (codec == Codec::Raw) {
        if (payload.size() != rawBytes)
            return false;
        out.assign(payload.begin(), payload.end());
        return true;
    }
    if (rawBytes > size_t(kMaxVolumeRawBytes) || payload.empty() ||
        !canHold(payload, codec, rawBytes))
        return false;
    return decompressInto(payload, codec, rawBytes, out);
}

EncodedVolume encodeVolumeBox(const Volume& volume, const Box3i& box, Codec codec, bool materials) {
    EncodedVolume e;
    Box3i b = box.intersect(volume.bounds());
    if (b.empty())
        return e;
    const size_t n = size_t(b.count());
    std::vector<uint8_t> raw(materials ? 2 * n : n);
    const glm::ivec3 size = b.size();
    const uint8_t* den = volume.densityData();
    const uint8_t* mat = volume.materialData();
    uint8_t* o = raw.data();
    for (int z = b.lo.z; z < b.hi.z; ++z)
        for (int y = b.lo.y; y < b.hi.y; ++y) {
            size_t i = volume.index(b.lo.x, y, z);
            std::memcpy(o, den + i, size_t(size.x));
            if (materials)
                std::memcpy(o + n, mat + i, size_t(size.x));
            o += size.x;
        }
    e.rawBytes = uint32_t(raw.size());
    e.codec = codec;
    e.payload = codec == Codec::Raw ? std::move(raw) : compressBytes(raw, codec);
    return e;
}

EncodedVolume encodeVolumeFull(const Volume& volume, Codec codec) {
    EncodedVolume e;
    const size_t n = volume.voxelCount();
    std::vector<uint8_t> raw(n * 2);
    std::memcpy(raw.data(), volume.densityData(), n);
    std::memcpy(raw.data() + n, volume.materialData(), n);
    e.rawBytes = uint32_t(raw.size());
    e.codec = codec == Codec::Raw ? Codec::Zstd : codec;
    e.payload = compressBytes(raw, e.codec);
    return e;
}

bool applyVolumeBox(Volume& volume, const Box3i& box, std::span<const uint8_t> densities,
                    std::span<const uint8_t> materials) {
    if (box.empty() || !(box.intersect(volume.bounds()) == box) ||
        densities.size() != size_t(box.count()) ||
        (!materials.empty() && materials.size() != densities.size()))
        return false;
    for (uint8_t m : materials)
        if (m >= uint8_t(kMaterialCount))
            return false; // a material label we do not know
    const uint8_t* inMat = materials.empty() ? nullptr : materials.data();
    const glm::ivec3 size = box.size();
    uint8_t* den = volume.densityData();
    uint8_t* mat = volume.materialData();
    const uint8_t* in = densities.data();
    for (int z = box.lo.z; z < box.hi.z; ++z)
        for (int y = box.lo.y; y < box.hi.y; ++y) {
            size_t row = volume.index(box.lo.x, y, z);
            for (int x = 0; x < size.x; ++x) {
                uint8_t d = *in++;
                den[row + size_t(x)] = d;
                if (inMat)
                    mat[row + size_t(x)] = *inMat++;
                else if (d == 0)
                    mat[row + size_t(x)] = uint8_t(Material::Air);
            }
        }
    return true;
}

bool decodeVolumeFull(std::span<const uint8_t> payload, uint32_t rawBytes, Codec codec,
                      glm::ivec3 dims, glm::vec3 spacing, Volume& out) {
    if (dims.x <= 0 || dims.y <= 0 || dims.z <= 0 || dims.x > kMaxVolumeDim ||
        dims.y > kMaxVolumeDim || dims.z > kMaxVolumeDim)
        return false;
    const uint64_t n = uint64_t(dims.x) * uint64_t(dims.y) * uint64_t(dims.z);
    if (uint64_t(rawBytes) != n * 2 || codec == Codec::Raw)
        return false;
    std::vector<uint8_t> raw;
    if (!decompressBytes(payload, codec, rawBytes, raw))
        return false;
    for (size_t i = size_t(n); i < raw.size(); ++i)
        if (raw[i] >= uint8_t(kMaterialCount))
            return false; // a material label we do not know
    Volume v(dims, spacing);
    std::memcpy(v.densityData(), raw.data(), size_t(n));
    std::memcpy(v.materialData(), raw.data() + n, size_t(n));
    out = std::move(v);
    return true;
}

} // namespace trephine::net

// Image-update codecs: how a DBI rectangle travels. `raw` is the bit-exact reference (RGBA8 +
// float32 depth, 8 bytes a pixel). `lz4` and `zstd` send a planar layout — R, G and B planes,
// then depth quantised to 16 bits of linear eye distance between the camera's near and far
// planes, delta-coded along rows and split into high and low byte planes — and compress it.
// Alpha is not sent: pixels at the background depth (1.0) have alpha 0, others 255.
// Volume updates of the replicated-volume baseline use the same codecs on voxel bytes (see
// [SECTION] volume below and docs/protocol.md).
#pragma once

#include "libsim/box.h"
#include "libsim/camera.h"
#include "libsim/dbi.h"
#include "libsim/volume.h"
#include "net/protocol.h"

#include <cstdint>
#include <span>
#include <string>
#include <vector>

namespace trephine::net {

const char* codecName(Codec c);
// "raw", "lz4" or "zstd"; throws trephine::Error naming the text otherwise.
Codec parseCodec(const std::string& text);

// Maps window depth to 16-bit linear eye distance and back for one camera's near/far.
class DepthQuantizer {
public:
    explicit DepthQuantizer(const Camera& camera);
    static constexpr uint16_t kBackground = 0xffff; // exactly kBackgroundDepth

    // Inline: the predicted image form quantises every pixel of a rectangle at both ends.
    uint16_t quantize(float windowDepth) const {
        // NaN too (a raw update's depths are whatever was sent): its code would be undefined.
        if (!(windowDepth < kBackgroundDepth))
            return kBackground;
        // Eye distance under glm::perspective (eyeZFromWindowDepth, negated), then linear codes.
        const double ndc = double(windowDepth) * 2.0 - 1.0;
        const double dist = m_twoFarNear / (m_farPlusNear - ndc * m_farMinusNear);
        const double code = (dist - m_near) * m_codesPerMm;
        return code <= 0.0 ? 0 : code >= 65534.0 ? 65534 : uint16_t(code + 0.5);
    }
    float dequantize(uint16_t q) const;
    // quantize and dequantize over n values, every code and depth bit for bit the one-value
    // functions' (the predicted form's passes). dequantizeRow works four lanes at a time;
    // quantizeRow stays scalar (a 4-lane version measured 1.7x slower).
    void quantizeRow(const float* windowDepth, uint16_t* codes, size_t n) const;
    void dequantizeRow(const uint16_t* codes, float* windowDepth, size_t n) const;
    // Worst-case error of a round trip, in millimetres of eye distance: half a quantisation step.
    double stepMm() const { return (m_far - m_near) / 65534.0; }

private:
    double m_near, m_far;
    double m_twoFarNear, m_farPlusNear, m_farMinusNear, m_codesPerMm;
};

struct EncodedImage {
    std::vector<uint8_t> payload;
    uint32_t rawBytes = 0; // bytes of the layout before compression
};

// Encodes a whole image (a rectangle already extracted from the full DBI).
EncodedImage encodeImage(const Dbi& image, Codec codec, const Camera& camera);
// Decodes into `out` (resized to width x height); false when the payload is malformed (wrong
// size, corrupt compression, a raw depth that is not +0 or a normal float in (0, 1]) — never a
// crash. Every depth decoded lies in [0, 1]: the quantised codecs cannot produce any other.
bool decodeImage(std::span<const uint8_t> payload, uint32_t rawBytes, Codec codec, int width,
                 int height, const Camera& camera, Dbi& out);

// [SECTION] volume

// Compresses bytes with a codec (Raw: a copy); zstd at level 1.
std::vector<uint8_t> compressBytes(std::span<const uint8_t> raw, Codec codec);
// Decompresses into exactly rawBytes bytes; false when the payload does not give exactly that.
bool decompressBytes(std::span<const uint8_t> payload, Codec codec, size_t rawBytes,
                     std::vector<uint8_t>& out);

struct EncodedVolume {
    std::vector<uint8_t> payload;
    uint32_t rawBytes = 0;
    Codec codec = Codec::Raw; // what the payload is encoded with
};
// A box update: the density byte of every voxel of `box` (x fastest), 1 byte each, with `codec`;
// with `materials`, the box's material bytes follow the densities.
EncodedVolume encodeVolumeBox(const Volume& volume, const Box3i& box, Codec codec,
                              bool materials = false);
// The whole volume: every density byte, then every material byte, compressed with `codec`, or
// with zstd when `codec` is Raw (a full volume always travels compressed).
EncodedVolume encodeVolumeFull(const Volume& volume, Codec codec);
// Writes a decoded box's densities into `volume` and derives materials the way the server's
// erosion and box cuts leave them: Air where the density is 0, unchanged elsewhere. `densities`
// must hold box.count() bytes and the box lie inside the volume (false otherwise, nothing written).
// With `materials` (box.count() known labels) those are written instead of derived.
bool applyVolumeBox(Volume& volume, const Box3i& box, std::span<const uint8_t> densities,
                    std::span<const uint8_t> materials = {});
// Decodes a full update into a volume of `dims` and `spacing`; false when malformed.
bool decodeVolumeFull(std::span<const uint8_t> payload, uint32_t rawBytes, Codec codec,
                      glm::ivec3 dims, glm::vec3 spacing, Volume& out);

} // namespace trephine::net

// Image-update codecs: how a DBI rectangle travels. `raw` is the bit-exact reference (RGBA8 +
// float32 depth, 8 bytes a pixel). `lz4` and `zstd` send a planar layout — R, G and B planes,
// then depth quantised to 16 bits of linear eye distance between the camera's near and far
// planes, delta-coded along rows and split into high and low byte planes — and compress it.
// Alpha is not sent: pixels at the background depth (1.0) have alpha 0, others 255.
#pragma once

#include "libsim/camera.h"
#include "libsim/dbi.h"
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

    uint16_t quantize(float windowDepth) const;
    float dequantize(uint16_t q) const;
    // Worst-case error of a round trip, in millimetres of eye distance: half a quantisation step.
    double stepMm() const { return (m_far - m_near) / 65534.0; }

private:
    Camera m_camera;
    double m_near, m_far;
};

struct EncodedImage {
    std::vector<uint8_t> payload;
    uint32_t rawBytes = 0; // bytes of the layout before compression
};

// Encodes a whole image (a rectangle already extracted from the full DBI).
EncodedImage encodeImage(const Dbi& image, Codec codec, const Camera& camera);
// Decodes into `out` (resized to width x height); false when the payload is malformed (wrong
// size, corrupt compression) — never a crash.
bool decodeImage(std::span<const uint8_t> payload, uint32_t rawBytes, Codec codec, int width,
                 int height, const Camera& camera, Dbi& out);

} // namespace trephine::net

// The "predicted" image-update form: a rectangle coded against the pixels the client already
// holds there. Drilling changes only part of BB_screen (the stencil margin and the unchanged rim
// keep their pixels), and what changes is a smooth surface, so the update sends
//   mask      1 bit a pixel (LSB first, raster order from the bottom row): colour or quantised
//             depth differs from the client's copy,
//   exact     1 bit per changed pixel (raster order): its five residuals below are all 0, as
//             for background seen through a hole; such a pixel stores none (protocol 5),
//   residuals for the other changed pixels only, raster order: R, then G-R and B-R (the shading
//             scales one material colour, so the channels move together), then the high and low
//             bytes of 16-bit linear depth; each residual is the value minus the median edge
//             detector (LOCO-I / JPEG-LS) prediction from the left, lower and lower-left
//             neighbours of the *new* image (unchanged neighbours are the client's own pixels),
// compressed with the client's codec. It needs the client's copy to be exactly what the server
// believes it is: the server keeps one per client, and the update carries a hash of the pixels it
// was coded against, so a client whose copy differs refuses it and asks for a full image instead
// of showing a wrong one (docs/protocol.md, docs/session.md).
#pragma once

#include "libsim/dbi.h"
#include "net/codec.h"
#include "net/protocol.h"

#include <cstdint>
#include <span>
#include <vector>

namespace trephine::net {

struct PredictedImage {
    std::vector<uint8_t> payload;
    uint32_t rawBytes = 0; // the layout above before compression
    int changedPixels = 0; // pixels the mask marks
    uint32_t baseHash = 0; // basePixelHash of the pixels it was coded against
};

// A 32-bit hash of a rectangle's R, G, B and quantised depth: what the predicted form depends on.
uint32_t basePixelHash(const Dbi& image, const DepthQuantizer& quantizer);

enum class PredictedStatus { Ok, Malformed, BaseMismatch };

// `next` is the rectangle now; `base` the same rectangle as the client holds it (same size).
// codec must be Lz4 or Zstd (Raw stays the bit-exact reference and is never predicted).
PredictedImage encodePredicted(const Dbi& next, const Dbi& base, Codec codec,
                               const DepthQuantizer& quantizer);

// Decodes in place: `image` holds the client's pixels of the rectangle on entry and the new
// pixels on Ok. BaseMismatch when those pixels are not the ones the update was coded against
// (hash differs); Malformed for wrong sizes, a mask that disagrees with the residual count or
// corrupt compression. `image` is unchanged unless Ok.
PredictedStatus decodePredicted(std::span<const uint8_t> payload, uint32_t rawBytes, Codec codec,
                                uint32_t baseHash, const DepthQuantizer& quantizer, Dbi& image);

} // namespace trephine::net

// The depth-buffered image (DBI): RGBA8 colour and float GL window depth per pixel, row 0 at the
// bottom (glReadPixels order). What the server renders and a client composites with its geometry.
#pragma once

#include "libsim/unset_allocator.h"

#include <cstdint>
#include <memory>
#include <string>
#include <utility>
#include <vector>

namespace trephine {

// A rectangle of pixels: columns [x, x + w), rows [y, y + h). Row 0 is the bottom row unless a
// function says otherwise; flipRows converts to and from top-left origin (files, command line).
struct PixelRect {
    int x = 0;
    int y = 0;
    int w = 0;
    int h = 0;

    bool empty() const { return w <= 0 || h <= 0; }
    int64_t area() const { return empty() ? 0 : int64_t(w) * h; }
    bool contains(int px, int py) const { return px >= x && py >= y && px < x + w && py < y + h; }
    // True when every pixel of o lies in this rectangle (an empty o always does).
    bool contains(const PixelRect& o) const {
        return o.empty() || (o.x >= x && o.y >= y && o.x + o.w <= x + w && o.y + o.h <= y + h);
    }
    bool operator==(const PixelRect&) const = default;
};

// The same pixels with rows counted from the other edge of a window `height` rows tall.
inline PixelRect flipRows(PixelRect r, int height) {
    return {r.x, height - (r.y + r.h), r.w, r.h};
}
PixelRect intersect(const PixelRect& a, const PixelRect& b);
// Smallest rectangle holding both (an empty one is ignored).
PixelRect unite(const PixelRect& a, const PixelRect& b);
std::string describe(const PixelRect& r); // "x y w h"

// Colour of pixels that show no bone; alpha 0 so a client may also blend instead of depth-test.
inline constexpr uint8_t kBackgroundRgba[4] = {24, 26, 32, 0};
// Depth of pixels that show no bone: the far plane, so any client geometry wins the depth test.
inline constexpr float kBackgroundDepth = 1.0f;

class Dbi {
public:
    Dbi() = default;
    // A width x height image filled with the background (colour kBackgroundRgba, depth 1).
    Dbi(int width, int height);
    // A width x height image whose pixels are not set, for a buffer about to be written whole:
    // a 2048 x 2048 image's 32 MB are then written once, by whoever fills them, not first here.
    static Dbi unfilled(int width, int height);

    int width() const { return m_width; }
    int height() const { return m_height; }
    bool empty() const { return m_width == 0 || m_height == 0; }
    PixelRect bounds() const { return {0, 0, m_width, m_height}; }

    size_t index(int x, int y) const { return size_t(y) * size_t(m_width) + size_t(x); }
    // RGBA8, 4 bytes per pixel, rows bottom to top.
    uint8_t* color() { return m_color.data(); }
    const uint8_t* color() const { return m_color.data(); }
    const uint8_t* color(int x, int y) const { return m_color.data() + 4 * index(x, y); }
    uint8_t* color(int x, int y) { return m_color.data() + 4 * index(x, y); }
    // GL window depth in [0, 1], rows bottom to top.
    float* depth() { return m_depth.data(); }
    const float* depth() const { return m_depth.data(); }
    float depth(int x, int y) const { return m_depth[index(x, y)]; }

    void fillBackground();
    // The pixels of `rect` (which must lie inside this image) as an image of the rectangle's size.
    Dbi extract(const PixelRect& rect) const;
    // Writes `patch` with its bottom-left pixel at (x, y); the patch must fit inside this image.
    void apply(const Dbi& patch, int x, int y);

    // Bit-for-bit equality of size, colour and depth.
    bool operator==(const Dbi& o) const;

private:
    int m_width = 0;
    int m_height = 0;
    std::vector<uint8_t, UnsetAllocator<uint8_t>> m_color;
    std::vector<float, UnsetAllocator<float>> m_depth;
};

// Where two images of the same size differ.
struct DbiDiff {
    int64_t differingPixels = 0; // colour or depth bits differ
    PixelRect bounds;            // bounding rectangle of the differing pixels (empty if none)
    float maxDepthError = 0.0f;  // largest |depth a - depth b|
    int maxColorError = 0;       // largest difference in any colour channel
    bool sameSize = true;

    bool identical() const { return sameSize && differingPixels == 0; }
    std::string describe() const;
};
DbiDiff compare(const Dbi& a, const Dbi& b);

} // namespace trephine

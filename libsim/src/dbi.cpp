#include "libsim/dbi.h"

#include <algorithm>
#include <cassert>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fmt/format.h>

namespace trephine {

PixelRect intersect(const PixelRect& a, const PixelRect& b) {
    int x0 = std::max(a.x, b.x), y0 = std::max(a.y, b.y);
    int x1 = std::min(a.x + a.w, b.x + b.w), y1 = std::min(a.y + a.h, b.y + b.h);
    if (x1 <= x0 || y1 <= y0)
        return {};
    return {x0, y0, x1 - x0, y1 - y0};
}

PixelRect unite(const PixelRect& a, const PixelRect& b) {
    if (a.empty())
        return b.empty() ? PixelRect{} : b;
    if (b.empty())
        return a;
    int x0 = std::min(a.x, b.x), y0 = std::min(a.y, b.y);
    int x1 = std::max(a.x + a.w, b.x + b.w), y1 = std::max(a.y + a.h, b.y + b.h);
    return {x0, y0, x1 - x0, y1 - y0};
}

std::string describe(const PixelRect& r) {
    return fmt::format("{} {} {} {}", r.x, r.y, r.w, r.h);
}

Dbi::Dbi(int width, int height) : Dbi(unfilled(width, height)) {
    fillBackground();
}

Dbi Dbi::unfilled(int width, int height) {
    assert(width >= 0 && height >= 0 && "Dbi size must not be negative");
    Dbi out;
    out.m_width = width;
    out.m_height = height;
    out.m_color.resize(size_t(width) * size_t(height) * 4);
    out.m_depth.resize(size_t(width) * size_t(height));
    return out;
}

void Dbi::fillBackground() {
    for (size_t i = 0; i < m_depth.size(); ++i) {
        std::memcpy(&m_color[4 * i], kBackgroundRgba, 4);
        m_depth[i] = kBackgroundDepth;
    }
}

Dbi Dbi::extract(const PixelRect& rect) const {
    assert(bounds().contains(rect) && "Dbi::extract: rectangle outside the image");
    Dbi out = unfilled(rect.w, rect.h);
    for (int row = 0; row < rect.h; ++row) {
        size_t src = index(rect.x, rect.y + row);
        size_t dst = out.index(0, row);
        std::memcpy(&out.m_color[4 * dst], &m_color[4 * src], 4 * size_t(rect.w));
        std::memcpy(&out.m_depth[dst], &m_depth[src], sizeof(float) * size_t(rect.w));
    }
    return out;
}

void Dbi::apply(const Dbi& patch, int x, int y) {
    assert(bounds().contains(PixelRect{x, y, patch.width(), patch.height()}) &&
           "Dbi::apply: patch does not fit inside the image");
    for (int row = 0; row < patch.height(); ++row) {
        size_t src = patch.index(0, row);
        size_t dst = index(x, y + row);
        std::memcpy(&m_color[4 * dst], &patch.m_color[4 * src], 4 * size_t(patch.width()));
        std::memcpy(&m_depth[dst], &patch.m_depth[src], sizeof(float) * size_t(patch.width()));
    }
}

bool Dbi::operator==(const Dbi& o) const {
    // Depth compares as bits: equal floats with different bits (never produced here) would still
    // be different images on the wire.
    return m_width == o.m_width && m_height == o.m_height && m_color == o.m_color &&
           (m_depth.empty() ||
            std::memcmp(m_depth.data(), o.m_depth.data(), m_depth.size() * sizeof(float)) == 0);
}

DbiDiff compare(const Dbi& a, const Dbi& b) {
    DbiDiff d;
    if (a.width() != b.width() || a.height() != b.height()) {
        d.sameSize = false;
        return d;
    }
    int x0 = a.width(), y0 = a.height(), x1 = -1, y1 = -1;
    for (int y = 0; y < a.height(); ++y) {
        for (int x = 0; x < a.width(); ++x) {
            const uint8_t* ca = a.color(x, y);
            const uint8_t* cb = b.color(x, y);
            float da = a.depth(x, y), db = b.depth(x, y);
            bool differs = std::memcmp(ca, cb, 4) != 0 || std::memcmp(&da, &db, 4) != 0;
            if (!differs)
                continue;
            d.differingPixels++;
            x0 = std::min(x0, x), y0 = std::min(y0, y), x1 = std::max(x1, x), y1 = std::max(y1, y);
            d.maxDepthError = std::max(d.maxDepthError, std::abs(da - db));
            for (int c = 0; c < 4; ++c)
                d.maxColorError = std::max(d.maxColorError, std::abs(int(ca[c]) - int(cb[c])));
        }
    }
    if (d.differingPixels > 0)
        d.bounds = {x0, y0, x1 - x0 + 1, y1 - y0 + 1};
    return d;
}

std::string DbiDiff::describe() const {
    if (!sameSize)
        return "images differ in size";
    return fmt::format("{} differing pixels in rect {}, max depth error {:g}, max colour error {}",
                       differingPixels, trephine::describe(bounds), double(maxDepthError),
                       maxColorError);
}

} // namespace trephine

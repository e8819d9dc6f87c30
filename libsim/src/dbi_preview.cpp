#include "libsim/dbi_preview.h"

#include <algorithm>
#include <cassert>
#include <cstring>

namespace trephine {

Camera previewCamera(const Camera& view) {
    Camera half = view;
    half.width = (view.width + 1) / 2;
    half.height = (view.height + 1) / 2;
    return half;
}

void upsampleRows(const Dbi& half, int row, int rows, Dbi& full) {
    assert(half.width() == (full.width() + 1) / 2 && half.height() == (full.height() + 1) / 2 &&
           "upsampleRows: `half` is not the preview of `full`");
    const int w = full.width();
    for (int y = row; y < std::min(row + rows, half.height()); ++y) {
        const uint8_t* srcColor = half.color(0, y);
        const float* srcDepth = half.depth() + half.index(0, y);
        uint8_t* color = full.color(0, 2 * y);
        float* depth = full.depth() + full.index(0, 2 * y);
        for (int x = 0; x < w; ++x) {
            std::memcpy(color + 4 * x, srcColor + 4 * (x / 2), 4);
            depth[x] = srcDepth[x / 2];
        }
        if (2 * y + 1 < full.height()) { // the block's upper row is the same
            std::memcpy(full.color(0, 2 * y + 1), color, 4 * size_t(w));
            std::memcpy(full.depth() + full.index(0, 2 * y + 1), depth, sizeof(float) * size_t(w));
        }
    }
}

} // namespace trephine

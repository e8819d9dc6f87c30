// A new view's first picture at reduced resolution (docs/session.md, "Progressive first
// pictures"): the same camera at half width and height, its pixels written back as 2 x 2 blocks.
#pragma once

#include "libsim/camera.h"
#include "libsim/dbi.h"

namespace trephine {

// The view with a window half as wide and tall (rounded up), all else kept. For even sides the
// projection is the view's (the same aspect), and preview pixel (i, j) is the ray through the
// centre of the view's 2 x 2 block at (2i, 2j); near and far are kept, so its depth is the GL
// window depth the view gives that point. For an odd side the last block is clipped and the
// aspect differs by under one pixel: a preview, not the picture.
Camera previewCamera(const Camera& view);

// Writes rows [row, row + rows) of `half` (a previewCamera-sized DBI) into `full` (the view's
// size), each pixel as a 2 x 2 block clipped to `full`.
void upsampleRows(const Dbi& half, int row, int rows, Dbi& full);

} // namespace trephine

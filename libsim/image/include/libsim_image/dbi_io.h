// DBI image files: OpenEXR with colour and GL window depth (for tools and tests) and PNG colour
// (for people). Files are top-down (row 0 at the top), DBIs in memory bottom-up: rows flip here.
#pragma once

#include "libsim/dbi.h"

#include <string>

namespace trephine {

// Writes `image` as OpenEXR: channels R, G, B, A (half, colour / 255) and Z (float: the GL window
// depth, bit for bit). Throws trephine::Error if the file cannot be written.
void writeDbiExr(const std::string& path, const Dbi& image);
// Throws the Error writeDbiExr would for `path`'s name (not ending in .exr), writing nothing: for
// callers that write much later.
void checkDbiExrPath(const std::string& path);
// Writes a rectangle of a larger frame: `image` holds the pixels of `rectInFrame` (row 0 at the
// bottom, as in the DBI) of a frameWidth x frameHeight window. The EXR's data window is the
// rectangle at its place in the frame and its display window the full frame.
void writeDbiExr(const std::string& path, const Dbi& image, const PixelRect& rectInFrame,
                 int frameWidth, int frameHeight);

// A DBI read back from OpenEXR, with where it sits in its frame.
struct DbiFile {
    Dbi image;
    PixelRect rectInFrame; // row 0 at the bottom of the frame
    int frameWidth = 0;
    int frameHeight = 0;
};
// Reads an EXR written by writeDbiExr (any EXR with R, G, B and Z channels; A is optional and
// taken as 255 where depth < 1, else 0). A missing file, a file that is not OpenEXR or one with
// no Z channel throws trephine::Error with one line naming the file and the problem.
DbiFile readDbiExr(const std::string& path);

// Writes the colour of `image` as an 8-bit RGB PNG, top row first.
void writeColorPng(const std::string& path, const Dbi& image);
// Throws the Error writeColorPng would for `path`'s name (not ending in .png), writing nothing.
void checkColorPngPath(const std::string& path);

} // namespace trephine

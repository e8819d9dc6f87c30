// Reading screenshots back in GUI tests: an 8-bit RGB image, top row first, as the PNG holds it.
#pragma once

#include <OpenImageIO/imageio.h>

#include <cstdint>
#include <string>
#include <vector>

namespace trephine::testing {

struct Image {
    int w = 0, h = 0;
    std::vector<uint8_t> rgb; // top row first
    const uint8_t* at(int x, int y) const { return &rgb[(size_t(y) * size_t(w) + size_t(x)) * 3]; }
};

// The first three channels of an image file as RGB8; an empty image when it cannot be read.
inline Image readPng(const std::string& path) {
    Image img;
    auto in = OIIO::ImageInput::open(path);
    if (!in)
        return img;
    img.w = in->spec().width;
    img.h = in->spec().height;
    img.rgb.resize(size_t(img.w) * size_t(img.h) * 3);
    in->read_image(0, 0, 0, 3, OIIO::TypeDesc::UINT8, img.rgb.data());
    return img;
}

} // namespace trephine::testing

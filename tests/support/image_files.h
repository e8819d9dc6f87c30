// Image files for the slice and DBI tests, written through OpenImageIO.
#pragma once

#include <OpenImageIO/imageio.h>
#include <gtest/gtest.h>

#include <string>
#include <vector>

namespace trephine::testing {

// `pixels` (w x h x channels values of `type`, rows top-down) as an image file; the format follows
// the name's extension.
template <typename T>
void writeImage(const std::string& path, int w, int h, int channels, OIIO::TypeDesc type,
                const std::vector<T>& pixels) {
    auto out = OIIO::ImageOutput::create(path);
    ASSERT_TRUE(out) << OIIO::geterror();
    OIIO::ImageSpec spec(w, h, channels, type);
    ASSERT_TRUE(out->open(path, spec)) << out->geterror();
    ASSERT_TRUE(out->write_image(type, pixels.data())) << out->geterror();
    ASSERT_TRUE(out->close());
}

} // namespace trephine::testing

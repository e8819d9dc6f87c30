#include "net/codec.h"

#include "libsim/error.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

using namespace trephine;
using namespace trephine::net;

namespace {

// A DBI of a tilted plane seen by `camera`, with a hole of background pixels, so depths are real
// window depths of real points.
Dbi planeImage(const Camera& camera, int w, int h) {
    Dbi img(w, h);
    glm::dmat4 vp = viewProjection(camera);
    std::mt19937 rng(3);
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
            if ((x - w / 2) * (x - w / 2) + (y - h / 2) * (y - h / 2) < 16)
                continue; // background
            glm::dvec3 p(x - w / 2.0, y - h / 2.0, 0.3 * x - 0.2 * y);
            size_t i = img.index(x, y);
            img.depth()[i] = windowDepth(vp, p);
            uint8_t* c = img.color(x, y);
            c[0] = uint8_t(200 + x % 50);
            c[1] = uint8_t(rng());
            c[2] = uint8_t(y);
            c[3] = 255;
        }
    return img;
}

Camera testCamera() {
    Camera c;
    c.eye = {0, 0, 300};
    c.nearMm = 110;
    c.farMm = 550;
    c.width = c.height = 64;
    c.fovYDeg = 60;
    return c;
}

} // namespace

TEST(Codec, RawIsBitExact) {
    Camera cam = testCamera();
    Dbi img = planeImage(cam, 40, 30);
    EncodedImage e = encodeImage(img, Codec::Raw, cam);
    EXPECT_EQ(e.payload.size(), 40u * 30u * 8u);
    Dbi back;
    ASSERT_TRUE(decodeImage(e.payload, e.rawBytes, Codec::Raw, 40, 30, cam, back));
    EXPECT_TRUE(back == img);
}

// The documented bound: depth error at most half a quantisation step of linear eye distance
// ((far - near) / 65534 / 2, 0.0034 mm for near 110, far 550), colour exact, background exact.
TEST(Codec, QuantisedCodecsStayWithinTheDocumentedDepthError) {
    Camera cam = testCamera();
    Dbi img = planeImage(cam, 40, 30);
    DepthQuantizer q(cam);
    const double boundMm = q.stepMm() / 2.0 + 1e-4; // + float rounding of the window depth
    EXPECT_LT(q.stepMm() / 2.0, 0.004);
    for (Codec codec : {Codec::Lz4, Codec::Zstd}) {
        EncodedImage e = encodeImage(img, codec, cam);
        EXPECT_EQ(e.rawBytes, 40u * 30u * 5u);
        EXPECT_LT(e.payload.size(), e.rawBytes) << codecName(codec) << " did not compress";
        Dbi back;
        ASSERT_TRUE(decodeImage(e.payload, e.rawBytes, codec, 40, 30, cam, back));
        double worst = 0;
        for (int y = 0; y < 30; ++y)
            for (int x = 0; x < 40; ++x) {
                const uint8_t* a = img.color(x, y);
                const uint8_t* b = back.color(x, y);
                ASSERT_EQ(std::memcmp(a, b, 3), 0);
                if (img.depth(x, y) == kBackgroundDepth) {
                    ASSERT_EQ(back.depth(x, y), kBackgroundDepth);
                    ASSERT_EQ(b[3], kBackgroundRgba[3]);
                    continue;
                }
                ASSERT_LT(back.depth(x, y), kBackgroundDepth);
                ASSERT_EQ(b[3], 255);
                double za = eyeZFromWindowDepth(cam, img.depth(x, y));
                double zb = eyeZFromWindowDepth(cam, back.depth(x, y));
                worst = std::max(worst, std::abs(za - zb));
            }
        EXPECT_LE(worst, boundMm) << codecName(codec);
    }
}

TEST(Codec, MalformedPayloadsAreRefusedNotCrashed) {
    Camera cam = testCamera();
    Dbi img = planeImage(cam, 16, 16);
    for (Codec codec : {Codec::Raw, Codec::Lz4, Codec::Zstd}) {
        EncodedImage e = encodeImage(img, codec, cam);
        Dbi out;
        auto truncated = std::span(e.payload.data(), e.payload.size() / 2);
        EXPECT_FALSE(decodeImage(truncated, e.rawBytes, codec, 16, 16, cam, out));
        EXPECT_FALSE(decodeImage(e.payload, e.rawBytes + 5, codec, 16, 16, cam, out));
        EXPECT_FALSE(decodeImage(e.payload, e.rawBytes, codec, 17, 16, cam, out));
        std::vector<uint8_t> junk(e.payload.size(), 0xAB);
        if (codec != Codec::Raw) {
            EXPECT_FALSE(decodeImage(junk, e.rawBytes, codec, 16, 16, cam, out));
        }
    }
    EXPECT_THROW(parseCodec("png"), Error);
    EXPECT_EQ(parseCodec("zstd"), Codec::Zstd);
}

#include "net/codec.h"

#include "libsim/error.h"

#include <gtest/gtest.h>

#include <bit>
#include <cfloat>
#include <cmath>
#include <limits>
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

// What a renderer writes (docs/protocol.md): +0, or a normal float in (0, 1].
bool depthInRange(float d) {
    return std::bit_cast<uint32_t>(d) == 0 || (d >= FLT_MIN && d <= 1.0f);
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

// docs/rendering.md: a depth is +0 or a normal float in (0, 1], the background exactly 1. The raw
// codec is the bit-exact reference for such depths; a raw payload with any other depth is
// malformed, never handed to the compositor.
TEST(Codec, RawDepthsOutsideWhatARendererWritesAreMalformed) {
    Camera cam = testCamera();
    const Dbi img = planeImage(cam, 16, 16);
    const float nan = std::numeric_limits<float>::quiet_NaN();
    const float inf = std::numeric_limits<float>::infinity();
    for (float bad : {-0.0f, -1.1e-16f, -1.0f, 1e-40f, FLT_TRUE_MIN, std::nextafter(1.0f, 2.0f),
                      2.0f, FLT_MAX, inf, -inf, nan, -nan}) {
        SCOPED_TRACE(bad);
        for (int at : {0, 7 * 16 + 3, 16 * 16 - 1}) {
            Dbi tampered = img;
            tampered.depth()[at] = bad;
            const EncodedImage e = encodeImage(tampered, Codec::Raw, cam);
            Dbi out;
            EXPECT_FALSE(decodeImage(e.payload, e.rawBytes, Codec::Raw, 16, 16, cam, out));
        }
    }
    for (float good : {0.0f, FLT_MIN, 1e-17f, 0.5f, std::nextafter(1.0f, 0.0f), 1.0f}) {
        SCOPED_TRACE(good);
        Dbi edge = img;
        edge.depth()[5] = good;
        const EncodedImage e = encodeImage(edge, Codec::Raw, cam);
        Dbi out;
        ASSERT_TRUE(decodeImage(e.payload, e.rawBytes, Codec::Raw, 16, 16, cam, out));
        EXPECT_TRUE(out == edge);
    }
}

// The quantised codecs produce depths in range from any code a peer sends: code 0 (the near plane)
// used to read back as -1.1e-16 for many near/far pairs (down to -3.8e-12).
TEST(Codec, QuantisedDepthsDecodeInRangeFromEveryCode) {
    std::vector<Camera> cameras{testCamera()};
    for (auto [n, f] : {std::pair{0.133290991f, 494.341827f},
                        {0.659874916f, 34705.2461f},
                        {9.79661465f, 1140.96167f},
                        {0.00684238179f, 315.195679f},
                        {0.001f, 1e6f},
                        {999999.9f, 1e6f}}) {
        Camera c = testCamera();
        c.nearMm = n;
        c.farMm = f;
        cameras.push_back(c);
    }
    // Every code once, delta-coded along 256 rows of 256 pixels, as a peer may send them.
    constexpr int kSide = 256;
    const size_t n = size_t(kSide) * kSide;
    std::vector<uint8_t> planar(5 * n, 0x80);
    for (size_t i = 0; i < n; ++i) {
        const uint16_t code = uint16_t(i), prev = i % kSide ? uint16_t(i - 1) : 0;
        const uint16_t delta = uint16_t(code - prev);
        planar[3 * n + i] = uint8_t(delta >> 8);
        planar[4 * n + i] = uint8_t(delta);
    }
    for (const Camera& cam : cameras) {
        SCOPED_TRACE(testing::Message() << "near " << cam.nearMm << " far " << cam.farMm);
        DepthQuantizer q(cam);
        std::vector<uint16_t> codes(65536);
        for (size_t i = 0; i < codes.size(); ++i)
            codes[i] = uint16_t(i);
        std::vector<float> row(codes.size());
        q.dequantizeRow(codes.data(), row.data(), codes.size());
        for (size_t i = 0; i < codes.size(); ++i) {
            ASSERT_TRUE(depthInRange(q.dequantize(codes[i]))) << i << " " << q.dequantize(codes[i]);
            ASSERT_EQ(std::bit_cast<uint32_t>(row[i]),
                      std::bit_cast<uint32_t>(q.dequantize(codes[i])));
        }
        for (Codec codec : {Codec::Lz4, Codec::Zstd}) {
            const std::vector<uint8_t> payload = compressBytes(planar, codec);
            Dbi out;
            ASSERT_TRUE(
                decodeImage(payload, uint32_t(planar.size()), codec, kSide, kSide, cam, out));
            for (size_t i = 0; i < n; ++i)
                ASSERT_TRUE(depthInRange(out.depth()[i])) << codecName(codec) << " code " << i;
        }
    }
}

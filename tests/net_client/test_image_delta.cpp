// The predicted image-update form: what a client reconstructs from its own pixels plus the
// update is exactly what the ordinary quantised codec would have given it, and it is smaller.
#include "libsim/camera.h"
#include "libsim/dirty_rect.h"
#include "libsim/renderer.h"
#include "libsim/skull.h"
#include "net/codec.h"
#include "net/image_delta.h"

#include <gtest/gtest.h>

#include <bit>
#include <cmath>
#include <limits>

#include <random>

using namespace trephine;
using namespace trephine::net;

namespace {

// What a client holds after receiving `image` through an ordinary quantised update.
Dbi throughCodec(const Dbi& image, const Camera& camera) {
    EncodedImage e = encodeImage(image, Codec::Lz4, camera);
    Dbi out;
    EXPECT_TRUE(
        decodeImage(e.payload, e.rawBytes, Codec::Lz4, image.width(), image.height(), camera, out));
    return out;
}

struct Cut {
    Camera camera;
    PixelRect rect;
    Dbi before, after; // the rectangle before and after cutting the box
};

// An n^3 box cut at the bone surface the paper camera looks at, as the study does.
Cut cutAtSurface(int n) {
    Volume v = makeSkull(64);
    v.setSpacing(glm::vec3(paperSpacingMm(64)));
    Cut c;
    c.camera = cameraPreset("paper", v, {200, 200});
    Renderer renderer(v);
    Dbi frame = renderer.render(c.camera);
    Box3i box = surfaceBox(v, n);
    c.rect = dirtyScreenRect(c.camera, v, box);
    c.before = frame.extract(c.rect);
    v.fill(box, 0, Material::Air);
    renderer.volumeChanged(box);
    renderer.render(c.camera, c.rect, frame);
    c.after = frame.extract(c.rect);
    return c;
}

} // namespace

TEST(DepthQuantizer, RoundTripIsIdempotentForEveryCode) {
    // The client recomputes the codes of its unchanged pixels from the depths it decoded; they
    // must be the codes the server used.
    Volume v = makeSkull(64);
    v.setSpacing(glm::vec3(paperSpacingMm(64)));
    for (const char* preset : {"paper", "working"}) {
        DepthQuantizer q(cameraPreset(preset, v, {500, 500}));
        for (uint32_t code = 0; code <= 0xffff; ++code)
            ASSERT_EQ(q.quantize(q.dequantize(uint16_t(code))), code) << preset << " code " << code;
    }
}

TEST(DepthQuantizer, RowFunctionsAreTheOneValueFunctionsBitForBit) {
    Volume v = makeSkull(64);
    v.setSpacing(glm::vec3(paperSpacingMm(64)));
    for (const char* preset : {"paper", "working"}) {
        DepthQuantizer q(cameraPreset(preset, v, {500, 500}));
        // Every code, an odd count so the scalar tail runs too.
        std::vector<uint16_t> codes(0x10000 + 3);
        for (size_t i = 0; i < codes.size(); ++i)
            codes[i] = uint16_t(i * 40503u);
        std::vector<float> depths(codes.size());
        q.dequantizeRow(codes.data(), depths.data(), codes.size());
        for (size_t i = 0; i < codes.size(); ++i)
            ASSERT_EQ(std::bit_cast<uint32_t>(depths[i]),
                      std::bit_cast<uint32_t>(q.dequantize(codes[i])))
                << preset << " code " << codes[i];
        // Depths across [0, 1], the background, values just below it and beyond both ends.
        std::vector<float> in{0.0f, -0.5f, 1.0f, 2.0f, std::nextafter(1.0f, 0.0f), 0.5f, 0.999f};
        for (int i = 0; i <= 200000; ++i)
            in.push_back(float(i) / 200000.0f);
        for (float d = 0.9f; d < 1.0f; d = std::nextafter(d, 1.0f) + 1e-7f)
            in.push_back(d);
        std::vector<uint16_t> out(in.size());
        q.quantizeRow(in.data(), out.data(), in.size());
        for (size_t i = 0; i < in.size(); ++i)
            ASSERT_EQ(out[i], q.quantize(in[i])) << preset << " depth " << in[i];
    }
}

TEST(DepthQuantizer, ADepthThatIsNotANumberIsTheBackground) {
    // A raw image update carries its float depths as sent, so a hostile server's NaN reaches the
    // client's picture, which the predicted form quantises (the base hash) before decoding.
    // Converting NaN to an integer code is undefined behaviour; it quantises as the background.
    Volume v = makeSkull(64);
    v.setSpacing(glm::vec3(paperSpacingMm(64)));
    const Camera camera = cameraPreset("working", v, {4, 2});
    const DepthQuantizer q(camera);
    const float nan = std::numeric_limits<float>::quiet_NaN();
    std::vector<float> in{nan, -nan, 0.5f, nan, 1.0f, nan};
    std::vector<uint16_t> out(in.size());
    q.quantizeRow(in.data(), out.data(), in.size());
    for (size_t i = 0; i < in.size(); ++i) {
        EXPECT_EQ(out[i], q.quantize(in[i])) << "depth " << in[i];
        if (std::isnan(in[i])) {
            EXPECT_EQ(out[i], DepthQuantizer::kBackground) << "depth " << in[i];
        }
    }
    // The way in is closed: a raw update of NaN depths is malformed (docs/protocol.md). A picture
    // holding NaN anyway has a predicted update against it refused (its hash is not the
    // server's) without UB.
    Dbi held(4, 2);
    std::fill(held.depth(), held.depth() + 8, nan);
    EncodedImage e = encodeImage(held, Codec::Raw, camera);
    Dbi decoded;
    EXPECT_FALSE(decodeImage(e.payload, e.rawBytes, Codec::Raw, 4, 2, camera, decoded));
    decoded = held;
    const PredictedImage p = encodePredicted(Dbi(4, 2), held, Codec::Zstd, q);
    EXPECT_EQ(decodePredicted(p.payload, p.rawBytes, Codec::Zstd, p.baseHash ^ 1, q, decoded),
              PredictedStatus::BaseMismatch);
}

TEST(PredictedImage, ReconstructsExactlyWhatTheOrdinaryCodecGivesAndIsSmaller) {
    for (int n : {6, 12}) {
        Cut c = cutAtSurface(n);
        ASSERT_GT(c.rect.w, 0);
        const Dbi clientHas = throughCodec(c.before, c.camera);
        const Dbi expected = throughCodec(c.after, c.camera);
        DepthQuantizer q(c.camera);
        for (Codec codec : {Codec::Lz4, Codec::Zstd}) {
            PredictedImage p = encodePredicted(c.after, c.before, codec, q);
            ASSERT_FALSE(p.payload.empty());
            EXPECT_GT(p.changedPixels, 0);
            EXPECT_LT(p.changedPixels, c.rect.w * c.rect.h); // the rim keeps its pixels
            Dbi image = clientHas;
            ASSERT_EQ(decodePredicted(p.payload, p.rawBytes, codec, p.baseHash, q, image),
                      PredictedStatus::Ok);
            EXPECT_TRUE(image == expected) << compare(image, expected).describe();
            EncodedImage ordinary = encodeImage(c.after, codec, c.camera);
            EXPECT_LT(p.payload.size(), ordinary.payload.size()) << "n=" << n;
        }
    }
}

TEST(PredictedImage, UnchangedRectangleCostsAlmostNothing) {
    Cut c = cutAtSurface(8);
    DepthQuantizer q(c.camera);
    PredictedImage p = encodePredicted(c.after, c.after, Codec::Zstd, q);
    EXPECT_EQ(p.changedPixels, 0);
    EXPECT_LT(p.payload.size(), 40u);
    Dbi image = throughCodec(c.after, c.camera);
    const Dbi copy = image;
    ASSERT_EQ(decodePredicted(p.payload, p.rawBytes, Codec::Zstd, p.baseHash, q, image),
              PredictedStatus::Ok);
    EXPECT_TRUE(image == copy);
}

TEST(PredictedImage, MalformedPayloadsAreRefusedAndLeaveTheImage) {
    Cut c = cutAtSurface(8);
    DepthQuantizer q(c.camera);
    PredictedImage p = encodePredicted(c.after, c.before, Codec::Lz4, q);
    const Dbi original = throughCodec(c.before, c.camera);
    auto refused = [&](std::span<const uint8_t> payload, uint32_t rawBytes, Codec codec) {
        Dbi image = original;
        PredictedStatus st = decodePredicted(payload, rawBytes, codec, p.baseHash, q, image);
        return st == PredictedStatus::Malformed && image == original;
    };
    EXPECT_TRUE(refused(p.payload, p.rawBytes + 5, Codec::Lz4)); // residual count disagrees
    EXPECT_TRUE(refused(p.payload, p.rawBytes - 1, Codec::Lz4)); // not mask + 5 per pixel
    EXPECT_TRUE(refused(p.payload, p.rawBytes, Codec::Raw));     // never predicted
    EXPECT_TRUE(refused(std::span(p.payload).first(p.payload.size() / 2), p.rawBytes,
                        Codec::Lz4)); // truncated
    EXPECT_TRUE(refused({}, 0, Codec::Zstd));
    // A mask whose count of set bits disagrees with the residuals.
    std::vector<uint8_t> raw(p.rawBytes, 0xff);
    std::vector<uint8_t> bogus = compressBytes(raw, Codec::Lz4);
    EXPECT_TRUE(refused(bogus, p.rawBytes, Codec::Lz4));
    std::mt19937 rng(7);
    for (int i = 0; i < 200; ++i) {
        std::vector<uint8_t> junk(size_t(rng() % 300));
        for (auto& b : junk)
            b = uint8_t(rng());
        Dbi image = original;
        (void)decodePredicted(junk, uint32_t(rng() % 20000), Codec(1 + rng() % 2), uint32_t(rng()),
                              q, image);
    }
}

TEST(PredictedImage, AClientWhoseCopyDiffersRefusesInsteadOfShowingAWrongPicture) {
    Cut c = cutAtSurface(8);
    DepthQuantizer q(c.camera);
    PredictedImage p = encodePredicted(c.after, c.before, Codec::Lz4, q);
    EXPECT_EQ(p.baseHash, basePixelHash(c.before, q));
    Dbi image = throughCodec(c.before, c.camera);
    EXPECT_EQ(basePixelHash(image, q), p.baseHash); // the quantised copy hashes the same
    image.color()[4 * 5] ^= 1;                      // one colour bit off
    const Dbi stale = image;
    EXPECT_EQ(decodePredicted(p.payload, p.rawBytes, Codec::Lz4, p.baseHash, q, image),
              PredictedStatus::BaseMismatch);
    EXPECT_TRUE(image == stale);
}

TEST(PredictedImage, PixelsPredictedExactlyStoreNoResiduals) {
    // Bone seen through a hole that now shows background everywhere: every pixel changed, and
    // every one but the first (nothing to predict it from) is predicted exactly, so the update
    // carries the two masks and one pixel's residuals (protocol 5).
    Cut c = cutAtSurface(8);
    const int w = 13, h = 7, n = w * h; // n % 8 != 0: the masks end in padding bits
    const PixelRect rect{0, 0, w, h};
    const Dbi clientHas = throughCodec(c.before, c.camera).extract(rect);
    const Dbi background(w, h);
    DepthQuantizer q(c.camera);
    PredictedImage p = encodePredicted(background, clientHas, Codec::Zstd, q);
    ASSERT_EQ(p.changedPixels, n);
    const uint32_t maskBytes = (n + 7) / 8;
    EXPECT_EQ(p.rawBytes, 2 * maskBytes + 5);
    Dbi image = clientHas;
    ASSERT_EQ(decodePredicted(p.payload, p.rawBytes, Codec::Zstd, p.baseHash, q, image),
              PredictedStatus::Ok);
    EXPECT_TRUE(image == throughCodec(background, c.camera));

    // The same update with a padding bit of the exact mask set, or one exact bit cleared (then
    // the residuals are one pixel short), is refused and leaves the picture.
    std::vector<uint8_t> raw;
    ASSERT_TRUE(decompressBytes(p.payload, Codec::Zstd, p.rawBytes, raw));
    auto refused = [&](std::vector<uint8_t> bytes) {
        std::vector<uint8_t> payload = compressBytes(bytes, Codec::Zstd);
        Dbi copy = clientHas;
        return decodePredicted(payload, uint32_t(bytes.size()), Codec::Zstd, p.baseHash, q, copy) ==
                   PredictedStatus::Malformed &&
               copy == clientHas;
    };
    std::vector<uint8_t> padded = raw;
    padded[2 * maskBytes - 1] |= 0x80;
    EXPECT_TRUE(refused(padded));
    std::vector<uint8_t> short1 = raw;
    short1[maskBytes] &= uint8_t(~0x02u);
    EXPECT_TRUE(refused(short1));
}

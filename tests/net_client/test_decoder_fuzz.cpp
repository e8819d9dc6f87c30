// Hostile and truncated input against every decoder a peer's bytes reach: valid messages and
// payloads of every kind, mutated (truncated at every length, bits flipped, bytes inserted and
// deleted, length and count fields set to 0, to huge and to negative-as-unsigned values, sizes
// that claim far more than the data holds, rectangles and boxes outside the view or the volume),
// must be refused or decode to something in range: never a crash, a hang or undefined behaviour
// (run it under -fsanitize=address,undefined). Valid inputs must still decode. The seeds are fixed
// and the counts bounded; TREPHINE_FUZZ_SCALE=N runs N times as many mutations for a long run.
#include "net/assessment_protocol.h"
#include "net/codec.h"
#include "net/image_delta.h"
#include "net/messages.h"
#include "net/protocol.h"
#include "net/replay_protocol.h"
#include "net/scene.h"
#include "net/view.h"

#include "libsim/camera.h"
#include "libsim/dbi.h"
#include "libsim/volume.h"

#include <gtest/gtest.h>

#include "fuzz.h"
#include <lz4.h>
#include <zstd.h>

#include <algorithm>
#include <bit>
#include <cfloat>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <new>
#include <random>
#include <set>

using namespace trephine;
using namespace trephine::net;

namespace {

using namespace trephine::testing;

// Every truncation, every hostile value at every offset, then `random` random mutations.
template <typename F>
void forEachMutation(const std::vector<uint8_t>& valid, uint32_t seed, int random, F&& f) {
    for (size_t len = 0; len < valid.size(); ++len)
        f(std::vector<uint8_t>(valid.begin(), valid.begin() + std::ptrdiff_t(len)));
    for (size_t at = 0; at < valid.size(); ++at)
        for (size_t width : {1, 2, 4, 8})
            for (uint64_t v : kSpecialValues) {
                std::vector<uint8_t> b = valid;
                writeLittleEndian(b, at, v, width);
                f(std::move(b));
            }
    Mutator m(seed);
    for (int i = 0; i < random; ++i)
        f(m.mutate(valid));
}

// [SECTION] messages

template <typename M>
bool decodesCanonically(std::span<const uint8_t> packet) {
    M m;
    if (!decodeMessage(packet, m))
        return false;
    // What decodes is in range, so it encodes again, to the same bytes (the format has one
    // encoding of every value).
    EXPECT_EQ(encodeMessage(m), std::vector<uint8_t>(packet.begin(), packet.end()))
        << "type " << int(M::kType);
    return true;
}

// Decodes a packet as whatever type its first byte names, as the server and the client do: every
// message of the list (net/messages.h), whoever sends it.
bool decodeAny(std::span<const uint8_t> p) {
    return dispatchAny(
        peekMessageType(p), [&]<typename M>(MessageTag<M>) { return decodesCanonically<M>(p); },
        false);
}

ViewSpec sampleView(uint16_t w, uint16_t h) {
    ViewSpec v;
    v.eye = {10, 20, 300};
    v.target = {1, 2, 3};
    v.up = {0, 1, 0};
    v.fovYDeg = 50;
    v.nearMm = 110;
    v.farMm = 550;
    v.width = w;
    v.height = h;
    return v;
}

ToolState sampleTool() {
    ToolState t;
    t.sequence = 77;
    t.clientTimeUs = 123456789;
    t.toolKind = 1;
    t.diameterMm = 3.5f;
    t.position = {1.5f, -2.0f, 30.0f};
    t.orientation = glm::quat(0.9f, 0.1f, 0.3f, 0.2f);
    t.speed = 0.75f;
    t.drilling = true;
    return t;
}

HapticModel sampleModel() {
    HapticModel h;
    h.toolSequence = 9;
    h.serverReceivedUs = 1000;
    h.serverSentUs = 1200;
    h.clientTimeUs = 900;
    h.position = {1, 2, 3};
    h.force = {0.5f, -0.25f, 2};
    h.gradient = glm::mat3(1.0f) * 0.3f;
    h.contact = true;
    return h;
}

template <typename M>
std::vector<uint8_t> encoded(M m) {
    std::vector<uint8_t> out = encodeMessage(m);
    EXPECT_FALSE(out.empty()) << "type " << int(M::kType);
    return out;
}

// One valid packet of every message type, payloads included.
std::vector<std::vector<uint8_t>> sampleMessages() {
    std::vector<std::vector<uint8_t>> all;
    Hello hello;
    hello.role = Role::Instructor;
    hello.name = "Dr. Fuzz";
    hello.codec = Codec::Zstd;
    hello.sync = Sync::Volume;
    hello.volumeCodec = Codec::Lz4;
    hello.view = sampleView(640, 480);
    all.push_back(encoded(hello));
    Welcome welcome;
    welcome.clientId = 3;
    welcome.serverTimeUs = 42;
    welcome.volumeDims = {9, 7, 5};
    welcome.spacing = {0.5f, 0.5f, 0.75f};
    welcome.volumeName = "skull";
    welcome.maxViewPixels = 1024 * 1024;
    all.push_back(encoded(welcome));
    all.push_back(encoded(ViewRequest{5, sampleView(300, 200)}));
    all.push_back(encoded(sampleTool()));
    all.push_back(encoded(ToolRelay{4, sampleTool()}));
    all.push_back(encoded(sampleModel()));
    ImageUpdate image;
    image.sequence = 11;
    image.viewId = 2;
    image.fullSequence = 9;
    image.x = 3;
    image.y = 4;
    image.width = 5;
    image.height = 6;
    image.codec = Codec::Lz4;
    image.erodeUs = 1;
    image.renderUs = 4;
    image.gridUs = 2;
    image.predicted = true;
    image.baseHash = 0xdeadbeef;
    image.payload = compressBytes(std::vector<uint8_t>(40, 7), Codec::Lz4);
    image.rawBytes = 40;
    all.push_back(encoded(image));
    VolumeUpdate volume;
    volume.sequence = 12;
    volume.x = 1;
    volume.y = 2;
    volume.z = 3;
    volume.sizeX = 2;
    volume.sizeY = 3;
    volume.sizeZ = 1;
    volume.materials = true;
    volume.codec = Codec::Zstd;
    volume.rawBytes = 12;
    volume.payload = compressBytes(std::vector<uint8_t>(12, 1), Codec::Zstd);
    all.push_back(encoded(volume));
    all.push_back(encoded(Ping{99}));
    all.push_back(encoded(Pong{99, 100}));
    Participants roster;
    roster.list = {{1, Role::Instructor, Sync::Dbi, "a", 0},
                   {2, Role::Trainee, Sync::Volume, "bee", 1},
                   {7, Role::Trainee, Sync::Dbi, "", 0}};
    all.push_back(encoded(roster));
    all.push_back(encoded(SyncMode{Sync::Volume, Codec::Zstd}));
    all.push_back(encoded(HapticRelay{6, sampleModel()}));
    all.push_back(encoded(Annotate{Annotate::Op::Add, 0, {1, 2, 3}, "here"}));
    Annotations marks;
    marks.list = {{1, 2, {0, 0, 0}, "one"}, {5, 2, {-1, 4, 9}, "five"}};
    all.push_back(encoded(marks));
    all.push_back(encoded(TakeOver{2}));
    // A small scene (a triangle for a field), so that every byte's mutations stay quick.
    Scene scene;
    scene.dims = {9, 7, 5};
    scene.spacing = {0.5f, 0.5f, 0.75f};
    scene.extentMm = glm::vec3(scene.dims) * scene.spacing;
    const ViewSpec v = sampleView(1, 1);
    scene.presets = {{"top", v.eye, v.target, v.up, v.fovYDeg, v.nearMm, v.farMm}};
    scene.sites = {{"burr", {1, 2, 3}, {0, 0, 1}}};
    scene.landmarks = {{"a", {0, 0, 1}}, {"b", {0, 1, 0}}};
    MeshData tri;
    tri.vertices = {{{0, 0, 0}, {0, 0, 1}, {1, 0, 0, 1}},
                    {{1, 0, 0}, {0, 0, 1}, {0, 1, 0, 1}},
                    {{0, 1, 0}, {0, 0, 1}, {0, 0, 1, 1}}};
    tri.indices = {0, 1, 2};
    setSceneMesh(scene, tri);
    stampScene(scene);
    all.push_back(encoded(scene));
    all.push_back(encoded(ViewAs{3}));
    all.push_back(encoded(ParticipantView{3, sampleView(64, 48)}));
    // The handshake: each of its steps (the first messages a stranger's bytes reach).
    Handshake challenge;
    challenge.step = Handshake::Step::Challenge;
    challenge.salt.fill(0x5a);
    all.push_back(encoded(challenge));
    Handshake offer;
    offer.step = Handshake::Step::Offer;
    offer.role = Role::Instructor;
    offer.share.fill(0x11);
    all.push_back(encoded(offer));
    Handshake answer;
    answer.step = Handshake::Step::Answer;
    answer.entries.resize(2);
    answer.entries[0].role = Role::Instructor;
    answer.entries[0].share.fill(0x22);
    answer.entries[0].mac.fill(0x33);
    answer.entries[1].share.fill(0x44);
    answer.entries[1].mac.fill(0x55);
    all.push_back(encoded(answer));
    Handshake confirm;
    confirm.step = Handshake::Step::Confirm;
    confirm.entry = 1;
    confirm.mac.fill(0x66);
    all.push_back(encoded(confirm));
    all.push_back(encoded(Remove{Remove::Op::Remove, 4}));
    // Codes both ways: an instructor's request, and the codes the server sends instructors.
    Codes request;
    request.op = Codes::Op::Issue;
    request.role = Role::Instructor;
    all.push_back(encoded(request));
    Codes current;
    current.trainee = "QX7M-4KTD";
    current.instructor = "HW2R-9PZE";
    all.push_back(encoded(current));
    all.push_back(encoded(HandLinks{{{2, 5, false}, {3, 0, true}}}));
    all.push_back(encoded(ImageAck{4, 77}));
    all.push_back(encoded(ViewRefused{5, 250000}));
    all.push_back(encoded(SafetyWarning{4, Zone::Danger, Zone::Caution, "sinus", 0.8f, 17, 99}));
    AssessmentSnapshot snapshot;
    snapshot.serverTimeUs = 5;
    ParticipantFigures f;
    f.clientId = 4;
    f.zone = Zone::Caution;
    f.sessionS = 12.5f;
    f.zoneS = {1, 2, 3, 0};
    f.removed = {{uint8_t(Material::Cortical), 40.0f}, {uint8_t(Material::Diploe), 12.0f}};
    f.structures = {{"dura", 2.5f, 4.0f, 1}, {"sinus", 0.5f, 6.0f, 0}};
    f.tools = {{"burr 4 mm", 9.0f}};
    snapshot.list = {f};
    all.push_back(encoded(snapshot));
    all.push_back(encoded(ReplayState{1'500'000, 60'000'000, 2.0f, true, 3}));
    all.push_back(encoded(ReplayControl{ReplayControl::Op::Seek, 30'000'000, 1.0f}));
    return all;
}

// [SECTION] image payloads

// A DBI of a tilted plane as `camera` sees it, with a hole of background pixels.
Dbi planeImage(const Camera& camera, int w, int h, uint32_t seed) {
    Dbi img(w, h);
    const glm::dmat4 vp = viewProjection(camera);
    std::mt19937 rng(seed);
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
            if ((x - w / 3) * (x - w / 3) + (y - h / 2) * (y - h / 2) < 6)
                continue; // background
            const glm::dvec3 p(x - w / 2.0, y - h / 2.0, 0.3 * x - 0.2 * y + 0.01 * (rng() % 8));
            img.depth()[img.index(x, y)] = windowDepth(vp, p);
            uint8_t* c = img.color(x, y);
            c[0] = uint8_t(200 + x % 50);
            c[1] = uint8_t(100 + (rng() % 4));
            c[2] = uint8_t(y * 3);
            c[3] = 255;
        }
    return img;
}

// Depths in range (docs/protocol.md): +0 or a normal float in (0, 1] at every pixel.
bool depthsInRange(const Dbi& image) {
    const float* d = image.depth();
    for (size_t i = 0; i < size_t(image.width()) * size_t(image.height()); ++i)
        if (!(std::bit_cast<uint32_t>(d[i]) == 0 || (d[i] >= FLT_MIN && d[i] <= 1.0f)))
            return false;
    return true;
}

Camera imageCamera(int w, int h) {
    Camera c = toCamera(sampleView(uint16_t(w), uint16_t(h)));
    c.eye = {0, 0, 300};
    c.target = {0, 0, 0};
    return c;
}

constexpr int kImageW = 13, kImageH = 9; // odd sizes: partial mask bytes, scalar tails

// Hostile rectangle sizes (the decoder takes int width and height).
constexpr int kHostileSizes[] = {0,    -1,   1,     kImageW - 1, kImageW + 1, kImageH,
                                 4096, 4097, 65535, INT32_MIN,   INT32_MAX};

// Hostile raw-byte counts for a payload that should be `valid` bytes before compression.
std::vector<uint32_t> hostileRawBytes(uint32_t valid) {
    return {0,
            1,
            valid - 1,
            valid + 1,
            valid * 2,
            uint32_t(kMaxPayloadBytes),
            kMaxVolumeRawBytes,
            kMaxVolumeRawBytes + 1,
            0x7fffffff,
            0x80000000,
            0xffffffff};
}

} // namespace

TEST(DecoderFuzz, EveryMessageTypeRefusesMutationsOrDecodesThemInRange) {
    const std::vector<std::vector<uint8_t>> samples = sampleMessages();
    // One of every type (the handshake's four steps each, both of Codes' ops).
    constexpr size_t kHandshakeSteps = 4, kCodesOps = 2;
    std::set<uint8_t> types;
    for (const std::vector<uint8_t>& s : samples)
        types.insert(s[0]);
    ASSERT_EQ(types.size(), kMessages.size()) << "a sample of every message of the list";
    ASSERT_EQ(samples.size(), types.size() + (kHandshakeSteps - 1) + (kCodesOps - 1));
    const int random = 1500 * fuzzScale();
    size_t mutated = 0, decoded = 0;
    for (size_t s = 0; s < samples.size(); ++s) {
        ASSERT_TRUE(decodeAny(samples[s])) << "valid sample of type " << int(samples[s][0]);
        forEachMutation(samples[s], uint32_t(1000 + s), random, [&](std::vector<uint8_t> b) {
            ++mutated;
            decoded += decodeAny(b) ? 1 : 0;
        });
    }
    // Most mutations must be refused: a decoder that accepts anything would pass the rest.
    EXPECT_LT(decoded, mutated / 2) << decoded << " of " << mutated << " mutations decoded";
}

TEST(DecoderFuzz, ImagePayloadsRefuseMutationsAndHostileSizes) {
    const Camera camera = imageCamera(kImageW, kImageH);
    const Dbi image = planeImage(camera, kImageW, kImageH, 5);
    const int random = 2000 * fuzzScale();
    for (Codec codec : {Codec::Raw, Codec::Lz4, Codec::Zstd}) {
        SCOPED_TRACE(codecName(codec));
        const EncodedImage e = encodeImage(image, codec, camera);
        Dbi expected;
        ASSERT_TRUE(decodeImage(e.payload, e.rawBytes, codec, kImageW, kImageH, camera, expected));
        for (int w : kHostileSizes)
            for (int h : kHostileSizes)
                for (uint32_t raw : hostileRawBytes(e.rawBytes)) {
                    Dbi out;
                    if (decodeImage(e.payload, raw, codec, w, h, camera, out)) {
                        // Only an honest size can decode, to a picture of that size.
                        EXPECT_EQ(out.width(), w);
                        EXPECT_EQ(out.height(), h);
                        EXPECT_EQ(raw, e.rawBytes);
                    }
                }
        // Another codec's payload under this codec's name.
        for (Codec other : {Codec::Raw, Codec::Lz4, Codec::Zstd}) {
            const EncodedImage o = encodeImage(image, other, camera);
            Dbi out;
            if (other != codec) {
                EXPECT_FALSE(
                    decodeImage(o.payload, e.rawBytes, codec, kImageW, kImageH, camera, out));
            }
        }
        forEachMutation(e.payload, 20 + uint32_t(codec), random, [&](std::vector<uint8_t> b) {
            Dbi out;
            if (decodeImage(b, e.rawBytes, codec, kImageW, kImageH, camera, out)) {
                EXPECT_EQ(out.width(), kImageW);
                EXPECT_EQ(out.height(), kImageH);
                EXPECT_TRUE(depthsInRange(out));
            }
        });
        // A raw depth a renderer never writes, at every pixel in turn: refused.
        if (codec == Codec::Raw) {
            for (uint32_t bits : {0x80000000u, 0x00000001u, 0x007fffffu, 0x3f800001u, 0x7f800000u,
                                  0x7fc00000u, 0xffc00000u, 0xbf800000u}) {
                for (size_t i = 0; i < size_t(kImageW) * kImageH; ++i) {
                    std::vector<uint8_t> b = e.payload;
                    writeLittleEndian(b, size_t(kImageW) * kImageH * 4 + 4 * i, bits, 4);
                    Dbi out;
                    EXPECT_FALSE(decodeImage(b, e.rawBytes, codec, kImageW, kImageH, camera, out))
                        << std::hex << bits << " at pixel " << std::dec << i;
                }
            }
        }
    }
}

TEST(DecoderFuzz, PredictedPayloadsRefuseMutationsAndLeaveTheImageAlone) {
    const Camera camera = imageCamera(kImageW, kImageH);
    const DepthQuantizer quantizer(camera);
    // What the client holds (through the planar codec, as a client would) and the picture now.
    Dbi base;
    const Dbi before = planeImage(camera, kImageW, kImageH, 5);
    const EncodedImage held = encodeImage(before, Codec::Lz4, camera);
    ASSERT_TRUE(
        decodeImage(held.payload, held.rawBytes, Codec::Lz4, kImageW, kImageH, camera, base));
    Dbi next = planeImage(camera, kImageW, kImageH, 6);
    for (int y = 2; y < 5; ++y)
        for (int x = 6; x < 10; ++x) {
            next.depth()[next.index(x, y)] = kBackgroundDepth;
            std::copy(kBackgroundRgba, kBackgroundRgba + 4, next.color(x, y));
        }
    const int random = 2000 * fuzzScale();
    for (Codec codec : {Codec::Lz4, Codec::Zstd}) {
        SCOPED_TRACE(codecName(codec));
        const PredictedImage p = encodePredicted(next, base, codec, quantizer);
        ASSERT_GT(p.changedPixels, 0);
        Dbi expected = base;
        ASSERT_EQ(decodePredicted(p.payload, p.rawBytes, codec, p.baseHash, quantizer, expected),
                  PredictedStatus::Ok);
        auto tryDecode = [&](std::span<const uint8_t> payload, uint32_t raw, Codec c, uint32_t hash,
                             const Dbi& held) {
            Dbi image = held;
            const PredictedStatus st = decodePredicted(payload, raw, c, hash, quantizer, image);
            if (st != PredictedStatus::Ok) {
                EXPECT_TRUE(image == held) << "a refused update changed the pixels";
            } else {
                EXPECT_TRUE(depthsInRange(image));
            }
            return st;
        };
        for (uint32_t raw : hostileRawBytes(p.rawBytes))
            for (Codec c : {Codec::Raw, Codec::Lz4, Codec::Zstd})
                if (raw != p.rawBytes || c != codec) {
                    EXPECT_NE(tryDecode(p.payload, raw, c, p.baseHash, base), PredictedStatus::Ok);
                }
        // Another base: the hash check refuses it.
        EXPECT_EQ(tryDecode(p.payload, p.rawBytes, codec, p.baseHash ^ 1, base),
                  PredictedStatus::BaseMismatch);
        EXPECT_EQ(tryDecode(p.payload, p.rawBytes, codec, p.baseHash, next),
                  PredictedStatus::BaseMismatch);
        // A rectangle of another size than the update's, and one that is empty.
        for (int w : {1, kImageW - 1, kImageW + 1})
            tryDecode(p.payload, p.rawBytes, codec, p.baseHash, planeImage(camera, w, kImageH, 7));
        EXPECT_EQ(tryDecode(p.payload, p.rawBytes, codec, p.baseHash, Dbi()),
                  PredictedStatus::Malformed);
        // The raw layout itself mutated (masks, counts, residuals), then compressed properly,
        // and the compressed payload mutated.
        std::vector<uint8_t> raw;
        ASSERT_TRUE(decompressBytes(p.payload, codec, p.rawBytes, raw));
        forEachMutation(raw, 40 + uint32_t(codec), random, [&](std::vector<uint8_t> b) {
            const std::vector<uint8_t> c = compressBytes(b, codec);
            tryDecode(c, uint32_t(b.size()), codec, p.baseHash, base);
        });
        forEachMutation(p.payload, 50 + uint32_t(codec), random, [&](std::vector<uint8_t> b) {
            tryDecode(b, p.rawBytes, codec, p.baseHash, base);
        });
    }
}

// [SECTION] volume payloads

namespace {

Volume sampleVolume(glm::ivec3 dims) {
    Volume v(dims, glm::vec3(0.5f));
    uint8_t* d = v.densityData();
    uint8_t* m = v.materialData();
    for (size_t i = 0; i < v.voxelCount(); ++i) {
        d[i] = uint8_t(i % 7 == 0 ? 0 : 40 + i % 200);
        m[i] = uint8_t(d[i] == 0 ? 0 : 1 + i % (kMaterialCount - 1));
    }
    return v;
}

// What the client does with a VolumeUpdate packet (SessionClient::applyVolume, without the
// renderer): decode, check the box against the welcome's dims, decompress, write the voxels.
bool applyLikeClient(std::span<const uint8_t> packet, Volume& volume) {
    VolumeUpdate u;
    if (!decodeMessage(packet, u))
        return false;
    const glm::ivec3 dims = volume.dims();
    const Box3i box{{u.x, u.y, u.z}, {u.x + u.sizeX, u.y + u.sizeY, u.z + u.sizeZ}};
    if (box.hi.x > dims.x || box.hi.y > dims.y || box.hi.z > dims.z)
        return false;
    if (u.full) {
        if (!(box == Box3i{glm::ivec3(0), dims}))
            return false;
        Volume v;
        if (!decodeVolumeFull(u.payload, u.rawBytes, u.codec, dims, volume.spacing(), v))
            return false;
        EXPECT_EQ(v.dims(), dims);
        volume = std::move(v);
        return true;
    }
    std::vector<uint8_t> voxels;
    if (!decompressBytes(u.payload, u.codec, u.rawBytes, voxels))
        return false;
    EXPECT_EQ(voxels.size(), size_t(u.rawBytes));
    const size_t n = size_t(box.count());
    std::span<const uint8_t> densities(voxels.data(), n), materials;
    if (u.materials)
        materials = std::span<const uint8_t>(voxels.data() + n, n);
    return applyVolumeBox(volume, box, densities, materials);
}

VolumeUpdate volumeMessage(const EncodedVolume& e, const Box3i& box, bool full, bool materials) {
    VolumeUpdate u;
    u.sequence = 3;
    u.full = full;
    u.materials = materials;
    u.x = uint16_t(box.lo.x);
    u.y = uint16_t(box.lo.y);
    u.z = uint16_t(box.lo.z);
    u.sizeX = uint16_t(box.size().x);
    u.sizeY = uint16_t(box.size().y);
    u.sizeZ = uint16_t(box.size().z);
    u.codec = e.codec;
    u.rawBytes = e.rawBytes;
    u.payload = e.payload;
    return u;
}

} // namespace

TEST(DecoderFuzz, VolumeUpdatesRefuseMutationsAndNeverWriteOutsideTheVolume) {
    const glm::ivec3 dims{9, 7, 5};
    const Volume server = sampleVolume(dims);
    const Box3i box{{2, 1, 0}, {7, 5, 4}};
    std::vector<std::vector<uint8_t>> packets;
    for (Codec codec : {Codec::Raw, Codec::Lz4, Codec::Zstd}) {
        for (bool materials : {false, true})
            packets.push_back(encoded(volumeMessage(encodeVolumeBox(server, box, codec, materials),
                                                    box, false, materials)));
        if (codec != Codec::Raw)
            packets.push_back(encoded(volumeMessage(encodeVolumeFull(server, codec),
                                                    Box3i{glm::ivec3(0), dims}, true, true)));
    }
    const int random = 1500 * fuzzScale();
    for (size_t i = 0; i < packets.size(); ++i) {
        SCOPED_TRACE(i);
        ASSERT_FALSE(packets[i].empty());
        Volume client(dims, server.spacing());
        ASSERT_TRUE(applyLikeClient(packets[i], client));
        forEachMutation(packets[i], 60 + uint32_t(i), random, [&](std::vector<uint8_t> b) {
            Volume v(dims, server.spacing());
            applyLikeClient(b, v);
            EXPECT_EQ(v.dims(), dims);
        });
    }
}

TEST(DecoderFuzz, VolumeDecodersRefuseHostileSizesAndLabels) {
    const glm::ivec3 dims{9, 7, 5};
    const Volume server = sampleVolume(dims);
    for (Codec codec : {Codec::Lz4, Codec::Zstd}) {
        SCOPED_TRACE(codecName(codec));
        const EncodedVolume full = encodeVolumeFull(server, codec);
        Volume v;
        ASSERT_TRUE(
            decodeVolumeFull(full.payload, full.rawBytes, codec, dims, server.spacing(), v));
        EXPECT_TRUE(v == server);
        for (glm::ivec3 d : {glm::ivec3(0, 7, 5), glm::ivec3(-9, -7, 5), glm::ivec3(9, 7, 4),
                             glm::ivec3(4097, 1, 1), glm::ivec3(INT32_MIN, INT32_MIN, 1),
                             glm::ivec3(4096, 4096, 4096), glm::ivec3(5, 7, 9)})
            for (uint32_t raw : hostileRawBytes(full.rawBytes)) {
                Volume out;
                if (decodeVolumeFull(full.payload, raw, codec, d, server.spacing(), out)) {
                    EXPECT_EQ(out.voxelCount() * 2, size_t(raw));
                }
            }
        for (uint32_t raw : hostileRawBytes(full.rawBytes)) {
            std::vector<uint8_t> out;
            EXPECT_FALSE(decompressBytes(full.payload, codec, raw, out));
            EXPECT_FALSE(decompressBytes({}, codec, raw, out));
        }
        // An unknown material label in an otherwise valid full volume.
        std::vector<uint8_t> raw;
        ASSERT_TRUE(decompressBytes(full.payload, codec, full.rawBytes, raw));
        raw.back() = uint8_t(kMaterialCount);
        EXPECT_FALSE(decodeVolumeFull(compressBytes(raw, codec), full.rawBytes, codec, dims,
                                      server.spacing(), v));
    }
    // Boxes partly or wholly outside the volume, empty or inverted, and sizes that disagree (the
    // client builds boxes from u16 origins and sizes, so their corners stay far from overflow).
    Volume v = server;
    const std::vector<uint8_t> bytes(9 * 7 * 5 * 2, 1);
    for (Box3i b :
         {Box3i{{-1, 0, 0}, {2, 2, 2}}, Box3i{{8, 6, 4}, {10, 7, 5}}, Box3i{{0, 0, 0}, {0, 5, 5}},
          Box3i{{5, 5, 5}, {2, 2, 2}}, Box3i{{0, 0, 0}, {4096, 1, 1}}, Box3i{}})
        EXPECT_FALSE(applyVolumeBox(v, b, std::span(bytes.data(), size_t(b.count() > 0 ? 1 : 0))));
    const Box3i b{{1, 1, 1}, {3, 3, 3}};
    EXPECT_FALSE(applyVolumeBox(v, b, std::span(bytes.data(), 7)));
    EXPECT_FALSE(applyVolumeBox(v, b, std::span(bytes.data(), 8), std::span(bytes.data(), 7)));
    const std::vector<uint8_t> labels(8, uint8_t(kMaterialCount));
    EXPECT_FALSE(applyVolumeBox(v, b, std::span(bytes.data(), 8), labels));
    EXPECT_TRUE(v == server) << "a refused box changed the volume";
}

// [SECTION] size claims

TREPHINE_FUZZ_ALLOCATION_PROBE()

TEST(DecoderFuzz, ASizeClaimBeyondWhatThePayloadCanHoldIsRefusedBeforeAllocatingIt) {
    // A few bytes claiming a 2048 x 2048 picture (20 MiB before compression), a 512^3 volume
    // (256 MiB) or a 64 MiB predicted layout: refused without allocating what they claim.
    const Camera camera = imageCamera(2048, 2048);
    Dbi held(2048, 2048);
    for (Codec codec : {Codec::Lz4, Codec::Zstd}) {
        SCOPED_TRACE(codecName(codec));
        const std::vector<uint8_t> tiny = compressBytes(std::vector<uint8_t>(64, 0), codec);
        AllocationProbe probe;
        Dbi out;
        EXPECT_FALSE(decodeImage(tiny, 5 * 2048 * 2048, codec, 2048, 2048, camera, out));
        std::vector<uint8_t> bytes;
        EXPECT_FALSE(decompressBytes(tiny, codec, kMaxVolumeRawBytes, bytes));
        Volume v;
        EXPECT_FALSE(
            decodeVolumeFull(tiny, kMaxVolumeRawBytes, codec, glm::ivec3(512), glm::vec3(0.5f), v));
        EXPECT_EQ(decodePredicted(tiny, uint32_t(kMaxPayloadBytes), codec, 0,
                                  DepthQuantizer(camera), held),
                  PredictedStatus::Malformed);
        EXPECT_LT(probe.largest(), size_t(1) << 20);
    }
    // The bound leaves room for the most compressible honest payloads: a picture of background
    // only, and a volume of air.
    const Dbi background(1024, 1024);
    for (Codec codec : {Codec::Lz4, Codec::Zstd}) {
        SCOPED_TRACE(codecName(codec));
        const Camera c = imageCamera(1024, 1024);
        const EncodedImage e = encodeImage(background, codec, c);
        Dbi out;
        EXPECT_TRUE(decodeImage(e.payload, e.rawBytes, codec, 1024, 1024, c, out));
        EXPECT_TRUE(out == background);
        const std::vector<uint8_t> air(size_t(16) << 20, 0);
        std::vector<uint8_t> bytes;
        EXPECT_TRUE(decompressBytes(compressBytes(air, codec), codec, air.size(), bytes));
        EXPECT_TRUE(bytes == air);
    }
}

namespace {

// A complete zstd frame whose header states `claimed` bytes of content but whose blocks hold only
// `real` bytes (2 bits of randomness a byte), then a last empty raw block: structurally whole, its
// header and the claim agree, and only decoding finds out that it lies.
std::vector<uint8_t> lyingZstdFrame(size_t claimed, size_t real) {
    std::vector<uint8_t> src(real);
    std::mt19937 rng(9);
    for (uint8_t& b : src)
        b = uint8_t(rng() & 3);
    ZSTD_CCtx* c = ZSTD_createCCtx();
    ZSTD_CCtx_setParameter(c, ZSTD_c_compressionLevel, 1);
    ZSTD_CCtx_setPledgedSrcSize(c, claimed);
    std::vector<uint8_t> out(ZSTD_compressBound(real) + 64);
    ZSTD_inBuffer in{src.data(), src.size(), 0};
    ZSTD_outBuffer o{out.data(), out.size(), 0};
    const size_t left = ZSTD_compressStream2(c, &o, &in, ZSTD_e_flush);
    ZSTD_freeCCtx(c);
    EXPECT_FALSE(ZSTD_isError(left));
    out.resize(o.pos);
    for (uint8_t b : {0x01, 0x00, 0x00}) // last block, raw, 0 bytes
        out.push_back(b);
    EXPECT_EQ(ZSTD_findFrameCompressedSize(out.data(), out.size()), out.size());
    EXPECT_EQ(ZSTD_getFrameContentSize(out.data(), out.size()), uint64_t(claimed));
    return out;
}

// Every decoder a zstd or lz4 payload reaches, with a claim of `raw` bytes (the image and volume
// decoders when the claim is their size).
bool anyDecodes(std::span<const uint8_t> payload, Codec codec, uint32_t raw) {
    std::vector<uint8_t> bytes;
    bool ok = decompressBytes(payload, codec, raw, bytes);
    if (raw % 5 == 0) {
        const int side = int(std::sqrt(double(raw / 5)));
        if (size_t(side) * side * 5 == raw) {
            Dbi out;
            ok |= decodeImage(payload, raw, codec, side, side, imageCamera(side, side), out);
        }
    }
    return ok;
}

} // namespace

// The zstd bound of 32768 times the payload let an 8 KiB frame claim 256 MiB and the receiver
// allocate all of it before finding out (measured: 268435456 bytes). A frame must now state its
// content size, equal to the claim, and beyond 1 MiB the output buffer grows only as real output
// arrives: a lying frame costs at most 1 MiB. lz4 is allocated once its sequences add up to the
// claim.
TEST(DecoderFuzz, AClaimThePayloadDoesNotReallyHoldCostsAtMostAMebibyte) {
    const std::vector<uint8_t> lying = lyingZstdFrame(kMaxVolumeRawBytes, 32 * 1024);
    EXPECT_LE(lying.size(), size_t(16 * 1024));
    const std::vector<uint8_t> lyingImage = lyingZstdFrame(5 * 2048 * 2048, 32 * 1024);
    const std::vector<uint8_t> lyingPredicted = lyingZstdFrame(kMaxPayloadBytes, 32 * 1024);
    // lz4: a megabyte of noise, and valid sequences that decode to less than claimed.
    std::vector<uint8_t> noise(size_t(1) << 20);
    std::mt19937 rng(4);
    for (uint8_t& b : noise)
        b = uint8_t(rng());
    const std::vector<uint8_t> shortLz4 =
        compressBytes(std::vector<uint8_t>(3 << 20, 7), Codec::Lz4);
    const Camera camera = imageCamera(2048, 2048);
    Dbi held(2048, 2048);
    {
        AllocationProbe probe;
        std::vector<uint8_t> bytes;
        EXPECT_FALSE(decompressBytes(lying, Codec::Zstd, kMaxVolumeRawBytes, bytes));
        Volume v;
        EXPECT_FALSE(decodeVolumeFull(lying, kMaxVolumeRawBytes, Codec::Zstd, glm::ivec3(512),
                                      glm::vec3(0.5f), v));
        Dbi out;
        EXPECT_FALSE(
            decodeImage(lyingImage, 5 * 2048 * 2048, Codec::Zstd, 2048, 2048, camera, out));
        EXPECT_EQ(decodePredicted(lyingPredicted, uint32_t(kMaxPayloadBytes), Codec::Zstd, 0,
                                  DepthQuantizer(camera), held),
                  PredictedStatus::Malformed);
        EXPECT_FALSE(decompressBytes(noise, Codec::Lz4, 255u << 20, bytes));
        EXPECT_FALSE(decompressBytes(shortLz4, Codec::Lz4, 255u << 20, bytes));
        EXPECT_FALSE(decompressBytes(shortLz4, Codec::Lz4, (3u << 20) + 1, bytes));
        EXPECT_FALSE(decodeImage(noise, 5 * 2048 * 2048, Codec::Lz4, 2048, 2048, camera, out));
        EXPECT_LE(probe.largest(), size_t(1) << 20);
    }
    // Honest payloads of every size still decode, through the growing buffer too (1, 8, then
    // 20 MiB), and so do claims within a mebibyte.
    for (size_t size :
         {size_t(1), size_t(1000), size_t(1) << 20, (size_t(1) << 20) + 1, size_t(20) << 20}) {
        std::vector<uint8_t> data(size);
        for (size_t i = 0; i < size; ++i)
            data[i] = uint8_t(i * 2654435761u >> 13 & (i % 3 ? 0xff : 0x0f));
        for (Codec codec : {Codec::Lz4, Codec::Zstd}) {
            SCOPED_TRACE(::testing::Message() << codecName(codec) << " " << size);
            const std::vector<uint8_t> payload = compressBytes(data, codec);
            std::vector<uint8_t> bytes;
            ASSERT_TRUE(decompressBytes(payload, codec, size, bytes));
            EXPECT_TRUE(bytes == data);
            EXPECT_FALSE(decompressBytes(payload, codec, size + 1, bytes));
            EXPECT_FALSE(decompressBytes(payload, codec, size - 1, bytes));
        }
    }
}

// Our encoder writes the content size in the (one) frame it makes; other frames are malformed:
// no content size, another content size, two frames, bytes after the frame, a skippable frame
// first, a window over 1 MiB.
TEST(DecoderFuzz, ZstdPayloadsAreOneFrameThatStatesItsContentSize) {
    for (size_t size : {size_t(1), size_t(777), size_t(300000), size_t(3) << 20}) {
        SCOPED_TRACE(size);
        std::vector<uint8_t> data(size);
        for (size_t i = 0; i < size; ++i)
            data[i] = uint8_t(i % 251 < 40 ? i : 0);
        const std::vector<uint8_t> ours = compressBytes(data, Codec::Zstd);
        EXPECT_EQ(ZSTD_getFrameContentSize(ours.data(), ours.size()), uint64_t(size));
        EXPECT_EQ(ZSTD_findFrameCompressedSize(ours.data(), ours.size()), ours.size());
        const uint32_t raw = uint32_t(size);
        std::vector<uint8_t> bytes;
        ASSERT_TRUE(decompressBytes(ours, Codec::Zstd, raw, bytes));

        auto compressWith = [&](auto&& configure, std::span<const uint8_t> src) {
            ZSTD_CCtx* c = ZSTD_createCCtx();
            ZSTD_CCtx_setParameter(c, ZSTD_c_compressionLevel, 1);
            configure(c);
            std::vector<uint8_t> out(ZSTD_compressBound(src.size()));
            const size_t n = ZSTD_compress2(c, out.data(), out.size(), src.data(), src.size());
            ZSTD_freeCCtx(c);
            EXPECT_FALSE(ZSTD_isError(n));
            out.resize(n);
            return out;
        };
        const std::vector<uint8_t> noSize = compressWith(
            [](ZSTD_CCtx* c) { ZSTD_CCtx_setParameter(c, ZSTD_c_contentSizeFlag, 0); }, data);
        EXPECT_EQ(ZSTD_getFrameContentSize(noSize.data(), noSize.size()), ZSTD_CONTENTSIZE_UNKNOWN);
        EXPECT_FALSE(anyDecodes(noSize, Codec::Zstd, raw));
        // Two frames of half the bytes each: ZSTD_decompress would join them.
        std::vector<uint8_t> two = compressBytes(std::span(data).first(size / 2), Codec::Zstd);
        const std::vector<uint8_t> second =
            compressBytes(std::span(data).subspan(size / 2), Codec::Zstd);
        two.insert(two.end(), second.begin(), second.end());
        EXPECT_FALSE(anyDecodes(two, Codec::Zstd, raw));
        std::vector<uint8_t> trailing = ours;
        trailing.push_back(0);
        EXPECT_FALSE(anyDecodes(trailing, Codec::Zstd, raw));
        std::vector<uint8_t> skippable{0x50, 0x2a, 0x4d, 0x18, 0, 0, 0, 0};
        skippable.insert(skippable.end(), ours.begin(), ours.end());
        EXPECT_FALSE(anyDecodes(skippable, Codec::Zstd, raw));
        // A 2^24 window (what level 1 never asks): the stream decoder would allocate it.
        if (size > (size_t(1) << 20)) {
            const std::vector<uint8_t> wide = compressWith(
                [](ZSTD_CCtx* c) {
                    ZSTD_CCtx_setParameter(c, ZSTD_c_windowLog, 24);
                    ZSTD_CCtx_setParameter(c, ZSTD_c_compressionLevel, 19);
                },
                data);
            EXPECT_FALSE(anyDecodes(wide, Codec::Zstd, raw));
        }
    }
}

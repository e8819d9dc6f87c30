#include "net/protocol.h"
#include "net/tool_model.h"

#include <gtest/gtest.h>

#include <cstring>
#include <random>

using namespace trephine;
using namespace trephine::net;

TEST(Protocol, MessagesRoundTrip) {
    Hello h;
    h.role = Role::Instructor;
    h.name = "Dr. Ada";
    h.codec = Codec::Zstd;
    h.view.eye = {1, 2, 3};
    h.view.width = 640;
    auto bytes = encodeMessage(h);
    ASSERT_FALSE(bytes.empty());
    EXPECT_EQ(peekMessageType(bytes), uint8_t(MessageType::Hello));
    Hello back;
    ASSERT_TRUE(decodeMessage(bytes, back));
    EXPECT_EQ(back.role, Role::Instructor);
    EXPECT_EQ(back.name, "Dr. Ada");
    EXPECT_EQ(back.codec, Codec::Zstd);
    EXPECT_EQ(back.view, h.view);

    HapticModel hm;
    hm.force = {0.5f, -1.0f, 2.0f};
    hm.gradient[1][2] = 3.5f;
    hm.contact = true;
    auto hb = encodeMessage(hm);
    HapticModel hmBack;
    ASSERT_TRUE(decodeMessage(hb, hmBack));
    EXPECT_EQ(hmBack.force, hm.force);
    EXPECT_EQ(hmBack.gradient, hm.gradient);
    // A message of one type never decodes as another.
    EXPECT_FALSE(decodeMessage(hb, back));
}

TEST(Protocol, RejectsOutOfRangeRectanglesAndTrailingBytes) {
    ImageUpdate u;
    u.x = 4000;
    u.width = 200; // runs past the largest window
    u.height = 4;
    u.rawBytes = 10;
    u.payload = {1, 2, 3};
    EXPECT_TRUE(encodeMessage(u).empty());

    u.x = 10;
    auto ok = encodeMessage(u);
    ImageUpdate back;
    ASSERT_TRUE(decodeMessage(ok, back));
    ok.push_back(0);
    EXPECT_FALSE(decodeMessage(ok, back)) << "trailing bytes accepted";

    // The grid update is a part of the render (version 6): never longer than it.
    u.renderUs = 300;
    u.gridUs = 120;
    ok = encodeMessage(u);
    ASSERT_TRUE(decodeMessage(ok, back));
    EXPECT_EQ(back.gridUs, 120u);
    EXPECT_EQ(back.renderUs, 300u);
    u.gridUs = 301;
    EXPECT_TRUE(encodeMessage(u).empty()) << "grid time over the render time encoded";

    ToolState t;
    t.speed = 0.5f;
    auto tb = encodeMessage(t);
    ToolState tBack;
    ASSERT_TRUE(decodeMessage(tb, tBack));
    // Poison the position with a NaN: position.x starts after seq(4)+time(8)+kind(1)+diam(4).
    float nan = std::nanf("");
    std::memcpy(&tb[1 + 17], &nan, 4);
    EXPECT_FALSE(decodeMessage(tb, tBack));
}

// The wire carries every kind the tool catalogue has, and no other.
TEST(Protocol, EveryCatalogueToolKindTravelsAndNoOther) {
    for (const ToolType* type : toolTypes()) {
        ToolState t;
        t.toolKind = uint8_t(type->kind);
        t.diameterMm = type->defaultDiameterMm;
        ToolState back;
        ASSERT_TRUE(decodeMessage(encodeMessage(t), back)) << type->name;
        EXPECT_EQ(back.toolKind, uint8_t(type->kind));
        EXPECT_NO_THROW(shapeOf(back)) << type->name;
    }
    ToolState t;
    std::vector<uint8_t> bytes = encodeMessage(t);
    bytes[1 + 12] = kToolKindCount; // kind after seq(4)+time(8)
    ToolState back;
    EXPECT_FALSE(decodeMessage(bytes, back));
}

TEST(Protocol, TruncatedAndRandomPacketsNeverDecode) {
    ImageUpdate u;
    u.width = u.height = 8;
    u.rawBytes = 64;
    u.payload.assign(64, 7);
    auto bytes = encodeMessage(u);
    for (size_t n = 0; n < bytes.size(); ++n) {
        ImageUpdate back;
        EXPECT_FALSE(decodeMessage(std::span(bytes.data(), n), back)) << n;
    }
    std::mt19937 rng(7);
    int decoded = 0;
    for (int i = 0; i < 5000; ++i) {
        std::vector<uint8_t> junk(1 + rng() % 80);
        for (auto& b : junk)
            b = uint8_t(rng());
        junk[0] = uint8_t(MessageType::ToolState);
        ToolState t;
        decoded += decodeMessage(junk, t);
    }
    EXPECT_LT(decoded, 5); // random bytes almost never make a valid, exactly sized tool state
}

TEST(Protocol, RefuseReasonsReadAsSentences) {
    uint32_t data = uint32_t(RefuseReason::Version) | (7u << 8);
    EXPECT_NE(refuseReasonText(data).find("version 7"), std::string::npos);
    EXPECT_NE(refuseReasonText(uint32_t(RefuseReason::Shutdown)).find("shutting down"),
              std::string::npos);
}

TEST(Protocol, SyncModeAndVolumeUpdateRoundTrip) {
    SyncMode m{Sync::Volume, Codec::Lz4};
    auto mb = encodeMessage(m);
    ASSERT_EQ(mb.size(), 3u);
    SyncMode mBack;
    ASSERT_TRUE(decodeMessage(mb, mBack));
    EXPECT_EQ(mBack.sync, Sync::Volume);
    EXPECT_EQ(mBack.volumeCodec, Codec::Lz4);
    mb[1] = 2; // no third mode
    EXPECT_FALSE(decodeMessage(mb, mBack));

    VolumeUpdate u;
    u.sequence = 9;
    u.causeServerUs = 123;
    u.sentServerUs = 456;
    u.erodeUs = 7;
    u.encodeUs = 8;
    u.x = 1;
    u.y = 2;
    u.z = 3;
    u.sizeX = 4;
    u.sizeY = 5;
    u.sizeZ = 6;
    u.rawBytes = 4 * 5 * 6;
    u.payload.assign(u.rawBytes, 200);
    auto ub = encodeMessage(u);
    ASSERT_FALSE(ub.empty());
    EXPECT_EQ(peekMessageType(ub), uint8_t(MessageType::VolumeUpdate));
    VolumeUpdate back;
    ASSERT_TRUE(decodeMessage(ub, back));
    EXPECT_EQ(back.sequence, 9u);
    EXPECT_EQ(back.causeServerUs, 123u);
    EXPECT_EQ(back.encodeUs, 8u);
    EXPECT_EQ(back.z, 3);
    EXPECT_EQ(back.sizeZ, 6);
    EXPECT_EQ(back.payload, u.payload);
    for (size_t n = 0; n < ub.size(); ++n)
        EXPECT_FALSE(decodeMessage(std::span(ub.data(), n), back)) << n;
    ub.push_back(0);
    EXPECT_FALSE(decodeMessage(ub, back)) << "trailing bytes accepted";
}

TEST(Protocol, VolumeUpdateRejectsBadBoxesSizesAndEncodings) {
    VolumeUpdate u;
    u.sizeX = u.sizeY = u.sizeZ = 2;
    u.rawBytes = 8;
    u.payload.assign(8, 1);
    ASSERT_FALSE(encodeMessage(u).empty());
    VolumeUpdate bad = u;
    bad.x = 4095; // runs past the largest volume
    EXPECT_TRUE(encodeMessage(bad).empty());
    bad = u;
    bad.sizeY = 0;
    EXPECT_TRUE(encodeMessage(bad).empty());
    bad = u;
    bad.rawBytes = 9; // a box update is exactly one byte per voxel
    EXPECT_TRUE(encodeMessage(bad).empty());
    bad = u;
    bad.full = true; // a full volume is density + material and never raw
    bad.rawBytes = 16;
    EXPECT_TRUE(encodeMessage(bad).empty());
    bad.materials = true;
    EXPECT_TRUE(encodeMessage(bad).empty());
    bad.codec = Codec::Zstd;
    EXPECT_FALSE(encodeMessage(bad).empty());
    bad.full = false; // a box with materials: density then material bytes
    EXPECT_FALSE(encodeMessage(bad).empty());
    bad.rawBytes = 8;
    EXPECT_TRUE(encodeMessage(bad).empty());

    // The same checks hold on the reading side: patch the wire bytes of a good message.
    auto bytes = encodeMessage(u);
    // type(1) seq(4) cause(8) sent(8) erode(4) encode(4) full(1) materials(1), then x, y, z, sx,
    // sy, sz (u16).
    const size_t boxAt = 1 + 4 + 8 + 8 + 4 + 4 + 1 + 1;
    VolumeUpdate back;
    auto patched = bytes;
    patched[boxAt + 6] = 0; // sizeX = 0
    patched[boxAt + 7] = 0;
    EXPECT_FALSE(decodeMessage(patched, back));
    patched = bytes;
    patched[boxAt + 10] = 3; // sizeZ = 3: rawBytes no longer matches the box
    EXPECT_FALSE(decodeMessage(patched, back));
    patched = bytes;
    patched[boxAt + 12] = 3; // the codec byte after the box: out of range
    EXPECT_FALSE(decodeMessage(patched, back));
}

TEST(Protocol, ParticipantsRoundTripAndRejectUnorderedIdsAndOverlongLists) {
    Participants p;
    p.list = {{3, Role::Trainee, Sync::Dbi, "Ada"},
              {7, Role::Instructor, Sync::Volume, "Dr. Cho"},
              {9, Role::Trainee, Sync::Dbi, ""}};
    auto bytes = encodeMessage(p);
    Participants back;
    ASSERT_TRUE(decodeMessage(bytes, back));
    EXPECT_EQ(back.list, p.list);
    Participants none;
    ASSERT_TRUE(decodeMessage(encodeMessage(none), back));
    EXPECT_TRUE(back.list.empty());

    Participants unordered = p;
    std::swap(unordered.list[0], unordered.list[1]);
    EXPECT_FALSE(decodeMessage(encodeMessage(unordered), back));
    Participants badRole = p;
    auto raw = encodeMessage(badRole);
    raw[5] = 2; // the first entry's role (type, count u16, id u16): no third role
    EXPECT_FALSE(decodeMessage(raw, back));
    // A count above the limit fails before any entry is read (nothing is allocated for it).
    std::vector<uint8_t> big = {uint8_t(MessageType::Participants),
                                uint8_t((kMaxParticipants + 1) & 0xff),
                                uint8_t((kMaxParticipants + 1) >> 8)};
    EXPECT_FALSE(decodeMessage(big, back));
    for (size_t n = 1; n < bytes.size(); ++n)
        EXPECT_FALSE(decodeMessage(std::span(bytes.data(), n), back)) << n;
}

// A camera that looks nowhere (eye at the target) or whose up lies along its view direction has
// NaN matrices: such a view is malformed, whether in a hello or a view request.
TEST(Protocol, AViewWithoutADirectionOrWithUpAlongItIsMalformed) {
    ViewRequest r;
    r.requestId = 1;
    EXPECT_FALSE(encodeMessage(r).empty()) << "the default view is fine";
    ViewRequest still = r;
    still.view.eye = still.view.target;
    EXPECT_TRUE(encodeMessage(still).empty());
    ViewRequest along = r;
    along.view.up = along.view.target - along.view.eye;
    EXPECT_TRUE(encodeMessage(along).empty());
    ViewRequest noUp = r;
    noUp.view.up = glm::vec3(0.0f);
    EXPECT_TRUE(encodeMessage(noUp).empty());
}

// An eye or target beyond kMaxViewDistanceMm, or a far plane beyond kMaxViewFarMm, is malformed:
// the server's ray caster counts samples in int, which a far plane or eye near 1e38 mm would
// overflow. (One serialize() checks both ways: what cannot be written cannot be read.)
TEST(Protocol, AViewFartherThanTheLimitsIsMalformed) {
    ViewRequest r;
    r.requestId = 1;
    ViewRequest farEye = r;
    farEye.view.eye.z = 1e38f;
    EXPECT_TRUE(encodeMessage(farEye).empty());
    ViewRequest farTarget = r;
    farTarget.view.target.x = -2.0f * kMaxViewDistanceMm;
    EXPECT_TRUE(encodeMessage(farTarget).empty());
    ViewRequest farPlane = r;
    farPlane.view.farMm = 1e38f;
    EXPECT_TRUE(encodeMessage(farPlane).empty());
    ViewRequest edge = r;
    edge.view.eye.z = kMaxViewDistanceMm;
    edge.view.farMm = kMaxViewFarMm;
    EXPECT_FALSE(encodeMessage(edge).empty()) << "the limits themselves are fine";
}

TEST(Protocol, AWelcomeWithASpacingNoVolumeMayHaveIsMalformed) {
    // The client's renderer steps by the smallest spacing across the largest extent: a zero,
    // negative, vanishing or very anisotropic spacing would make it march (all but) forever.
    Welcome w;
    w.volumeDims = {64, 64, 64};
    w.spacing = {0.5f, 0.5f, 0.75f};
    const std::vector<uint8_t> valid = encodeMessage(w);
    ASSERT_FALSE(valid.empty());
    const size_t at = 1 + 2 + 8 + 12; // type, client id, server time, dims
    auto withSpacing = [&](glm::vec3 s) {
        std::vector<uint8_t> b = valid;
        std::memcpy(b.data() + at, &s, sizeof s);
        Welcome back;
        return decodeMessage(b, back) && back.spacing == s;
    };
    EXPECT_TRUE(withSpacing({0.5f, 0.5f, 0.75f}));
    EXPECT_TRUE(withSpacing({0.001f, 0.001f, 1.0f})); // a ratio of 1000 is the most
    EXPECT_TRUE(withSpacing({1000.0f, 1000.0f, 1000.0f}));
    for (glm::vec3 s : {glm::vec3(0.0f, 1.0f, 1.0f), glm::vec3(-0.5f), glm::vec3(1e-6f, 1.0f, 1.0f),
                        glm::vec3(1e-4f), glm::vec3(2000.0f), glm::vec3(0.001f, 1.5f, 1.0f),
                        glm::vec3(-0.0f, 1.0f, 1.0f)})
        EXPECT_FALSE(withSpacing(s)) << s.x << " " << s.y << " " << s.z;
    w.spacing = glm::vec3(0.0f);
    EXPECT_TRUE(encodeMessage(w).empty()); // nor does a server send one
}

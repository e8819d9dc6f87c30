// The Trephine wire protocol: message types, their fields and their one serialize() each (write,
// read and size). docs/protocol.md describes the same format for people; keep the two together.
// Reads check every length and range; a message that fails to read is dropped and counted.
#pragma once

#include "net/participant_colours.h"
#include "net/serialize.h"

#include "libsim/tool_catalogue.h"
#include "libsim/volume_io.h"

#include <glm/gtc/quaternion.hpp>
#include <glm/mat3x3.hpp>
#include <glm/vec3.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

namespace trephine::net {

// Travels in ENet's connect data; the server refuses other versions with kRefuseVersion. What
// each version changed: docs/protocol.md, "Versions".
inline constexpr uint32_t kProtocolVersion = 16;

// Disconnect reasons (ENet disconnect data) the client turns into a sentence for the user.
enum class RefuseReason : uint32_t {
    None = 0,
    Version = 1,    // protocol version mismatch
    Malformed = 2,  // kept sending malformed messages
    ServerFull = 3, //
    Shutdown = 4,   // the server is stopping
    BadHello = 5,   // first message was not a valid hello
    // volume sync: the whole volume does not fit a message in the client's volume codec
    VolumeTooLarge = 6,
    // docs/security.md. WrongCode carries a CodeRefusal in bits 8 and up; TooManyAttempts the
    // seconds until this address may try again.
    WrongCode = 7,
    Removed = 8, // the instructor removed this participant
    TooManyAttempts = 9,
    Busy = 10,      // too many connections wait to be admitted (from this address, or in all)
    Idle = 11,      // said nothing for ServerConfig::idleTimeoutS
    ViewsFull = 12, // the views served together would pass ServerConfig::maxTotalViewPixels
    // Admission under pressure (net/admission.h): connect again with the cookie in bits 8 and up
    // as the connect ID. A client not yet welcomed does so at once.
    Retry = 13,
};
enum class CodeRefusal : uint32_t {
    Wrong = 0,               // the code proved none of the session's
    None = 1,                // the session needs a code and the client gave none
    TraineeAsInstructor = 2, // the trainee code, in instructor mode
    ServerOpen = 3, // said by the client itself: it will not join an open session with a code
};
std::string refuseReasonText(uint32_t disconnectData);

inline constexpr uint16_t kMaxWindowSize = 4096;
inline constexpr size_t kMaxNameLength = 64;
// A role code as shown (Codes): a longer one given at start is sent in its normalised form.
inline constexpr size_t kMaxCodeTextBytes = 96;
// The most entries a Participants message may hold (the server's --max-clients is far below).
inline constexpr uint16_t kMaxParticipants = 1024;
// The most marks a session holds (Annotations); an Annotate add beyond it is refused.
inline constexpr uint16_t kMaxAnnotations = 256;
// Marks lie within this distance of the volume's centre (mm): the largest volume is 4096 voxels.
inline constexpr float kMaxAnnotationDistanceMm = 1.0e5f;
// Tool positions likewise; a tool's orientation quaternion has a norm within [0.5, 2] (the server
// normalises it).
inline constexpr float kMaxToolDistanceMm = 1.0e5f;
// A view's eye and target likewise, and its far plane at most this far (mm): further out float
// positions lose a skull's detail (the ray caster's int sample indices stay in range for any view:
// it widens its step, docs/rendering.md).
inline constexpr float kMaxViewDistanceMm = 1.0e5f;
inline constexpr float kMaxViewFarMm = 1.0e6f;
inline constexpr size_t kMaxPayloadBytes = 64u * 1024u * 1024u;
// The largest message the server sends: ENet delivers a reliable packet only while its fragments
// (1372 bytes at the default MTU) fit the receiver's acknowledgement window (7-8 windows of 4096
// sequence numbers past the channel's position: 32-37 MiB), and it refuses packets over its
// 32 MiB default anyway. A larger one is never sent (a box goes as the whole volume, compressed;
// a whole volume over it refuses volume sync: RefuseReason::VolumeTooLarge).
inline constexpr size_t kMaxSentMessageBytes = 30u * 1024u * 1024u;
// Images: a raw rectangle costs 8 bytes a pixel; the lz4/zstd forms at most 5.25 before
// compression (the predicted form's masks and residuals; the planar form 5) and at most ~0.4 %
// more after it. A raw rectangle whose 8 bytes a pixel exceed this goes lz4-coded instead (the
// client decodes whatever codec an update names); the largest view a server may serve
// (ServerConfig::maxViewPixels) is one whose coded image always fits.
inline constexpr size_t kMaxImagePayloadBytes = kMaxSentMessageBytes - 64u * 1024u;
inline constexpr int64_t kMaxServedViewPixels = int64_t(kMaxImagePayloadBytes / 21 * 4 * 250 / 251);
inline constexpr uint16_t kMaxVolumeDim = 4096;    // as the welcome's range
inline constexpr size_t kMaxVolumeNameBytes = 256; // the welcome's volume name
// The largest uncompressed volume layout a VolumeUpdate may announce (density + material bytes of
// a 512^3 volume); ENet itself refuses packets over 32 MiB, so payloads stay under
// kMaxPayloadBytes.
inline constexpr uint32_t kMaxVolumeRawBytes = 512u * 512u * 512u * 2u;
// Whether a box of `size` voxels (density, and materials when `materials`) is within
// kMaxVolumeRawBytes, so a VolumeUpdate may carry it at all, however well it codes.
inline bool fitsVolumeUpdate(glm::ivec3 size, bool materials) {
    return size.x >= 0 && size.y >= 0 && size.z >= 0 &&
           uint64_t(size.x) * uint64_t(size.y) * uint64_t(size.z) * (materials ? 2u : 1u) <=
               kMaxVolumeRawBytes;
}

// Every message, once: X(name, type byte, direction, channel, newest wins, version it came in).
// The name is also its struct's (here, net/scene.h, net/assessment_protocol.h,
// net/replay_protocol.h). The enum below and net/messages.h (the table, the type list and the
// dispatch a receiver's handlers go through) come from it; docs/protocol.md's message list is
// checked against it (tests/net/test_message_table.cpp). Newest wins: a newer one says all an
// older one said (unsequenced on the tool and haptic channels; held as the newest of its kind by
// the control budget, net/budgets.h). Append new types; a type byte is never reused.
#define TREPHINE_MESSAGES(X)                                                                       \
    X(Hello, 1, ClientToServer, Control, false, 1)                                                 \
    X(Welcome, 2, ServerToClient, Control, false, 1)                                               \
    X(ViewRequest, 3, ClientToServer, Control, false, 1)                                           \
    X(ToolState, 4, ClientToServer, ToolState, true, 1)                                            \
    X(ToolRelay, 5, ServerToClient, ToolState, true, 1)                                            \
    X(HapticModel, 6, ServerToClient, Haptic, true, 1)                                             \
    X(ImageUpdate, 7, ServerToClient, Image, false, 1)                                             \
    X(VolumeUpdate, 8, ServerToClient, Volume, false, 2)                                           \
    X(Ping, 9, ClientToServer, Control, false, 1)                                                  \
    X(Pong, 10, ServerToClient, Control, false, 1)                                                 \
    X(Participants, 11, ServerToClient, Control, true, 3)                                          \
    X(SyncMode, 12, ClientToServer, Control, false, 2)                                             \
    X(HapticRelay, 13, ServerToClient, Haptic, true, 1)                                            \
    X(Annotate, 14, ClientToServer, Control, false, 3)                                             \
    X(Annotations, 15, ServerToClient, Control, true, 3)                                           \
    X(TakeOver, 16, ClientToServer, Control, false, 4)                                             \
    X(Scene, 17, ServerToClient, Control, false, 8)                                                \
    X(ViewAs, 18, ClientToServer, Control, false, 8)                                               \
    X(ParticipantView, 19, ServerToClient, Control, true, 8)                                       \
    X(SafetyWarning, 20, ServerToClient, Control, false, 9)                                        \
    X(AssessmentSnapshot, 21, ServerToClient, Control, false, 9)                                   \
    X(ReplayState, 22, ServerToClient, Control, false, 10)                                         \
    X(ReplayControl, 23, ClientToServer, Control, false, 10)                                       \
    X(Handshake, 24, Both, Control, false, 9)                                                      \
    X(Remove, 25, ClientToServer, Control, false, 9)                                               \
    X(Codes, 26, Both, Control, true, 10)                                                          \
    X(HandLinks, 27, Both, Control, true, 12)                                                      \
    X(ImageAck, 28, ClientToServer, ImageLossy, true, 13)                                          \
    X(ViewRefused, 29, ServerToClient, Control, false, 16)

enum class MessageType : uint8_t {
#define TREPHINE_MESSAGE_ENUM(name, id, direction, channel, newestWins, since) name = id,
    TREPHINE_MESSAGES(TREPHINE_MESSAGE_ENUM)
#undef TREPHINE_MESSAGE_ENUM
};

namespace detail {
// One past the largest type byte of the list.
constexpr uint8_t messageTypeEnd() {
    uint8_t end = 1;
#define TREPHINE_MESSAGE_END(name, id, direction, channel, newestWins, since)                      \
    end = std::max<uint8_t>(end, uint8_t(id + 1));
    TREPHINE_MESSAGES(TREPHINE_MESSAGE_END)
#undef TREPHINE_MESSAGE_END
    return end;
}
} // namespace detail
inline constexpr uint8_t kMessageTypeCount = detail::messageTypeEnd(); // one past the largest

enum class Role : uint8_t { Trainee = 0, Instructor = 1 };
enum class Codec : uint8_t { Raw = 0, Lz4 = 1, Zstd = 2 };
enum class Sync : uint8_t { Dbi = 0, Volume = 1 };

// [SECTION] field helpers

template <typename S>
bool serializeFinite(S& s, float& v) {
    if (!s.f32(v))
        return false;
    return std::isfinite(v);
}

template <typename S>
bool serializeVec3(S& s, glm::vec3& v) {
    return serializeFinite(s, v.x) && serializeFinite(s, v.y) && serializeFinite(s, v.z);
}

template <typename S>
bool serializeQuat(S& s, glm::quat& q) {
    return serializeFinite(s, q.w) && serializeFinite(s, q.x) && serializeFinite(s, q.y) &&
           serializeFinite(s, q.z);
}

// A voxel spacing (mm) that a volume file may have (libsim's checkSpacing): each axis within
// [kMinSpacingMm, kMaxSpacingMm], none over kMaxSpacingRatio times another's. A client's renderer
// steps by the smallest spacing across the largest extent: a zero, negative or vanishing one from
// the wire would make it march forever.
template <typename S>
bool serializeSpacing(S& s, glm::vec3& v) {
    if (!serializeVec3(s, v))
        return false;
    for (int i = 0; i < 3; ++i)
        if (!(double(v[i]) >= kMinSpacingMm && double(v[i]) <= kMaxSpacingMm))
            return false;
    return double(std::max({v.x, v.y, v.z})) <=
           double(std::min({v.x, v.y, v.z})) * kMaxSpacingRatio;
}

// A u16 count (at most maxCount) and that many entries, in strictly increasing id(entry): no
// duplicates, and one order for every receiver.
template <typename S, typename T, typename Id>
bool serializeIdList(S& s, std::vector<T>& list, uint16_t maxCount, Id id) {
    uint16_t count = uint16_t(std::min<size_t>(list.size(), maxCount));
    if (!s.ranged(count, uint16_t(0), maxCount))
        return false;
    if constexpr (S::kReading)
        list.assign(count, T{});
    for (uint16_t i = 0; i < count; ++i) {
        if (!list[i].serialize(s))
            return false;
        if (i > 0 && id(list[i]) <= id(list[i - 1]))
            return false;
    }
    return true;
}

// [SECTION] messages

// A camera as both ends build it with glm::lookAt and glm::perspective.
struct ViewSpec {
    glm::vec3 eye{0, 0, 300};
    glm::vec3 target{0};
    glm::vec3 up{0, 1, 0};
    float fovYDeg = 60.0f;
    float nearMm = 10.0f;
    float farMm = 1000.0f;
    uint16_t width = 500;
    uint16_t height = 500;

    template <typename S>
    bool serialize(S& s) {
        return serializeVec3(s, eye) && serializeVec3(s, target) && serializeVec3(s, up) &&
               serializeFinite(s, fovYDeg) && fovYDeg > 1.0f && fovYDeg < 179.0f &&
               serializeFinite(s, nearMm) && serializeFinite(s, farMm) && nearMm > 0.0f &&
               farMm > nearMm && farMm <= kMaxViewFarMm && within(eye) && within(target) &&
               s.ranged(width, uint16_t(1), kMaxWindowSize) &&
               s.ranged(height, uint16_t(1), kMaxWindowSize) && oriented();
    }
    static bool within(glm::vec3 p) {
        return std::abs(p.x) <= kMaxViewDistanceMm && std::abs(p.y) <= kMaxViewDistanceMm &&
               std::abs(p.z) <= kMaxViewDistanceMm;
    }
    // A camera needs a direction to look in and an up that is not along it (lookAt of either
    // gives NaN matrices, so every pixel would be garbage).
    bool oriented() const {
        const glm::vec3 dir = target - eye;
        const float d = std::sqrt(dir.x * dir.x + dir.y * dir.y + dir.z * dir.z);
        const float u = std::sqrt(up.x * up.x + up.y * up.y + up.z * up.z);
        const glm::vec3 c(dir.y * up.z - dir.z * up.y, dir.z * up.x - dir.x * up.z,
                          dir.x * up.y - dir.y * up.x);
        const float cross = std::sqrt(c.x * c.x + c.y * c.y + c.z * c.z);
        return d > 1e-6f && u > 1e-6f && cross > 1e-4f * d * u;
    }
    bool operator==(const ViewSpec&) const = default;
};

struct Hello {
    static constexpr MessageType kType = MessageType::Hello;
    Role role = Role::Trainee;
    std::string name;
    Codec codec = Codec::Lz4;
    Sync sync = Sync::Dbi;
    // How volume box updates travel: Raw is the paper's 1 byte per voxel; Lz4 / Zstd compress it
    // (the baseline's compressed variant, reported separately).
    Codec volumeCodec = Codec::Raw;
    ViewSpec view;

    template <typename S>
    bool serialize(S& s) {
        return s.ranged(role, Role::Trainee, Role::Instructor) && s.string(name, kMaxNameLength) &&
               s.ranged(codec, Codec::Raw, Codec::Zstd) &&
               s.ranged(sync, Sync::Dbi, Sync::Volume) &&
               s.ranged(volumeCodec, Codec::Raw, Codec::Zstd) && view.serialize(s);
    }
};

struct Welcome {
    static constexpr MessageType kType = MessageType::Welcome;
    uint16_t clientId = 0;
    uint64_t serverTimeUs = 0;
    glm::ivec3 volumeDims{0};
    glm::vec3 spacing{1.0f};
    // A label for people (the Session panel): a client never opens it as a file or a volume spec;
    // what it needs of the volume comes in the Scene that follows.
    std::string volumeName;
    // The largest view (width x height pixels) the server serves: a larger ViewRequest would be
    // dropped, so the client refuses it itself (SessionClient::requestView).
    uint32_t maxViewPixels = uint32_t(kMaxWindowSize) * kMaxWindowSize;

    template <typename S>
    bool serialize(S& s) {
        return s.integer(clientId) && s.integer(serverTimeUs) &&
               s.ranged(volumeDims.x, 1, int(kMaxVolumeDim)) &&
               s.ranged(volumeDims.y, 1, int(kMaxVolumeDim)) &&
               s.ranged(volumeDims.z, 1, int(kMaxVolumeDim)) && serializeSpacing(s, spacing) &&
               s.string(volumeName, kMaxVolumeNameBytes) &&
               s.ranged(maxViewPixels, uint32_t(1), uint32_t(kMaxWindowSize) * kMaxWindowSize);
    }
};

struct ViewRequest {
    static constexpr MessageType kType = MessageType::ViewRequest;
    uint32_t requestId = 0;
    ViewSpec view;

    template <typename S>
    bool serialize(S& s) {
        return s.integer(requestId) && view.serialize(s);
    }
};

// A view request the server does not serve: all participants' views together would pass its
// total (ServerConfig::maxTotalViewPixels). The client keeps the view it has.
struct ViewRefused {
    static constexpr MessageType kType = MessageType::ViewRefused;
    uint32_t requestId = 0;
    uint32_t freePixels = 0; // the most pixels a view of this participant could have now

    template <typename S>
    bool serialize(S& s) {
        return s.integer(requestId) && s.integer(freePixels);
    }
};

// The client's tool: pose, kind, size and drilling speed. Unsequenced; the newest wins.
struct ToolState {
    static constexpr MessageType kType = MessageType::ToolState;
    uint32_t sequence = 0;
    uint64_t clientTimeUs = 0;
    uint8_t toolKind = 0; // ToolKind
    float diameterMm = 4.0f;
    glm::vec3 position{0};
    glm::quat orientation{1, 0, 0, 0};
    float speed = 0.0f; // [0, 1]
    bool drilling = false;

    template <typename S>
    bool serialize(S& s) {
        return s.integer(sequence) && s.integer(clientTimeUs) &&
               s.ranged(toolKind, uint8_t(0), uint8_t(kToolKindCount - 1)) &&
               serializeFinite(s, diameterMm) && diameterMm > 0.0f && diameterMm <= 20.0f &&
               serializeVec3(s, position) && std::abs(position.x) <= kMaxToolDistanceMm &&
               std::abs(position.y) <= kMaxToolDistanceMm &&
               std::abs(position.z) <= kMaxToolDistanceMm && serializeQuat(s, orientation) &&
               glm::dot(orientation, orientation) >= 0.25f &&
               glm::dot(orientation, orientation) <= 4.0f && serializeFinite(s, speed) &&
               speed >= 0.0f && speed <= 1.0f && s.boolean(drilling);
    }
};

// Another participant's tool, relayed by the server so every client can draw every tool.
struct ToolRelay {
    static constexpr MessageType kType = MessageType::ToolRelay;
    uint16_t clientId = 0;
    ToolState tool;

    template <typename S>
    bool serialize(S& s) {
        return s.integer(clientId) && tool.serialize(s);
    }
};

// Multi-rate haptics: force f(P_N) and its gradient at the device position P_N the server used.
struct HapticModel {
    static constexpr MessageType kType = MessageType::HapticModel;
    uint32_t toolSequence = 0;
    uint64_t serverReceivedUs = 0;
    uint64_t serverSentUs = 0;
    uint64_t clientTimeUs = 0; // echoed from the tool state, for the round trip
    glm::vec3 position{0};     // P_N
    glm::vec3 force{0};        // newtons
    glm::mat3 gradient{0.0f};  // N/mm, column-major as glm
    bool contact = false;

    template <typename S>
    bool serialize(S& s) {
        bool ok = s.integer(toolSequence) && s.integer(serverReceivedUs) &&
                  s.integer(serverSentUs) && s.integer(clientTimeUs) &&
                  serializeVec3(s, position) && serializeVec3(s, force);
        for (int c = 0; ok && c < 3; ++c)
            ok = serializeVec3(s, gradient[c]);
        return ok && s.boolean(contact);
    }
};

// Another participant's force model, relayed by the server's network thread to every instructor
// when it answers that participant's tool state (Channel::Haptic, unsequenced; newest wins).
struct HapticRelay {
    static constexpr MessageType kType = MessageType::HapticRelay;
    uint16_t clientId = 0;
    HapticModel model;

    template <typename S>
    bool serialize(S& s) {
        return s.integer(clientId) && model.serialize(s);
    }
};

// A rectangle of the client's DBI (x, y from the bottom-left, as GL), encoded with `codec`. Full
// images travel reliably on Channel::Image; since version 13 the server sends drilling
// rectangles on Channel::ImageLossy, unreliable, naming the full image they build on.
struct ImageUpdate {
    static constexpr MessageType kType = MessageType::ImageUpdate;
    uint32_t sequence = 0;
    uint32_t viewId = 0; // the ViewRequest this image belongs to (0 = the hello's view)
    // A rectangle after a full image (lossy or not): the sequence of the full image it applies on
    // (a client holding another ignores it). 0: a full image.
    uint32_t fullSequence = 0;
    // A rectangle after a full image that builds on the client's picture after image
    // `baseSequence` (version 14): it applies only there, and carries only its own pixels. 0: it
    // carries every rectangle the client has not acknowledged, and applies on any older picture.
    uint32_t baseSequence = 0;
    uint64_t causeServerUs = 0; // when the tool state that caused it reached the server
    uint64_t sentServerUs = 0;
    bool full = false; // a whole-window refresh (join or view change)
    // A new large view's first picture, shown until its exact full image follows (version 13):
    // the view at half size (previewCamera; x = y = 0, width and height (w + 1) / 2 and
    // (h + 1) / 2 of the view's), each pixel shown as a 2 x 2 block (since version 14).
    bool preview = false;
    uint16_t x = 0, y = 0, width = 0, height = 0;
    Codec codec = Codec::Raw;
    uint32_t rawBytes = 0; // size before compression
    // Server stage times of this update, microseconds (0: none): the erosion of the batch that
    // caused it, the rendering of its rectangle, the extraction and encoding of its pixels.
    // gridUs: the part of renderUs spent bringing the renderer's brick grid up to date.
    uint32_t erodeUs = 0, renderUs = 0, encodeUs = 0, gridUs = 0;
    // Coded against the pixels the client holds in the rectangle (net/image_delta.h): only for
    // lz4/zstd and never for a full image; baseHash = basePixelHash of those pixels.
    bool predicted = false;
    uint32_t baseHash = 0;
    std::vector<uint8_t> payload;

    template <typename S>
    bool serialize(S& s) {
        return s.integer(sequence) && s.integer(viewId) && s.integer(fullSequence) &&
               s.integer(baseSequence) && !(baseSequence != 0 && fullSequence == 0) &&
               s.integer(causeServerUs) && s.integer(sentServerUs) && s.integer(erodeUs) &&
               s.integer(renderUs) && s.integer(encodeUs) && s.integer(gridUs) &&
               gridUs <= renderUs && s.boolean(full) && !(full && fullSequence != 0) &&
               s.boolean(preview) && !(preview && !full) && s.boolean(predicted) &&
               s.integer(baseHash) && !(predicted && full) &&
               s.ranged(x, uint16_t(0), uint16_t(kMaxWindowSize - 1)) &&
               s.ranged(y, uint16_t(0), uint16_t(kMaxWindowSize - 1)) &&
               s.ranged(width, uint16_t(1), kMaxWindowSize) &&
               s.ranged(height, uint16_t(1), kMaxWindowSize) && x + width <= kMaxWindowSize &&
               y + height <= kMaxWindowSize && s.ranged(codec, Codec::Raw, Codec::Zstd) &&
               !(predicted && codec == Codec::Raw) &&
               s.ranged(rawBytes, uint32_t(1), uint32_t(kMaxPayloadBytes)) &&
               s.blob(payload, kMaxPayloadBytes);
    }
};

// Client -> server (Channel::Control, reliable): switch this client's sync mode live. To Volume:
// the server sends the whole volume, then BB_volume boxes; to Dbi: a full DBI of the client's
// view, then BB_screen rectangles.
struct SyncMode {
    static constexpr MessageType kType = MessageType::SyncMode;
    Sync sync = Sync::Dbi;
    Codec volumeCodec = Codec::Raw; // as Hello::volumeCodec

    template <typename S>
    bool serialize(S& s) {
        return s.ranged(sync, Sync::Dbi, Sync::Volume) &&
               s.ranged(volumeCodec, Codec::Raw, Codec::Zstd);
    }
};

// Voxels of the replicated-volume baseline (Channel::Volume, reliable). A box update carries the
// density of every voxel of the box (x fastest, then y, then z), 1 byte each as in the paper;
// the receiver sets material Air where the density is 0 and keeps its material elsewhere, which
// is exactly what erosion and box cuts do on the server. A full update carries the whole volume
// as every density byte then every material byte (box = the whole volume), always compressed;
// a box with `materials` set (voxels written wholesale, SessionServer::submitVoxels) carries the
// box's density bytes then its material bytes.
// The box is range-checked here against the largest volume and by the client against the dims
// of its welcome.
struct VolumeUpdate {
    static constexpr MessageType kType = MessageType::VolumeUpdate;
    uint32_t sequence = 0;      // shared with image updates: one counter per server
    uint64_t causeServerUs = 0; // when the tool state that caused it reached the server
    uint64_t sentServerUs = 0;
    uint32_t erodeUs = 0, encodeUs = 0; // server stage times (see ImageUpdate)
    bool full = false;
    bool materials = false; // the payload holds material bytes after the densities (full: always)
    uint16_t x = 0, y = 0, z = 0;             // box origin, voxels
    uint16_t sizeX = 0, sizeY = 0, sizeZ = 0; // box size, voxels
    Codec codec = Codec::Raw;
    uint32_t rawBytes = 0; // bytes before compression: box voxels (x 2 with materials)
    std::vector<uint8_t> payload;

    uint64_t voxelCount() const { return uint64_t(sizeX) * sizeY * sizeZ; }

    template <typename S>
    bool serialize(S& s) {
        constexpr uint16_t kLast = kMaxVolumeDim - 1;
        return s.integer(sequence) && s.integer(causeServerUs) && s.integer(sentServerUs) &&
               s.integer(erodeUs) && s.integer(encodeUs) && s.boolean(full) &&
               s.boolean(materials) && (!full || materials) && s.ranged(x, uint16_t(0), kLast) &&
               s.ranged(y, uint16_t(0), kLast) && s.ranged(z, uint16_t(0), kLast) &&
               s.ranged(sizeX, uint16_t(1), kMaxVolumeDim) &&
               s.ranged(sizeY, uint16_t(1), kMaxVolumeDim) &&
               s.ranged(sizeZ, uint16_t(1), kMaxVolumeDim) && x + sizeX <= kMaxVolumeDim &&
               y + sizeY <= kMaxVolumeDim && z + sizeZ <= kMaxVolumeDim &&
               s.ranged(codec, Codec::Raw, Codec::Zstd) &&
               s.ranged(rawBytes, uint32_t(1), kMaxVolumeRawBytes) &&
               uint64_t(rawBytes) == voxelCount() * (materials ? 2u : 1u) &&
               (full ? codec != Codec::Raw : true) && s.blob(payload, kMaxPayloadBytes);
    }
};

// One participant of the session as the server knows it from its hello.
struct ParticipantInfo {
    uint16_t clientId = 0;
    Role role = Role::Trainee;
    Sync sync = Sync::Dbi; // the design feeding its picture (the hello's, then its SyncMode)
    std::string name;
    // A trainee an instructor has taken over: that instructor's client id (0: nobody). Its
    // drilling is paused and the instructor's drill cuts instead (TakeOver).
    uint16_t takenOverBy = 0;
    // The colour every window draws this participant in (its name, tool and plots), given by the
    // server (net/participant_colours.h) for as long as it stays.
    Rgb8 colour{};

    template <typename S>
    bool serialize(S& s) {
        return s.ranged(clientId, uint16_t(1), uint16_t(UINT16_MAX)) &&
               s.ranged(role, Role::Trainee, Role::Instructor) &&
               s.ranged(sync, Sync::Dbi, Sync::Volume) && s.string(name, kMaxNameLength) &&
               s.integer(takenOverBy) && s.integer(colour.r) && s.integer(colour.g) &&
               s.integer(colour.b);
    }
    bool operator==(const ParticipantInfo&) const = default;
};

// Server -> client (Channel::Control, reliable): everyone in the session who has said hello, the
// receiver included, in increasing client id. Sent whole whenever it changes (a hello, a leave, a
// sync switch), so the newest one is the roster; a client forgets the tools and force models of
// ids it no longer lists.
struct Participants {
    static constexpr MessageType kType = MessageType::Participants;
    std::vector<ParticipantInfo> list;

    template <typename S>
    bool serialize(S& s) {
        return serializeIdList(s, list, kMaxParticipants,
                               [](const ParticipantInfo& p) { return p.clientId; });
    }
};

// Client -> server (Channel::Control, reliable): an instructor marks the skull for everyone (a
// point on the bone and a short label), removes one mark, or clears them all. The server refuses
// (counts, does not apply) edits from trainees and adds beyond kMaxAnnotations.
struct Annotate {
    static constexpr MessageType kType = MessageType::Annotate;
    enum class Op : uint8_t { Add = 0, Remove = 1, Clear = 2 };
    Op op = Op::Add;
    uint32_t id = 0;          // Remove: the mark's id (from Annotations)
    glm::vec3 position{0.0f}; // Add: object space, mm
    std::string label;        // Add

    template <typename S>
    bool serialize(S& s) {
        return s.ranged(op, Op::Add, Op::Clear) && s.integer(id) && serializeVec3(s, position) &&
               std::abs(position.x) <= kMaxAnnotationDistanceMm &&
               std::abs(position.y) <= kMaxAnnotationDistanceMm &&
               std::abs(position.z) <= kMaxAnnotationDistanceMm && s.string(label, kMaxNameLength);
    }
};

// One mark as the server keeps it.
struct AnnotationInfo {
    uint32_t id = 0;     // >= 1, unique in the session
    uint16_t author = 0; // client id of the instructor who placed it
    glm::vec3 position{0.0f};
    std::string label;

    template <typename S>
    bool serialize(S& s) {
        return s.ranged(id, uint32_t(1), uint32_t(UINT32_MAX)) && s.integer(author) &&
               serializeVec3(s, position) && s.string(label, kMaxNameLength);
    }
    bool operator==(const AnnotationInfo&) const = default;
};

// Server -> client (Channel::Control, reliable): every mark of the session in increasing id, sent
// whole to everyone whenever it changes and to each client after its welcome.
struct Annotations {
    static constexpr MessageType kType = MessageType::Annotations;
    std::vector<AnnotationInfo> list;

    template <typename S>
    bool serialize(S& s) {
        return serializeIdList(s, list, kMaxAnnotations,
                               [](const AnnotationInfo& a) { return a.id; });
    }
};

// Client -> server (Channel::Control, reliable): an instructor takes over a trainee (trainee's
// client id) or hands back whoever it holds (0). While taken over, the trainee's tool still
// touches the bone (forces, relays) but cuts nothing, and the instructor's drill cuts: the only
// time an instructor's drill does. An instructor holds one trainee at a time (taking another
// hands the first back); a trainee held by another instructor must be handed back first. The
// server refuses (counts, does not apply) take-overs from trainees and of anyone else, and hands
// back when either leaves; Participants says who holds whom.
struct TakeOver {
    static constexpr MessageType kType = MessageType::TakeOver;
    uint16_t trainee = 0; // 0: hand back

    template <typename S>
    bool serialize(S& s) {
        return s.integer(trainee);
    }
};

// What an instructor's force device is joined to (docs/devices.md): it feels participant `feels`'
// forces (0: its own), and it guides the hand of the trainee it holds (TakeOver) by a bounded
// spring toward its own tool. Both are off until asked for.
struct HandLink {
    uint16_t instructor = 0;
    uint16_t feels = 0;
    bool guides = false;
    bool operator==(const HandLink&) const = default;

    template <typename S>
    bool serialize(S& s) {
        return s.integer(instructor) && s.integer(feels) && s.boolean(guides);
    }
};
// Both ways (Channel::Control, reliable). Client -> server: an instructor's own link, the one
// entry of the list (its instructor is the sender, whatever it says); the server refuses
// (counts as a refused take-over) a trainee's and one feeling someone not in the session.
// Server -> everyone, with the roster: every link in force by instructor id, so a trainee knows
// who feels or guides it. A guide holds only while its instructor holds a trainee, and a feel
// while its participant is in the session: a hand-back or a leave ends them.
struct HandLinks {
    static constexpr MessageType kType = MessageType::HandLinks;
    std::vector<HandLink> list;

    template <typename S>
    bool serialize(S& s) {
        return serializeIdList(s, list, kMaxParticipants,
                               [](const HandLink& l) { return l.instructor; });
    }
};

// Client -> server (Channel::Control, reliable): an instructor watches through a participant's
// camera (its client id) or through its own again (0). The server answers with that
// participant's view (ParticipantView) at once and again whenever it changes; the instructor asks
// for the view like any other, so the server renders nothing new. Only an instructor's are
// applied (a trainee's is ignored).
struct ViewAs {
    static constexpr MessageType kType = MessageType::ViewAs;
    uint16_t clientId = 0;

    template <typename S>
    bool serialize(S& s) {
        return s.integer(clientId);
    }
};

// Server -> instructor (Channel::Control, reliable): the current view (its hello's, then its
// newest ViewRequest's) of the participant the instructor watches through (ViewAs).
struct ParticipantView {
    static constexpr MessageType kType = MessageType::ParticipantView;
    uint16_t clientId = 0;
    ViewSpec view;

    template <typename S>
    bool serialize(S& s) {
        return s.ranged(clientId, uint16_t(1), uint16_t(UINT16_MAX)) && view.serialize(s);
    }
};

// Channel::Control, the only message ever sent in the clear (docs/security.md): the role-code
// handshake, one step each. Server: Challenge at connect (whether the session takes codes, and
// the salt of the codes' hash). Client: Offer (the role it asks for, its SPAKE2 share X*).
// Server: Answer, one entry per code that may prove that role (an instructor's offer is also
// answered with the trainee code's, so a trainee code there is told apart from a wrong one):
// the code's role, its share Y* and its confirmation MAC. Client: Confirm, the entry whose MAC
// it could verify (kNoEntry: none) and its own MAC. Everything after a Confirm is sealed.
struct Handshake {
    static constexpr MessageType kType = MessageType::Handshake;
    enum class Step : uint8_t { Challenge = 0, Offer = 1, Answer = 2, Confirm = 3 };
    static constexpr uint8_t kNoEntry = 255;
    struct Entry {
        Role role = Role::Trainee;
        std::array<uint8_t, 32> share{}, mac{};
        bool operator==(const Entry&) const = default;
    };
    Step step = Step::Challenge;
    bool open = false;               // Challenge: no codes; the hello goes in the clear
    std::array<uint8_t, 16> salt{};  // Challenge
    Role role = Role::Trainee;       // Offer
    std::array<uint8_t, 32> share{}; // Offer: X*
    std::vector<Entry> entries;      // Answer: one or two
    uint8_t entry = kNoEntry;        // Confirm
    std::array<uint8_t, 32> mac{};   // Confirm

    template <typename S>
    bool serialize(S& s) {
        if (!s.ranged(step, Step::Challenge, Step::Confirm))
            return false;
        switch (step) {
        case Step::Challenge:
            return s.boolean(open) && s.bytes(salt.data(), salt.size());
        case Step::Offer:
            return s.ranged(role, Role::Trainee, Role::Instructor) &&
                   s.bytes(share.data(), share.size());
        case Step::Answer: {
            uint8_t count = uint8_t(std::min<size_t>(entries.size(), 2));
            if (!s.ranged(count, uint8_t(1), uint8_t(2)))
                return false;
            if constexpr (S::kReading)
                entries.assign(count, Entry{});
            for (Entry& e : entries)
                if (!s.ranged(e.role, Role::Trainee, Role::Instructor) ||
                    !s.bytes(e.share.data(), e.share.size()) ||
                    !s.bytes(e.mac.data(), e.mac.size()))
                    return false;
            return count < 2 || entries[0].role != entries[1].role;
        }
        case Step::Confirm:
            return s.integer(entry) && (entry < 2 || entry == kNoEntry) &&
                   s.bytes(mac.data(), mac.size());
        }
        return false;
    }
};

// Client -> server (Channel::Control): an instructor removes a participant from the session (its
// client id), or lets every removed participant join again. A removed participant is sent away
// (RefuseReason::Removed) and refused from its address with the code of its role until then,
// or until the server runs with new codes. The server refuses (counts) a trainee's.
struct Remove {
    static constexpr MessageType kType = MessageType::Remove;
    enum class Op : uint8_t { Remove = 0, AllowRejoin = 1 };
    Op op = Op::Remove;
    uint16_t clientId = 0; // Remove

    template <typename S>
    bool serialize(S& s) {
        return s.ranged(op, Op::Remove, Op::AllowRejoin) && s.integer(clientId);
    }
};

// Client -> server (Channel::ImageLossy, unreliable, newest wins): the newest image of view
// `viewId` the client has applied (full, or a rectangle on its full image). Cumulative: a
// rectangle applies only on the one before it or carries every one not yet acknowledged, so this
// acknowledges all before it; the server forgets them and re-sends what stays unacknowledged
// (net/outbox.h). `unusable` (version 14; 0: none): a newer rectangle that arrived but builds on
// a picture the client does not hold, so one before it was lost. `lossPermille` (version 15): of
// the channel's datagrams the client's host received, those lost per thousand (Host::lossPermille),
// which sizes the parity the server sends them with (net/fragments.h).
struct ImageAck {
    static constexpr MessageType kType = MessageType::ImageAck;
    uint32_t viewId = 0;
    uint32_t sequence = 0;
    uint32_t unusable = 0;
    uint16_t lossPermille = 0;

    template <typename S>
    bool serialize(S& s) {
        return s.integer(viewId) && s.integer(sequence) && s.integer(unusable) &&
               s.ranged(lossPermille, uint16_t(0), uint16_t(1000));
    }
};

// Both ways on Channel::Control (docs/security.md). Issue: an instructor asks the server for a
// new code of `role` (the old one stops working for new connections, and those removed with it
// may rejoin with the new one). Current: the session's codes as the server prints them, sent to
// every instructor at its welcome and after each change, never to a trainee. The server refuses
// (counts) a trainee's Issue, and any in an open session.
struct Codes {
    static constexpr MessageType kType = MessageType::Codes;
    enum class Op : uint8_t { Issue = 0, Current = 1 };
    Op op = Op::Current;
    Role role = Role::Trainee;       // Issue
    std::string trainee, instructor; // Current: at most kMaxCodeTextBytes each

    bool operator==(const Codes&) const = default;
    template <typename S>
    bool serialize(S& s) {
        if (!s.ranged(op, Op::Issue, Op::Current))
            return false;
        if (op == Op::Issue)
            return s.ranged(role, Role::Trainee, Role::Instructor);
        return s.string(trainee, kMaxCodeTextBytes) && s.string(instructor, kMaxCodeTextBytes);
    }
};

struct Ping {
    static constexpr MessageType kType = MessageType::Ping;
    uint64_t clientTimeUs = 0;

    template <typename S>
    bool serialize(S& s) {
        return s.integer(clientTimeUs);
    }
};

struct Pong {
    static constexpr MessageType kType = MessageType::Pong;
    uint64_t clientTimeUs = 0; // echoed
    uint64_t serverTimeUs = 0;

    template <typename S>
    bool serialize(S& s) {
        return s.integer(clientTimeUs) && s.integer(serverTimeUs);
    }
};

// [SECTION] framing: one type byte, then the message; nothing may follow it.

template <typename M>
std::vector<uint8_t> encodeMessage(M& m) {
    std::vector<uint8_t> out;
    out.push_back(uint8_t(M::kType));
    WriteStream w(out);
    if (!m.serialize(w))
        out.clear(); // a value out of range: a programmer mistake the caller sees as empty
    return out;
}

// The type byte of a packet, or 0 when it is empty or unknown.
inline uint8_t peekMessageType(std::span<const uint8_t> packet) {
    if (packet.empty() || packet[0] == 0 || packet[0] >= kMessageTypeCount)
        return 0;
    return packet[0];
}

template <typename M>
bool decodeMessage(std::span<const uint8_t> packet, M& m) {
    if (packet.empty() || packet[0] != uint8_t(M::kType))
        return false;
    ReadStream r(packet.subspan(1));
    return m.serialize(r) && r.atEnd();
}

} // namespace trephine::net

// The scene: what a client needs of the session's volume without its voxels, sent by the server
// once, right after the welcome (MessageType::Scene, Channel::Control): the volume's dims, spacing
// and extent, the named camera presets (computed once by the server, so a preset is one view on
// every client), the burr sites and landmarks, and the patient geometry a client draws over the
// DBI (the surgical field's scalp and drape mesh, compressed). A server saving its session writes
// the same message beside the volume (scenePathFor), and a server started on that volume sends it
// again, so presets and sites survive a save and restart. docs/protocol.md gives the layout.
#pragma once

#include "libsim/camera.h"
#include "libsim/mesh.h"
#include "libsim/volume.h"
#include "net/protocol.h"

#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace trephine::net {

// The scene's own layout version: a scene of another format is refused (malformed).
inline constexpr uint16_t kSceneFormat = 1;
inline constexpr uint16_t kMaxScenePresets = 32;
inline constexpr uint16_t kMaxSceneSites = 16;
inline constexpr uint16_t kMaxSceneLandmarks = 64;
inline constexpr uint32_t kMaxSceneVertices = 1u << 20;
inline constexpr uint32_t kMaxSceneIndices = 3u << 20;
// Bytes a vertex takes in the mesh layout: position and normal 3 x f32 each, colour 4 x u8.
inline constexpr uint32_t kSceneVertexBytes = 28;
// The presets are computed for a square window: the overview presets frame the bounding sphere in
// the smaller field of view, which for a square window is the vertical one.
inline constexpr int kScenePresetSizePx = 500;
// The default burr site's name (the burrhole script aims at it; `--camera site` looks at it).
inline constexpr std::string_view kDefaultSiteName = "burr";
// The surgical-field mesh travels zstd-compressed.
inline constexpr Codec kSceneMeshCodec = Codec::Zstd;

// A named camera without a window size: the client adds its own width and height.
struct ScenePreset {
    std::string name;
    glm::vec3 eye{0, 0, 300}, target{0}, up{0, 1, 0};
    float fovYDeg = 45.0f, nearMm = 10.0f, farMm = 1000.0f;

    template <typename S>
    bool serialize(S& s) {
        return s.string(name, kMaxNameLength) && !name.empty() && serializeVec3(s, eye) &&
               serializeVec3(s, target) && serializeVec3(s, up) && serializeFinite(s, fovYDeg) &&
               serializeFinite(s, nearMm) && serializeFinite(s, farMm) && valid();
    }
    // What ViewSpec::serialize requires of a camera (so every preset can be requested).
    bool valid() const;
    bool operator==(const ScenePreset&) const = default;
};

// A point on the bone and its outward unit normal (a burr site).
struct SceneSite {
    std::string name;
    glm::vec3 position{0}, normal{0, 0, 1};

    template <typename S>
    bool serialize(S& s) {
        return s.string(name, kMaxNameLength) && !name.empty() && serializeVec3(s, position) &&
               ViewSpec::within(position) && serializeVec3(s, normal) &&
               std::abs(glm::dot(normal, normal) - 1.0f) < 1e-3f;
    }
    bool operator==(const SceneSite&) const = default;
};

// A named point of the anatomy (on the outer table), for labels.
struct SceneLandmark {
    std::string name;
    glm::vec3 position{0};

    template <typename S>
    bool serialize(S& s) {
        return s.string(name, kMaxNameLength) && !name.empty() && serializeVec3(s, position) &&
               ViewSpec::within(position);
    }
    bool operator==(const SceneLandmark&) const = default;
};

struct Scene {
    static constexpr MessageType kType = MessageType::Scene;
    uint16_t format = kSceneFormat;
    // FNV-1a 64 of the encoded message with this field 0 (sceneIdOf): one scene, one id, on every
    // client and across a save; a reconnecting client keeps what it built when the id is the same.
    uint64_t sceneId = 0;
    glm::ivec3 dims{1};      // voxels, as the welcome
    glm::vec3 spacing{1.0f}; // mm per voxel, as the welcome
    // dims * spacing (mm): the volume's box, centred on the origin, +z superior, +y anterior, +x
    // the patient's left.
    glm::vec3 extentMm{1.0f};
    std::vector<ScenePreset> presets;     // in increasing name (bytewise)
    std::vector<SceneSite> sites;         // likewise
    std::vector<SceneLandmark> landmarks; // likewise
    // The surgical field: vertexCount vertices and indexCount triangle indices, laid out as in
    // docs/protocol.md (planar, 28 bytes a vertex, then u32 indices), meshRawBytes in all before
    // compression with meshCodec. Empty (0, 0) when the volume holds no skull.
    uint32_t vertexCount = 0, indexCount = 0;
    Codec meshCodec = kSceneMeshCodec;
    uint32_t meshRawBytes = 0;
    std::vector<uint8_t> meshPayload;

    template <typename S>
    bool serialize(S& s) {
        auto byName = [](const auto& e) { return std::string_view(e.name); };
        return s.ranged(format, kSceneFormat, kSceneFormat) && s.integer(sceneId) &&
               s.ranged(dims.x, 1, int(kMaxVolumeDim)) && s.ranged(dims.y, 1, int(kMaxVolumeDim)) &&
               s.ranged(dims.z, 1, int(kMaxVolumeDim)) && serializeSpacing(s, spacing) &&
               serializeVec3(s, extentMm) && extentMatches() &&
               serializeIdList(s, presets, kMaxScenePresets, byName) &&
               serializeIdList(s, sites, kMaxSceneSites, byName) &&
               serializeIdList(s, landmarks, kMaxSceneLandmarks, byName) &&
               s.ranged(vertexCount, uint32_t(0), kMaxSceneVertices) &&
               s.ranged(indexCount, uint32_t(0), kMaxSceneIndices) && indexCount % 3 == 0 &&
               (indexCount == 0 || vertexCount > 0) &&
               s.ranged(meshCodec, Codec::Raw, Codec::Zstd) && s.integer(meshRawBytes) &&
               uint64_t(meshRawBytes) ==
                   uint64_t(vertexCount) * kSceneVertexBytes + uint64_t(indexCount) * 4u &&
               s.blob(meshPayload, kMaxPayloadBytes);
    }
    // extentMm is dims * spacing (to a float's rounding).
    bool extentMatches() const;
    bool operator==(const Scene&) const = default;
};

// [SECTION] building (the server)

// The scene of `volume`: its presets (cameraPresetNames(), `working` looking at the burr site),
// the burr site (defaultBurrSite; for a volume without one, the top of the volume, looking down,
// and no field mesh), the landmarks found on the bone (vertex, Kocher's points), and the surgical
// field around the site. Takes a few milliseconds on a 256^3 skull.
Scene buildScene(const Volume& volume);

// The encoded mesh of `field` (its colours rounded to bytes), set into `scene` with sceneId.
void setSceneMesh(Scene& scene, const MeshData& field);
// Recomputes scene.sceneId from its content.
void stampScene(Scene& scene);
uint64_t sceneIdOf(const Scene& scene);

// [SECTION] reading (the client)

// Decodes a Scene message and checks it whole: ranges, the id against the content, and the mesh
// (decompresses to its raw size, finite floats, positions within kMaxViewDistanceMm, unit-ish
// normals, indices below vertexCount). `field` gets the mesh (colours byte / 255). False when
// anything is wrong: a client drops it and counts it malformed.
bool decodeScene(std::span<const uint8_t> packet, Scene& scene, MeshData* field = nullptr);

// What a client keeps of a scene: the message and its decoded surgical-field mesh.
struct ReceivedScene {
    Scene scene;
    MeshData field;
};

// A preset's camera for a window of `size` pixels; nothing when the scene has no preset `name`.
std::optional<Camera> presetCamera(const Scene& scene, std::string_view name, glm::ivec2 size);
const SceneSite* findSite(const Scene& scene, std::string_view name);
// The radius of the volume's bounding sphere (mm), for near/far planes of orbited views.
float sceneBoundingRadius(const Scene& scene);

// [SECTION] the scene beside a saved volume

// The scene file that goes with a saved volume: VOLUME.scene.
std::string scenePathFor(const std::string& volumePath);
// Writes the encoded scene message after an 8-byte magic ("TRPSCN01") through a ReplacingFile.
// Throws trephine::Error.
void writeSceneFile(const std::string& path, const Scene& scene);
// Reads one back; throws trephine::Error (one line naming the file) when it is not a whole,
// valid scene.
Scene readSceneFile(const std::string& path);
// The scene a server on `volume` serves: the one saved beside `volumeFile` (a regular file; "" for
// built-in volumes) when there is one, else buildScene(volume). A saved scene whose dims or
// spacing differ from the volume's is refused (trephine::Error naming both files).
Scene sceneForVolume(const Volume& volume, const std::string& volumeFile);

} // namespace trephine::net

#include "net/scene.h"

#include "libsim/error.h"
#include "libsim/replacing_file.h"
#include "libsim/skull.h"
#include "net/codec.h"
#include "net/view.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>

namespace trephine::net {

namespace {

constexpr char kSceneMagic[8] = {'T', 'R', 'P', 'S', 'C', 'N', '0', '1'};
constexpr uint64_t kFnvOffset = 0xcbf29ce484222325ull;
constexpr uint64_t kFnvPrime = 0x100000001b3ull;
// The working preset: the burr site from 275 mm along its normal in a 20 degree field of view
// (libsim's cameraPreset("working")).
constexpr float kWorkingDistanceMm = 275.0f;
constexpr float kWorkingFovDeg = 20.0f;

ScenePreset presetOf(const std::string& name, const Camera& c) {
    return {name, c.eye, c.target, c.up, c.fovYDeg, c.nearMm, c.farMm};
}

template <typename T>
void sortByName(std::vector<T>& v) {
    std::sort(v.begin(), v.end(), [](const T& a, const T& b) { return a.name < b.name; });
}

uint8_t colorByte(float c) {
    return uint8_t(std::lround(std::clamp(c, 0.0f, 1.0f) * 255.0f));
}

void putF32(std::vector<uint8_t>& out, float v) {
    uint32_t bits;
    std::memcpy(&bits, &v, 4);
    for (int i = 0; i < 4; ++i)
        out.push_back(uint8_t(bits >> (8 * i)));
}

float getF32(const uint8_t* p) {
    uint32_t bits =
        uint32_t(p[0]) | uint32_t(p[1]) << 8 | uint32_t(p[2]) << 16 | uint32_t(p[3]) << 24;
    float v;
    std::memcpy(&v, &bits, 4);
    return v;
}

uint32_t getU32(const uint8_t* p) {
    return uint32_t(p[0]) | uint32_t(p[1]) << 8 | uint32_t(p[2]) << 16 | uint32_t(p[3]) << 24;
}

} // namespace

bool ScenePreset::valid() const {
    ViewSpec v;
    v.eye = eye;
    v.target = target;
    v.up = up;
    v.fovYDeg = fovYDeg;
    v.nearMm = nearMm;
    v.farMm = farMm;
    v.width = v.height = 1;
    MeasureStream m;
    return v.serialize(m) && fovYDeg > 1.0f && fovYDeg < 179.0f && nearMm > 0.0f &&
           farMm > nearMm && farMm <= kMaxViewFarMm && ViewSpec::within(eye) &&
           ViewSpec::within(target) && v.oriented();
}

bool Scene::extentMatches() const {
    const glm::vec3 want = glm::vec3(dims) * spacing;
    for (int i = 0; i < 3; ++i)
        if (!(std::abs(extentMm[i] - want[i]) <= 1e-4f * std::max(1.0f, want[i])))
            return false;
    return true;
}

// [SECTION] building

void setSceneMesh(Scene& scene, const MeshData& field) {
    const size_t n = field.vertices.size();
    if (n > kMaxSceneVertices || field.indices.size() > kMaxSceneIndices)
        throw Error("scene: the surgical field has " + std::to_string(n) + " vertices and " +
                    std::to_string(field.indices.size()) + " indices; at most " +
                    std::to_string(kMaxSceneVertices) + " and " + std::to_string(kMaxSceneIndices));
    // Planar: each component of every vertex together (x of all, then y of all, ...), so the
    // compressor sees slowly varying runs.
    std::vector<uint8_t> raw;
    raw.reserve(n * kSceneVertexBytes + field.indices.size() * 4);
    for (int c = 0; c < 3; ++c)
        for (const MeshVertex& v : field.vertices)
            putF32(raw, v.position[c]);
    for (int c = 0; c < 3; ++c)
        for (const MeshVertex& v : field.vertices)
            putF32(raw, v.normal[c]);
    for (int c = 0; c < 4; ++c)
        for (const MeshVertex& v : field.vertices)
            raw.push_back(colorByte(v.color[c]));
    for (uint32_t i : field.indices)
        for (int b = 0; b < 4; ++b)
            raw.push_back(uint8_t(i >> (8 * b)));
    scene.vertexCount = uint32_t(n);
    scene.indexCount = uint32_t(field.indices.size());
    scene.meshCodec = kSceneMeshCodec;
    scene.meshRawBytes = uint32_t(raw.size());
    scene.meshPayload = raw.empty() ? std::vector<uint8_t>{} : compressBytes(raw, scene.meshCodec);
}

uint64_t sceneIdOf(const Scene& scene) {
    Scene copy = scene;
    copy.sceneId = 0;
    const std::vector<uint8_t> bytes = encodeMessage(copy);
    uint64_t h = kFnvOffset;
    for (uint8_t b : bytes)
        h = (h ^ b) * kFnvPrime;
    return h;
}

void stampScene(Scene& scene) {
    scene.sceneId = sceneIdOf(scene);
}

Scene buildScene(const Volume& volume) {
    if (volume.empty())
        throw Error("scene: the volume is empty");
    Scene s;
    s.dims = volume.dims();
    s.spacing = volume.spacing();
    s.extentMm = volume.extentMm();
    const glm::ivec2 size(kScenePresetSizePx);
    std::optional<SurfaceSite> site;
    try {
        site = defaultBurrSite(volume);
    } catch (const Error&) {
        // No bone under the top: the presets look at the top of the volume; no field.
    }
    const SurfaceSite aim =
        site ? *site : SurfaceSite{{0.0f, 0.0f, 0.5f * s.extentMm.z}, {0.0f, 0.0f, 1.0f}};
    const float radius = 0.5f * glm::length(s.extentMm);
    for (const std::string& name : cameraPresetNames()) {
        const Camera c = name == "working"
                             ? cameraLookingAt(aim.position, aim.normal, kWorkingDistanceMm,
                                               kWorkingFovDeg, size, radius)
                             : cameraPreset(name, volume, size);
        s.presets.push_back(presetOf(name, c));
    }
    s.sites.push_back({std::string(kDefaultSiteName), aim.position, glm::normalize(aim.normal)});
    const struct {
        const char* name;
        glm::vec2 column;
    } landmarks[] = {{"vertex", {0.0f, 0.0f}},
                     {"kocher-right", {kKocherPointXMm, kKocherPointYMm}},
                     {"kocher-left", {-kKocherPointXMm, kKocherPointYMm}}};
    for (const auto& l : landmarks)
        if (const std::optional<SurfaceSite> p = surfaceSiteBelow(volume, l.column))
            s.landmarks.push_back({l.name, p->position});
    sortByName(s.presets);
    sortByName(s.sites);
    sortByName(s.landmarks);
    setSceneMesh(s, site ? makeSurgicalField(volume, *site) : MeshData{});
    stampScene(s);
    return s;
}

// [SECTION] reading

namespace {

bool decodeMesh(const Scene& s, MeshData& out) {
    out = {};
    if (s.vertexCount == 0 && s.indexCount == 0)
        return s.meshPayload.empty() || s.meshRawBytes == 0;
    std::vector<uint8_t> raw;
    if (!decompressBytes(s.meshPayload, s.meshCodec, s.meshRawBytes, raw))
        return false;
    const size_t n = s.vertexCount;
    out.vertices.resize(n);
    const uint8_t* p = raw.data();
    for (int c = 0; c < 3; ++c)
        for (size_t i = 0; i < n; ++i, p += 4) {
            const float v = getF32(p);
            if (!std::isfinite(v) || std::abs(v) > kMaxViewDistanceMm)
                return false;
            out.vertices[i].position[c] = v;
        }
    for (int c = 0; c < 3; ++c)
        for (size_t i = 0; i < n; ++i, p += 4) {
            const float v = getF32(p);
            if (!std::isfinite(v) || std::abs(v) > 1.001f)
                return false;
            out.vertices[i].normal[c] = v;
        }
    for (int c = 0; c < 4; ++c)
        for (size_t i = 0; i < n; ++i, ++p)
            out.vertices[i].color[c] = float(*p) / 255.0f;
    out.indices.resize(s.indexCount);
    for (uint32_t& index : out.indices) {
        index = getU32(p);
        p += 4;
        if (index >= n)
            return false;
    }
    return true;
}

} // namespace

bool decodeScene(std::span<const uint8_t> packet, Scene& scene, MeshData* field) {
    Scene s;
    if (!decodeMessage(packet, s) || sceneIdOf(s) != s.sceneId)
        return false;
    MeshData mesh;
    if (!decodeMesh(s, mesh))
        return false;
    scene = std::move(s);
    if (field)
        *field = std::move(mesh);
    return true;
}

std::optional<Camera> presetCamera(const Scene& scene, std::string_view name, glm::ivec2 size) {
    for (const ScenePreset& p : scene.presets)
        if (p.name == name) {
            Camera c;
            c.eye = p.eye;
            c.target = p.target;
            c.up = p.up;
            c.fovYDeg = p.fovYDeg;
            c.nearMm = p.nearMm;
            c.farMm = p.farMm;
            c.width = size.x;
            c.height = size.y;
            return c;
        }
    return std::nullopt;
}

const SceneSite* findSite(const Scene& scene, std::string_view name) {
    for (const SceneSite& s : scene.sites)
        if (s.name == name)
            return &s;
    return nullptr;
}

float sceneBoundingRadius(const Scene& scene) {
    return 0.5f * glm::length(scene.extentMm);
}

// [SECTION] the scene beside a saved volume

std::string scenePathFor(const std::string& volumePath) {
    return volumePath + ".scene";
}

void writeSceneFile(const std::string& path, const Scene& scene) {
    Scene copy = scene;
    const std::vector<uint8_t> bytes = encodeMessage(copy);
    if (bytes.empty())
        throw Error("scene file " + path + ": the scene does not encode (a value out of range)");
    ReplacingFile f(path);
    f.stream().write(kSceneMagic, sizeof kSceneMagic);
    f.stream().write(reinterpret_cast<const char*>(bytes.data()), std::streamsize(bytes.size()));
    if (!f.commit())
        throw Error("scene file " + path + ": cannot write it");
}

Scene readSceneFile(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    if (!in)
        throw Error("scene file " + path + ": cannot open it");
    // Bounded: a scene message is at most one payload and its lists.
    std::vector<uint8_t> bytes;
    bytes.reserve(1 << 16);
    char buf[1 << 16];
    while (in.read(buf, sizeof buf) || in.gcount() > 0) {
        bytes.insert(bytes.end(), buf, buf + in.gcount());
        if (bytes.size() > kMaxPayloadBytes + (1u << 20))
            throw Error("scene file " + path + ": larger than any scene");
    }
    if (bytes.size() < sizeof kSceneMagic ||
        std::memcmp(bytes.data(), kSceneMagic, sizeof kSceneMagic) != 0)
        throw Error("scene file " + path + ": not a Trephine scene (no TRPSCN01 header)");
    Scene s;
    if (!decodeScene(std::span<const uint8_t>(bytes).subspan(sizeof kSceneMagic), s))
        throw Error("scene file " + path +
                    ": damaged (it does not read as a whole, valid scene; "
                    "delete it to rebuild the scene from the volume)");
    return s;
}

Scene sceneForVolume(const Volume& volume, const std::string& volumeFile) {
    std::error_code ec;
    if (volumeFile.empty() || !std::filesystem::is_regular_file(scenePathFor(volumeFile), ec))
        return buildScene(volume);
    const std::string path = scenePathFor(volumeFile);
    Scene s = readSceneFile(path);
    if (s.dims != volume.dims() || s.spacing != volume.spacing())
        throw Error("scene file " + path + " is for a volume of " + std::to_string(s.dims.x) + "x" +
                    std::to_string(s.dims.y) + "x" + std::to_string(s.dims.z) + " voxels, not " +
                    volumeFile + "'s " + std::to_string(volume.dims().x) + "x" +
                    std::to_string(volume.dims().y) + "x" + std::to_string(volume.dims().z) +
                    " (or another spacing): delete it to rebuild the scene from the volume");
    return s;
}

} // namespace trephine::net

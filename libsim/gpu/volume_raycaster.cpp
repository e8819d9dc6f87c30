// The GPU ray caster (the window's VolumeView, the server's GPU renderer). It follows
// libsim/src/renderer.cpp step by step (docs/rendering.md, "Ray casting"), with the GPU's texture
// unit doing the trilinear work:
//
// [SECTION] Shaders: one fullscreen triangle; per pixel the CPU renderer's ray, march, refinement,
//           gradient normal, material and headlight shading, and the hit's GL window depth
// [SECTION] Uploads: density and material (R8), gradients (RGB16F, one voxel of apron)
// [SECTION] Drawing: into the bound framebuffer, or into the view's own offscreen target
#include "libsim_gpu/volume_raycaster.h"

#include "libsim_gpu/gl_program.h"

#include "libsim/brick_grid.h"
#include "libsim/error.h"
#include "libsim/renderer.h"

#include <fmt/format.h>

#include <algorithm>
#include <cassert>
#include <chrono>
#include <glm/gtc/type_ptr.hpp>
#include <glm/matrix.hpp>
#include <string>
#include <vector>

namespace trephine::gpu {

namespace {

// [SECTION] Shaders ----------------------------------------------------------------------------

// Voxel coordinates put voxel centres at integers; the density texture's texel i is voxel i, the
// gradient texture's texel i is voxel i - 1 (one voxel of apron on every side). Both clamp to a
// zero border, so voxels outside the volume are air, as in the CPU renderer.
// The ray, everything but the entry point: castRay(window pixel centre) gives the colour and the
// hit's GL window depth. Implicit-LOD lookups are undefined outside fragment shaders, so every
// lookup names level 0 (the textures have no mipmaps: the same texels as texture() there).
const char* kRay = R"(
uniform sampler3D uDensity;  // R8, linear: the trilinear density
uniform sampler3D uMaterial; // R8, fetched
uniform sampler3D uGradient; // RGB16F, linear: central differences interpolated trilinearly
// R8, fetched: per 4^3 brick the largest density of its voxels and the next one up on each axis
// (every voxel a sample whose floor lies in the brick reads), as BrickGrid's maximum
uniform sampler3D uBricks;
uniform ivec3 uBrickDims;
uniform bool uSkip;        // empty-space skipping (the pixels are the same without)
uniform vec3 uDims;
uniform ivec3 uDimsI;
uniform vec3 uOrigin;      // eye, voxel coordinates
uniform vec3 uInvSpacing;  // voxels per mm
uniform vec3 uEye;         // mm
uniform vec4 uFarH, uFarDx, uFarDy; // far-plane point of ndc (x, y): farH + x farDx + y farDy
uniform vec2 uNdcPerPixel;
uniform vec2 uViewportOrigin;
uniform float uNearOverFar;
uniform float uDt;         // sample step, mm
uniform mat4 uViewProj;
uniform vec3 uColor[7];    // materialColor, 0..255
uniform vec4 uShade[7];    // ambient, diffuse, specular, log2 of the shininess
uniform vec4 uBackground;

const float kIso = 128.0;

float density(vec3 p) { return textureLod(uDensity, (p + 0.5) / uDims, 0.0).r * 255.0; }
int voxelDensity(ivec3 v) { return int(texelFetch(uDensity, v, 0).r * 255.0 + 0.5); }
int voxelMaterial(ivec3 v) { return int(texelFetch(uMaterial, v, 0).r * 255.0 + 0.5); }

// Renderer's hitMaterial: the nearest voxel's label, or if that is air the labelled corner of the
// first sample inside nearest the hit (the denser on a tie).
int hitMaterial(vec3 pHit, vec3 pIn) {
    ivec3 v = clamp(ivec3(floor(pHit + 0.5)), ivec3(0), uDimsI - 1);
    int m = voxelMaterial(v);
    if (m != 0)
        return m;
    ivec3 c = ivec3(floor(pIn));
    float bestD2 = 1e30;
    int best = -1;
    for (int i = 0; i < 8; ++i) {
        ivec3 q = c + ivec3(i & 1, (i >> 1) & 1, i >> 2);
        if (any(lessThan(q, ivec3(0))) || any(greaterThanEqual(q, uDimsI)))
            continue;
        int l = voxelMaterial(q);
        if (l == 0)
            continue;
        vec3 e = vec3(q) - pHit;
        float d2 = dot(e, e);
        int d = voxelDensity(q);
        if (d2 < bestD2 || (d2 == bestD2 && d > best)) {
            bestD2 = d2;
            best = d;
            m = l;
        }
    }
    return m == 0 ? 1 : m;
}

vec4 castRay(vec2 windowPixel, out float depth) {
    vec2 ndc = (windowPixel - uViewportOrigin) * uNdcPerPixel - 1.0;
    vec4 h = uFarH + ndc.x * uFarDx + ndc.y * uFarDy;
    vec3 toFar = h.xyz / h.w - uEye;
    float tFar = length(toFar);
    vec3 dir = toFar / tFar;
    vec3 dv = dir * uInvSpacing;
    // Samples where some trilinear corner is inside the volume: voxel coordinates [-1, n].
    float t0 = max(tFar * uNearOverFar, 0.0), t1 = tFar;
    bool outside = false;
    for (int a = 0; a < 3; ++a) {
        if (dv[a] == 0.0) {
            outside = outside || uOrigin[a] < -1.0 || uOrigin[a] > uDims[a];
            continue;
        }
        float ta = (-1.0 - uOrigin[a]) / dv[a], tb = (uDims[a] - uOrigin[a]) / dv[a];
        t0 = max(t0, min(ta, tb));
        t1 = min(t1, max(ta, tb));
    }
    int k = int(ceil(t0 / uDt)), kStart = k, kEnd = int(floor(t1 / uDt));
    float value = 0.0, last = 0.0;
    int lastK = kStart - 2; // the index `last` was sampled at
    bool found = false;
    if (!outside && t0 <= t1) {
        for (; k <= kEnd; ++k) {
            vec3 p = uOrigin + (float(k) * uDt) * dv;
            // A sample whose floor lies in a brick with no density at the iso-value is below it
            // (a trilinear sample is a convex combination of voxels the brick's maximum covers):
            // leap to the last sample before the ray leaves the brick and test that one, which
            // also covers a rounding that put it just past the brick's face. Samples sit at the
            // same k * dt as without skipping, so the first one inside is the same.
            if (uSkip) {
                ivec3 b = clamp(ivec3(floor(p)), ivec3(0), uDimsI - 1) >> 2;
                if (texelFetch(uBricks, b, 0).r * 255.0 < kIso - 0.5) {
                    float tExit = 3.4e38;
                    for (int a = 0; a < 3; ++a) {
                        if (dv[a] > 0.0 && b[a] < uBrickDims[a] - 1)
                            tExit = min(tExit, (float(4 * b[a] + 4) - uOrigin[a]) / dv[a]);
                        else if (dv[a] < 0.0 && b[a] > 0)
                            tExit = min(tExit, (float(4 * b[a]) - uOrigin[a]) / dv[a]);
                    }
                    int kLast = int(min(floor(tExit / uDt), float(kEnd)));
                    if (kLast > k) {
                        k = kLast;
                        p = uOrigin + (float(k) * uDt) * dv;
                    }
                }
            }
            value = density(p);
            if (value >= kIso) {
                found = true;
                break;
            }
            last = value;
            lastK = k;
        }
    }
    if (found && k > kStart && lastK != k - 1) // the sample before the hit was leapt over
        last = density(uOrigin + (float(k - 1) * uDt) * dv);
    if (!found) {
        depth = 1.0;
        return uBackground;
    }
    float tIn = float(k) * uDt, t = tIn;
    if (k > kStart) { // one regula-falsi step with a sample, then the final secant
        float ta = float(k - 1) * uDt, tb = tIn;
        float fa = last - kIso, fb = value - kIso;
        float tm = ta + (tb - ta) * (fa / (fa - fb));
        float fm = density(uOrigin + tm * dv) - kIso;
        if (fm >= 0.0) {
            tb = tm;
            fb = fm;
        } else {
            ta = tm;
            fa = fm;
        }
        t = ta + (tb - ta) * (fa / (fa - fb));
    }
    vec4 clip = uViewProj * vec4(uEye + t * dir, 1.0);
    depth = clamp(clip.z / clip.w * 0.5 + 0.5, 0.0, 1.0);

    vec3 p = uOrigin + t * dv;
    vec3 grad = textureLod(uGradient, (p + 1.5) / (uDims + 2.0), 0.0).xyz * uInvSpacing;
    float len = length(grad);
    vec3 n = len > 0.0 ? -grad / len : -dir;
    int m = hitMaterial(p, uOrigin + tIn * dv);
    vec4 s = uShade[m];
    float ndl = max(0.0, -dot(n, dir));
    float spec = ndl;
    for (int i = 0; i < int(s.w); ++i)
        spec *= spec;
    vec3 c = uColor[m] * (s.x + s.y * ndl) + s.z * spec * 255.0;
    return vec4(min(c, vec3(255.0)) / 255.0, 1.0);
}
)";

// The window's entry: a fullscreen triangle's fragments into the bound framebuffer.
const char* kFsMain = R"(
out vec4 fragColor;
void main() {
    float depth;
    fragColor = castRay(gl_FragCoord.xy, depth);
    gl_FragDepth = depth;
})";

constexpr int kLocalSize = 16; // the compute shader's work group is kLocalSize^2 pixels

// The server's entry: one invocation a pixel of the rectangle, its colour (RGBA8, as a colour
// attachment rounds it) and depth stored in buffers in the rectangle's row order. Compute shaders
// run on every multiprocessor, where compute GPUs (H100, H200) run fragment shaders on a few; and
// on an H200 images a compute shader stored to took 0.84 s to read back through a framebuffer,
// buffers 4 ms (docs/rendering.md, "The GPU renderer").
const char* kCsMain = R"(
layout(local_size_x = 16, local_size_y = 16) in; // kLocalSize
layout(std430, binding = 0) writeonly buffer ColorOut { uint colorOut[]; };
layout(std430, binding = 1) writeonly buffer DepthOut { float depthOut[]; };
uniform ivec2 uSize; // the rectangle's
void main() {
    ivec2 p = ivec2(gl_GlobalInvocationID.xy);
    if (p.x >= uSize.x || p.y >= uSize.y)
        return;
    float depth;
    vec4 c = castRay(vec2(p) + 0.5, depth);
    int i = p.y * uSize.x + p.x;
    colorOut[i] = packUnorm4x8(c);
    depthOut[i] = depth;
})";

// The shading constants of libsim's renderer (materialShade in renderer.cpp), per label.
static_assert(kMaterialCount == 7, "uColor and uShade in the shader hold a vec per material");
constexpr float kShade[kMaterialCount][4] = {
    {0.20f, 0.75f, 0.12f, 5}, // air (never shaded; the default)
    {0.20f, 0.75f, 0.12f, 5}, // cortical
    {0.22f, 0.75f, 0.05f, 4}, // diploe
    {0.22f, 0.75f, 0.15f, 6}, // dura
    {0.22f, 0.75f, 0.12f, 6}, // brain
    {0.22f, 0.75f, 0.15f, 6}, // sinus
    {0.22f, 0.75f, 0.15f, 6}, // artery
};

void setTexParams(GLenum filter) {
    const float border[4] = {0, 0, 0, 0};
    glTexParameteri(GL_TEXTURE_3D, GL_TEXTURE_MIN_FILTER, GLint(filter));
    glTexParameteri(GL_TEXTURE_3D, GL_TEXTURE_MAG_FILTER, GLint(filter));
    for (GLenum w : {GL_TEXTURE_WRAP_S, GL_TEXTURE_WRAP_T, GL_TEXTURE_WRAP_R})
        glTexParameteri(GL_TEXTURE_3D, w, GL_CLAMP_TO_BORDER);
    glTexParameterfv(GL_TEXTURE_3D, GL_TEXTURE_BORDER_COLOR, border);
}

double msSince(std::chrono::steady_clock::time_point t0) {
    return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

// Unpack state for reading a sub-box straight out of a volume-sized array (no copy).
struct UnpackBox {
    UnpackBox(glm::ivec3 dims, glm::ivec3 lo) {
        glPixelStorei(GL_UNPACK_ALIGNMENT, 1);
        glPixelStorei(GL_UNPACK_ROW_LENGTH, dims.x);
        glPixelStorei(GL_UNPACK_IMAGE_HEIGHT, dims.y);
        glPixelStorei(GL_UNPACK_SKIP_PIXELS, lo.x);
        glPixelStorei(GL_UNPACK_SKIP_ROWS, lo.y);
        glPixelStorei(GL_UNPACK_SKIP_IMAGES, lo.z);
    }
    ~UnpackBox() {
        for (GLenum e : {GL_UNPACK_ROW_LENGTH, GL_UNPACK_IMAGE_HEIGHT, GL_UNPACK_SKIP_PIXELS,
                         GL_UNPACK_SKIP_ROWS, GL_UNPACK_SKIP_IMAGES})
            glPixelStorei(e, 0);
    }
};

} // namespace

VolumeRaycaster::VolumeRaycaster(Pipeline pipeline) : m_pipeline(pipeline) {
    if (pipeline == Pipeline::Compute)
        m_program = linkComputeProgram(
            (std::string("#version 430 core\n") + kRay + kCsMain).c_str(), "volume (compute)");
    else
        m_program =
            linkProgram(kFullscreenTriangleVs,
                        (std::string("#version 330 core\n") + kRay + kFsMain).c_str(), "volume");
    glUseProgram(m_program);
    glUniform1i(glGetUniformLocation(m_program, "uDensity"), 0);
    glUniform1i(glGetUniformLocation(m_program, "uMaterial"), 1);
    glUniform1i(glGetUniformLocation(m_program, "uGradient"), 2);
    glUniform1i(glGetUniformLocation(m_program, "uBricks"), 3);
    glm::vec3 colors[kMaterialCount];
    for (int m = 0; m < kMaterialCount; ++m)
        colors[m] = materialColor(Material(m));
    glUniform3fv(glGetUniformLocation(m_program, "uColor"), kMaterialCount,
                 glm::value_ptr(colors[0]));
    glUniform4fv(glGetUniformLocation(m_program, "uShade"), kMaterialCount, &kShade[0][0]);
    glUniform4f(glGetUniformLocation(m_program, "uBackground"), kBackgroundRgba[0] / 255.0f,
                kBackgroundRgba[1] / 255.0f, kBackgroundRgba[2] / 255.0f,
                kBackgroundRgba[3] / 255.0f);
    glUseProgram(0);
    glGenVertexArrays(1, &m_emptyVao); // a core profile draws nothing without a bound VAO
}

VolumeRaycaster::~VolumeRaycaster() {
    GLuint tex[] = {m_densityTex, m_materialTex, m_gradientTex, m_brickTex, m_fboColor};
    glDeleteTextures(5, tex);
    glDeleteRenderbuffers(1, &m_fboDepth);
    GLuint buffers[] = {m_outColor, m_outDepth};
    glDeleteBuffers(2, buffers);
    glDeleteFramebuffers(1, &m_fbo);
    glDeleteVertexArrays(1, &m_emptyVao);
    glDeleteProgram(m_program);
}

// [SECTION] Uploads ----------------------------------------------------------------------------

void VolumeRaycaster::upload(const Volume& volume) {
    if (volume.empty())
        throw Error("gpu: VolumeRaycaster::upload: the volume is empty");
    // The gradient texture holds an apron of one voxel on every side: n + 2 texels an axis.
    GLint maxSize = 0;
    glGetIntegerv(GL_MAX_3D_TEXTURE_SIZE, &maxSize);
    const glm::ivec3 d = volume.dims();
    if (std::max({d.x, d.y, d.z}) + 2 > maxSize)
        throw Error("gpu: the volume (" + std::to_string(d.x) + " x " + std::to_string(d.y) +
                    " x " + std::to_string(d.z) + ") is too large for this OpenGL's 3D textures (" +
                    std::to_string(maxSize) + " texels an axis, less 2 for the gradients' apron)");
    clearGlErrors();
    m_dims = volume.dims();
    m_spacing = volume.spacing();
    auto make = [&](GLuint& tex, GLenum internal, glm::ivec3 size, GLenum format, GLenum type,
                    GLenum filter, const void* data) {
        if (!tex)
            glGenTextures(1, &tex);
        glBindTexture(GL_TEXTURE_3D, tex);
        glPixelStorei(GL_UNPACK_ALIGNMENT, 1);
        glTexImage3D(GL_TEXTURE_3D, 0, GLint(internal), size.x, size.y, size.z, 0, format, type,
                     data);
        setTexParams(filter);
    };
    make(m_densityTex, GL_R8, m_dims, GL_RED, GL_UNSIGNED_BYTE, GL_LINEAR, volume.densityData());
    make(m_materialTex, GL_R8, m_dims, GL_RED, GL_UNSIGNED_BYTE, GL_NEAREST, volume.materialData());
    make(m_gradientTex, GL_RGB16F, m_dims + 2, GL_RGB, GL_FLOAT, GL_LINEAR, nullptr);
    uploadGradients(volume, {glm::ivec3(-1), m_dims + 1});
    m_brickDims = (m_dims + 3) / 4;
    make(m_brickTex, GL_R8, m_brickDims, GL_RED, GL_UNSIGNED_BYTE, GL_NEAREST, nullptr);
    uploadBricks(volume, {glm::ivec3(0), m_brickDims});
    glBindTexture(GL_TEXTURE_3D, 0);
    // Out of memory (256^3 takes ~140 MB of textures) or a size the driver refuses: say so
    // rather than draw a blank or flat-shaded volume.
    try {
        throwIfGlRefused("the volume's textures");
    } catch (...) {
        m_dims = glm::ivec3(0);
        throw;
    }
}

VolumeUpdateStats VolumeRaycaster::updateBox(const Volume& volume, const Box3i& box) {
    VolumeUpdateStats stats;
    if (empty() || volume.dims() != m_dims)
        throw Error("gpu: VolumeRaycaster::updateBox: the volume is not the one uploaded");
    Box3i b = box.intersect(volume.bounds());
    if (b.empty())
        return stats;
    auto t0 = std::chrono::steady_clock::now();
    glm::ivec3 s = b.size();
    {
        UnpackBox unpack(m_dims, b.lo);
        glBindTexture(GL_TEXTURE_3D, m_densityTex);
        glTexSubImage3D(GL_TEXTURE_3D, 0, b.lo.x, b.lo.y, b.lo.z, s.x, s.y, s.z, GL_RED,
                        GL_UNSIGNED_BYTE, volume.densityData());
        glBindTexture(GL_TEXTURE_3D, m_materialTex);
        glTexSubImage3D(GL_TEXTURE_3D, 0, b.lo.x, b.lo.y, b.lo.z, s.x, s.y, s.z, GL_RED,
                        GL_UNSIGNED_BYTE, volume.materialData());
    }
    stats.voxels = b.count();
    stats.voxelUploadMs = msSince(t0);
    auto t1 = std::chrono::steady_clock::now();
    // A changed voxel enters the central differences of its six face neighbours.
    Box3i g{glm::max(b.lo - 1, glm::ivec3(-1)), glm::min(b.hi + 1, m_dims + 1)};
    uploadGradients(volume, g);
    stats.gradientVoxels = g.count();
    // The bricks whose maximum reads a changed voxel: brick c covers voxels [4c, 4c + 5).
    uploadBricks(volume, {glm::max((b.lo - 4 + 3) / 4, glm::ivec3(0)),
                          glm::min((b.hi - 1) / 4 + 1, m_brickDims)});
    stats.gradientMs = msSince(t1);
    glBindTexture(GL_TEXTURE_3D, 0);
    return stats;
}

// Gradients of the voxels in `box` (volume coordinates in [-1, n], the apron included), computed
// as the CPU renderer's gradientAt does at a voxel: half the central differences, air outside.
// Done in slabs of z so a full upload never holds more than a few MB.
void VolumeRaycaster::uploadGradients(const Volume& volume, const Box3i& box) {
    const glm::ivec3 n = m_dims;
    const uint8_t* d = volume.densityData();
    const ptrdiff_t sy = n.x, sz = ptrdiff_t(n.x) * n.y;
    auto at = [&](int x, int y, int z) -> float {
        if (unsigned(x) >= unsigned(n.x) || unsigned(y) >= unsigned(n.y) ||
            unsigned(z) >= unsigned(n.z))
            return 0.0f;
        return float(d[x + sy * y + sz * z]);
    };
    const glm::ivec3 s = box.size();
    const int slab = std::max(1, int((1 << 20) / std::max<int64_t>(1, int64_t(s.x) * s.y)));
    std::vector<float> buf;
    glBindTexture(GL_TEXTURE_3D, m_gradientTex);
    glPixelStorei(GL_UNPACK_ALIGNMENT, 1);
    for (int z0 = box.lo.z; z0 < box.hi.z; z0 += slab) {
        int z1 = std::min(box.hi.z, z0 + slab);
        buf.resize(size_t(s.x) * size_t(s.y) * size_t(z1 - z0) * 3);
        float* o = buf.data();
        for (int z = z0; z < z1; ++z)
            for (int y = box.lo.y; y < box.hi.y; ++y) {
                bool interior = z >= 1 && y >= 1 && z + 1 < n.z && y + 1 < n.y;
                for (int x = box.lo.x; x < box.hi.x; ++x, o += 3) {
                    if (interior && x >= 1 && x + 1 < n.x) {
                        const uint8_t* p = d + x + sy * y + sz * z;
                        o[0] = 0.5f * (float(p[1]) - float(p[-1]));
                        o[1] = 0.5f * (float(p[sy]) - float(p[-sy]));
                        o[2] = 0.5f * (float(p[sz]) - float(p[-sz]));
                    } else {
                        o[0] = 0.5f * (at(x + 1, y, z) - at(x - 1, y, z));
                        o[1] = 0.5f * (at(x, y + 1, z) - at(x, y - 1, z));
                        o[2] = 0.5f * (at(x, y, z + 1) - at(x, y, z - 1));
                    }
                }
            }
        glTexSubImage3D(GL_TEXTURE_3D, 0, box.lo.x + 1, box.lo.y + 1, z0 + 1, s.x, s.y, z1 - z0,
                        GL_RGB, GL_FLOAT, buf.data());
    }
}

// The largest density of each brick in `bricks` (brick coordinates, half-open) over its voxels
// and the next one up on each axis, as BrickGrid's maximum, uploaded to the brick texture.
void VolumeRaycaster::uploadBricks(const Volume& volume, const Box3i& bricks) {
    static_assert(BrickGrid::kSize == 4 && BrickGrid::kApronLo == 0 && BrickGrid::kApronHi == 1,
                  "the shader's bricks (4^3, brick b from floor(p) >> 2) are BrickGrid's");
    if (bricks.empty())
        return;
    std::vector<uint8_t> maxima;
    BrickGrid::regionMax(volume, bricks.lo, bricks.hi - 1, maxima);
    const glm::ivec3 s = bricks.size();
    glBindTexture(GL_TEXTURE_3D, m_brickTex);
    glPixelStorei(GL_UNPACK_ALIGNMENT, 1);
    glTexSubImage3D(GL_TEXTURE_3D, 0, bricks.lo.x, bricks.lo.y, bricks.lo.z, s.x, s.y, s.z, GL_RED,
                    GL_UNSIGNED_BYTE, maxima.data());
}

// [SECTION] Drawing ----------------------------------------------------------------------------

// The program's per-view uniforms (the program in use); `viewportOrigin` is the window pixel
// position of the view's corner.
void VolumeRaycaster::setUniforms(const Camera& camera, glm::vec2 viewportOrigin) {
    // The CPU renderer's frame set-up (makeFrame): matrices in double from the float ones.
    const glm::dmat4 vp = viewProjection(camera);
    const glm::dmat4 inv = glm::inverse(vp);
    const glm::vec4 farH(inv * glm::dvec4(0, 0, 1, 1)), farDx(inv * glm::dvec4(1, 0, 0, 0)),
        farDy(inv * glm::dvec4(0, 1, 0, 0));
    const glm::vec3 origin(glm::dvec3(camera.eye) / glm::dvec3(m_spacing) +
                           glm::dvec3(m_dims) * 0.5 - 0.5);
    const float minSpacing = std::min({m_spacing.x, m_spacing.y, m_spacing.z});
    const glm::mat4 vpf(vp);

    auto loc = [&](const char* name) { return glGetUniformLocation(m_program, name); };
    glUniform3f(loc("uDims"), float(m_dims.x), float(m_dims.y), float(m_dims.z));
    glUniform3i(loc("uDimsI"), m_dims.x, m_dims.y, m_dims.z);
    glUniform3fv(loc("uOrigin"), 1, glm::value_ptr(origin));
    glm::vec3 invSpacing = 1.0f / m_spacing;
    glUniform3fv(loc("uInvSpacing"), 1, glm::value_ptr(invSpacing));
    glUniform3fv(loc("uEye"), 1, glm::value_ptr(camera.eye));
    glUniform4fv(loc("uFarH"), 1, glm::value_ptr(farH));
    glUniform4fv(loc("uFarDx"), 1, glm::value_ptr(farDx));
    glUniform4fv(loc("uFarDy"), 1, glm::value_ptr(farDy));
    glUniform2f(loc("uNdcPerPixel"), 2.0f / float(camera.width), 2.0f / float(camera.height));
    glUniform2f(loc("uViewportOrigin"), viewportOrigin.x, viewportOrigin.y);
    glUniform1f(loc("uNearOverFar"), float(double(camera.nearMm) / double(camera.farMm)));
    glUniform1f(loc("uDt"), std::max(1e-3f, m_stepVoxels) * minSpacing);
    glUniformMatrix4fv(loc("uViewProj"), 1, GL_FALSE, glm::value_ptr(vpf));

    glUniform3i(loc("uBrickDims"), m_brickDims.x, m_brickDims.y, m_brickDims.z);
    glUniform1i(loc("uSkip"), m_skipEmpty ? 1 : 0);
}

void VolumeRaycaster::bindVolume() {
    const GLuint tex[4] = {m_densityTex, m_materialTex, m_gradientTex, m_brickTex};
    for (int i = 0; i < 4; ++i) {
        glActiveTexture(GLenum(GL_TEXTURE0 + i));
        glBindTexture(GL_TEXTURE_3D, tex[i]);
    }
}

void VolumeRaycaster::draw(const Camera& camera) {
    if (m_pipeline != Pipeline::Fragment)
        throw Error("gpu: VolumeRaycaster::draw needs the fragment pipeline");
    if (empty())
        return;
    GLint program = 0, vao = 0, depthFunc = GL_LESS, active = GL_TEXTURE0, viewport[4] = {};
    glGetIntegerv(GL_CURRENT_PROGRAM, &program);
    glGetIntegerv(GL_VERTEX_ARRAY_BINDING, &vao);
    glGetIntegerv(GL_DEPTH_FUNC, &depthFunc);
    glGetIntegerv(GL_ACTIVE_TEXTURE, &active);
    glGetIntegerv(GL_VIEWPORT, viewport);
    glUseProgram(m_program);
    setUniforms(camera, {float(viewport[0]), float(viewport[1])});
    bindVolume();
    glDisable(GL_BLEND);
    glEnable(GL_DEPTH_TEST);
    glDepthMask(GL_TRUE);
    glDepthFunc(GL_ALWAYS);
    glBindVertexArray(m_emptyVao);
    glDrawArrays(GL_TRIANGLES, 0, 3);

    glDepthFunc(GLenum(depthFunc));
    glBindVertexArray(GLuint(vao));
    glActiveTexture(GLenum(active));
    glUseProgram(GLuint(program));
}

void VolumeRaycaster::ensureTarget(int width, int height) {
    if (m_fbo && width <= m_fboWidth && height <= m_fboHeight)
        return;
    const int w = std::max(width, m_fboWidth), h = std::max(height, m_fboHeight);
    m_fboWidth = m_fboHeight = 0; // until the new target is made: a refused one is not kept
    makeColorDepthTarget(m_fbo, m_fboColor, m_fboDepth, w, h, "volume ray caster's");
    m_fboWidth = w;
    m_fboHeight = h;
}

// The compute pipeline's buffers hold exactly the rectangle: on an H200, reading a 1920 x 4
// band out of buffers sized for 1920 x 1080 took 1.6 ms, as much as a third of reading them
// whole. Leaves its buffer bound (render() restores the binding it found).
void VolumeRaycaster::sizeOutput(int64_t pixels) {
    if (pixels == m_outPixels)
        return;
    GLint64 most = 0;
    glGetInteger64v(GL_MAX_SHADER_STORAGE_BLOCK_SIZE, &most);
    if (pixels * 4 > most)
        throw Error(fmt::format("gpu: a rectangle of {} pixels is over this OpenGL's shader "
                                "storage blocks ({} bytes)",
                                pixels, most));
    clearGlErrors();
    for (GLuint* b : {&m_outColor, &m_outDepth}) {
        if (!*b)
            glGenBuffers(1, b);
        glBindBuffer(GL_SHADER_STORAGE_BUFFER, *b);
        glBufferData(GL_SHADER_STORAGE_BUFFER, GLsizeiptr(pixels) * 4, nullptr, GL_STREAM_READ);
    }
    m_outPixels = 0;
    throwIfGlRefused(fmt::format("{} pixels of output buffers", pixels));
    m_outPixels = pixels;
}

void VolumeRaycaster::render(const Camera& camera) {
    render(camera, {0, 0, camera.width, camera.height});
}

// The viewport is the whole window shifted so that the rectangle's corner lands on the target's
// corner; draw() takes the pixel position from it, so a pixel's ray does not depend on the
// rectangle. The scissor keeps a larger target's other pixels unrendered.
void VolumeRaycaster::render(const Camera& camera, const PixelRect& rect) {
    const PixelRect r = intersect(rect, {0, 0, camera.width, camera.height});
    // Nothing uploaded, nothing cast (or a cast GL refused): readBack then writes nothing rather
    // than an older render.
    m_rendered = {};
    if (empty() || r.empty())
        return;
    if (m_pipeline == Pipeline::Compute) {
        GLint program = 0, active = GL_TEXTURE0, storage = 0;
        glGetIntegerv(GL_CURRENT_PROGRAM, &program);
        glGetIntegerv(GL_ACTIVE_TEXTURE, &active);
        glGetIntegerv(GL_SHADER_STORAGE_BUFFER_BINDING, &storage);
        sizeOutput(r.area());
        glUseProgram(m_program);
        setUniforms(camera, {float(-r.x), float(-r.y)});
        glUniform2i(glGetUniformLocation(m_program, "uSize"), r.w, r.h);
        bindVolume();
        glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 0, m_outColor);
        glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 1, m_outDepth);
        glDispatchCompute(GLuint((r.w + kLocalSize - 1) / kLocalSize),
                          GLuint((r.h + kLocalSize - 1) / kLocalSize), 1);
        glMemoryBarrier(GL_BUFFER_UPDATE_BARRIER_BIT); // the stores are read back next
        glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 0, 0);
        glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 1, 0);
        glBindBuffer(GL_SHADER_STORAGE_BUFFER, GLuint(storage));
        glActiveTexture(GLenum(active));
        glUseProgram(GLuint(program));
        m_rendered = r;
        return;
    }
    // The viewport is the whole window's: a window over the GL's viewport would be clipped.
    GLint viewportMost[2] = {};
    glGetIntegerv(GL_MAX_VIEWPORT_DIMS, viewportMost);
    if (camera.width > viewportMost[0] || camera.height > viewportMost[1])
        throw Error(fmt::format("gpu: a {} x {} view is over this OpenGL's viewport ({} x {})",
                                camera.width, camera.height, viewportMost[0], viewportMost[1]));
    ensureTarget(r.w, r.h);
    glBindFramebuffer(GL_FRAMEBUFFER, m_fbo);
    glViewport(-r.x, -r.y, camera.width, camera.height);
    glEnable(GL_SCISSOR_TEST);
    glScissor(0, 0, r.w, r.h);
    draw(camera);
    glDisable(GL_SCISSOR_TEST);
    glBindFramebuffer(GL_FRAMEBUFFER, 0);
    m_rendered = r;
}

Dbi VolumeRaycaster::readBack() {
    Dbi out(m_rendered.w, m_rendered.h);
    readInto(out, 0, 0);
    return out;
}

void VolumeRaycaster::readBack(Dbi& frame) {
    readInto(frame, m_rendered.x, m_rendered.y);
}

// The last render's pixels (at the target's corner) into `out` with their corner at (x, y).
void VolumeRaycaster::readInto(Dbi& out, int x, int y) {
    const PixelRect r = m_rendered;
    if (r.empty() || (m_pipeline == Pipeline::Compute ? m_outPixels != r.area() : !m_fbo))
        return;
    assert(out.bounds().contains(PixelRect{x, y, r.w, r.h}) &&
           "VolumeRaycaster::readBack: the image does not hold the rendered rectangle");
    if (m_pipeline == Pipeline::Compute) {
        // Rows of the rectangle are contiguous in the buffers, and in the image too when the
        // rectangle spans it (a full frame, a band of rows): then one read each.
        const bool spans = r.w == out.width();
        const GLsizeiptr row = GLsizeiptr(r.w) * 4;
        GLint storage = 0;
        glGetIntegerv(GL_SHADER_STORAGE_BUFFER_BINDING, &storage);
        auto read = [&](GLuint buffer, auto at) {
            glBindBuffer(GL_SHADER_STORAGE_BUFFER, buffer);
            if (spans)
                glGetBufferSubData(GL_SHADER_STORAGE_BUFFER, 0, row * r.h, at(y));
            else
                for (int j = 0; j < r.h; ++j)
                    glGetBufferSubData(GL_SHADER_STORAGE_BUFFER, row * j, row, at(y + j));
        };
        read(m_outColor, [&](int yy) { return static_cast<void*>(out.color(x, yy)); });
        read(m_outDepth,
             [&](int yy) { return static_cast<void*>(out.depth() + out.index(x, yy)); });
        glBindBuffer(GL_SHADER_STORAGE_BUFFER, GLuint(storage));
        return;
    }
    glBindFramebuffer(GL_READ_FRAMEBUFFER, m_fbo);
    glPixelStorei(GL_PACK_ALIGNMENT, 1);
    glPixelStorei(GL_PACK_ROW_LENGTH, out.width()); // straight into the image's rows
    glReadPixels(0, 0, r.w, r.h, GL_RGBA, GL_UNSIGNED_BYTE, out.color(x, y));
    glReadPixels(0, 0, r.w, r.h, GL_DEPTH_COMPONENT, GL_FLOAT, out.depth() + out.index(x, y));
    glPixelStorei(GL_PACK_ROW_LENGTH, 0);
    glBindFramebuffer(GL_READ_FRAMEBUFFER, 0);
}

} // namespace trephine::gpu

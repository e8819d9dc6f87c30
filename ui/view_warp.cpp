#include "ui/view_warp.h"

#include "libsim/dbi.h"
#include "ui/gl_program.h"

#include <glm/gtc/type_ptr.hpp>
#include <glm/mat4x4.hpp>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>

namespace trephine::ui {

namespace {

constexpr GLuint kRestart = 0xFFFFFFFFu;

// One vertex per grid point at its old window position; its depth is fetched here, so the grid
// stays the same while the DBI's pixels change. A background vertex sits on the nearest bone
// around it (the silhouette moves with the bone), or, far from bone, at the target's depth (its
// triangles stay small, and are discarded).
const char* kWarpVs = R"(#version 330 core
layout(location = 0) in vec2 aOld;
uniform sampler2D uDepth;
uniform ivec2 uDbiSize;
uniform int uStep;
uniform float uBgDepth;
uniform vec2 uNearFar;
uniform mat4 uWarp;
uniform mat4 uUnproject;
out vec2 vOld;
out float vEye;
out vec3 vWorld;
void main() {
    ivec2 p = clamp(ivec2(floor(aOld)), ivec2(0), uDbiSize - 1);
    float d = texelFetch(uDepth, p, 0).r;
    if (d >= 1.0) {
        float nearest = 1.0;
        for (int dy = -1; dy <= 1; ++dy)
            for (int dx = -1; dx <= 1; ++dx)
                nearest = min(nearest, texelFetch(uDepth, clamp(p + ivec2(dx, dy) * uStep,
                                                                ivec2(0), uDbiSize - 1), 0).r);
        d = nearest < 1.0 ? nearest : uBgDepth;
    }
    vOld = aOld;
    vec4 world = uUnproject * vec4(aOld, d, 1.0);
    vWorld = world.xyz / world.w;
    vEye = uNearFar.x * uNearFar.y / (uNearFar.y - d * (uNearFar.y - uNearFar.x));
    gl_Position = uWarp * vec4(aOld, d, 1.0);
})";

// Within one grid triangle the old eye distance is affine in the old position, so the screen
// derivatives give its slope per old pixel exactly: a steep one is a depth jump. A stretched
// jump (the new pixel covers under half an old one) is a hole the nearer surface uncovered: it
// shows the farther side, one grid step down the slope.
const char* kWarpFs = R"(#version 330 core
in vec2 vOld;
in float vEye;
in vec3 vWorld;
uniform sampler2D uColor;
uniform sampler2D uDepth;
uniform ivec2 uDbiSize;
uniform int uStep;
uniform float uBreak;
uniform bool uBilinear;
uniform bool uRelight;
uniform vec3 uEyeOld, uEyeNew;
out vec4 fragColor;
// The server's headlight moved with the eye: a surface's diffuse and specular terms are taken
// off with the old light direction and put back with the new (ambient 0.21, diffuse 0.75,
// specular 0.12 at exponent 32, libsim's shades on average), the facet's normal from the mesh.
vec3 relit(vec3 c, vec3 n) {
    float len = length(n);
    if (len <= 0.0)
        return c;
    n /= len;
    float co = abs(dot(n, normalize(uEyeOld - vWorld)));
    float cn = abs(dot(n, normalize(uEyeNew - vWorld)));
    float so = 0.12 * pow(co, 32.0), sn = 0.12 * pow(cn, 32.0);
    return max(c - so, 0.0) * ((0.21 + 0.75 * cn) / (0.21 + 0.75 * co)) + sn;
}
ivec2 pixelAt(vec2 p) { return clamp(ivec2(floor(p)), ivec2(0), uDbiSize - 1); }
void main() {
    vec2 ox = dFdx(vOld), oy = dFdy(vOld);
    float ex = dFdx(vEye), ey = dFdy(vEye);
    vec3 normal = cross(dFdx(vWorld), dFdy(vWorld));
    if (texelFetch(uDepth, pixelAt(vOld), 0).r >= 1.0)
        discard; // the background's clear colour
    float det = ox.x * oy.y - ox.y * oy.x;
    bool degenerate = abs(det) < 1e-12;
    vec2 slope = degenerate ? vec2(0.0) : vec2(ex * oy.y - ey * ox.y, ey * ox.x - ex * oy.x) / det;
    bool jump = degenerate || abs(slope.x) + abs(slope.y) > uBreak * vEye;
    vec2 at = vOld;
    if (jump && !degenerate && abs(det) < 0.5)
        at += normalize(slope) * float(uStep);
    vec3 c = uBilinear && !jump ? texture(uColor, vOld / vec2(uDbiSize)).rgb
                                : texelFetch(uColor, pixelAt(at), 0).rgb;
    if (uRelight && !jump)
        c = relit(c, normal);
    fragColor = vec4(c, 1.0);
})";

// Grid coordinates along one axis of `n` pixels: the edge, every step-th pixel centre, the last
// centre, the other edge.
std::vector<float> gridAxis(int n, int step) {
    std::vector<float> a{0.0f};
    for (int i = 0; i < n; i += step)
        a.push_back(float(i) + 0.5f);
    if (a.back() != float(n) - 0.5f)
        a.push_back(float(n) - 0.5f);
    a.push_back(float(n));
    return a;
}

} // namespace

ViewWarp::ViewWarp() {
    m_program = linkProgram(kWarpVs, kWarpFs, "view warp");
    m_uWarp = glGetUniformLocation(m_program, "uWarp");
    m_uDbiSize = glGetUniformLocation(m_program, "uDbiSize");
    m_uStep = glGetUniformLocation(m_program, "uStep");
    m_uBgDepth = glGetUniformLocation(m_program, "uBgDepth");
    m_uNearFar = glGetUniformLocation(m_program, "uNearFar");
    m_uBreak = glGetUniformLocation(m_program, "uBreak");
    m_uColor = glGetUniformLocation(m_program, "uColor");
    m_uDepth = glGetUniformLocation(m_program, "uDepth");
    m_uBilinear = glGetUniformLocation(m_program, "uBilinear");
    m_uUnproject = glGetUniformLocation(m_program, "uUnproject");
    m_uRelight = glGetUniformLocation(m_program, "uRelight");
    m_uEyeOld = glGetUniformLocation(m_program, "uEyeOld");
    m_uEyeNew = glGetUniformLocation(m_program, "uEyeNew");
    glGenSamplers(1, &m_linear);
    glSamplerParameteri(m_linear, GL_TEXTURE_MIN_FILTER, GL_LINEAR);
    glSamplerParameteri(m_linear, GL_TEXTURE_MAG_FILTER, GL_LINEAR);
    glSamplerParameteri(m_linear, GL_TEXTURE_WRAP_S, GL_CLAMP_TO_EDGE);
    glSamplerParameteri(m_linear, GL_TEXTURE_WRAP_T, GL_CLAMP_TO_EDGE);
}

ViewWarp::~ViewWarp() {
    glDeleteBuffers(1, &m_vbo);
    glDeleteBuffers(1, &m_ibo);
    glDeleteVertexArrays(1, &m_vao);
    glDeleteSamplers(1, &m_linear);
    glDeleteProgram(m_program);
}

void ViewWarp::buildGrid(glm::ivec2 size, int step) {
    const std::vector<float> xs = gridAxis(size.x, step), ys = gridAxis(size.y, step);
    std::vector<glm::vec2> vertices;
    vertices.reserve(xs.size() * ys.size());
    for (float y : ys)
        for (float x : xs)
            vertices.emplace_back(x, y);
    // One triangle strip per row of cells, joined by the restart index.
    const auto cols = GLuint(xs.size());
    std::vector<GLuint> indices;
    indices.reserve((ys.size() - 1) * (2 * xs.size() + 1));
    for (GLuint r = 0; r + 1 < GLuint(ys.size()); ++r) {
        for (GLuint c = 0; c < cols; ++c) {
            indices.push_back((r + 1) * cols + c);
            indices.push_back(r * cols + c);
        }
        indices.push_back(kRestart);
    }
    if (!m_vao) {
        glGenVertexArrays(1, &m_vao);
        glGenBuffers(1, &m_vbo);
        glGenBuffers(1, &m_ibo);
    }
    glBindVertexArray(m_vao);
    glBindBuffer(GL_ARRAY_BUFFER, m_vbo);
    glBufferData(GL_ARRAY_BUFFER, GLsizeiptr(vertices.size() * sizeof(glm::vec2)), vertices.data(),
                 GL_STATIC_DRAW);
    glBindBuffer(GL_ELEMENT_ARRAY_BUFFER, m_ibo);
    glBufferData(GL_ELEMENT_ARRAY_BUFFER, GLsizeiptr(indices.size() * sizeof(GLuint)),
                 indices.data(), GL_STATIC_DRAW);
    glEnableVertexAttribArray(0);
    glVertexAttribPointer(0, 2, GL_FLOAT, GL_FALSE, sizeof(glm::vec2), nullptr);
    glBindVertexArray(0);
    m_indexCount = GLsizei(indices.size());
    m_gridSize = size;
    m_gridStep = step;
}

void ViewWarp::draw(GLuint colorTex, GLuint depthTex, const Camera& dbiCamera,
                    const Camera& camera) {
    const glm::ivec2 size(dbiCamera.width, dbiCamera.height);
    const int step = std::max(1, m_options.gridStep);
    if (size != m_gridSize || step != m_gridStep)
        buildGrid(size, step);
    // Old window (x, y, depth, 1) -> old NDC -> object space -> new clip space, composed in
    // double from the float matrices both cameras give GL.
    glm::dmat4 toNdc(1.0);
    toNdc[0][0] = 2.0 / size.x;
    toNdc[1][1] = 2.0 / size.y;
    toNdc[2][2] = 2.0;
    toNdc[3] = glm::dvec4(-1.0, -1.0, -1.0, 1.0);
    const glm::dmat4 oldVp = viewProjection(dbiCamera);
    const glm::dmat4 unproject = glm::inverse(oldVp) * toNdc;
    const glm::mat4 warp(viewProjection(camera) * unproject);
    const float bgDepth = std::min(windowDepth(oldVp, glm::dvec3(dbiCamera.target)), 0.999f);
    const float pixelAngle =
        2.0f * std::tan(glm::radians(dbiCamera.fovYDeg) * 0.5f) / float(size.y);

    glClearColor(float(kBackgroundRgba[0]) / 255.0f, float(kBackgroundRgba[1]) / 255.0f,
                 float(kBackgroundRgba[2]) / 255.0f, 1.0f);
    glClearDepth(1.0);
    glDepthMask(GL_TRUE);
    glClear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);
    glEnable(GL_DEPTH_TEST);
    glDepthFunc(GL_LESS);
    glUseProgram(m_program);
    glUniformMatrix4fv(m_uWarp, 1, GL_FALSE, glm::value_ptr(warp));
    glUniform2i(m_uDbiSize, size.x, size.y);
    glUniform1i(m_uStep, step);
    glUniform1f(m_uBgDepth, bgDepth);
    glUniform2f(m_uNearFar, dbiCamera.nearMm, dbiCamera.farMm);
    glUniform1f(m_uBreak, m_options.breakSlope * pixelAngle);
    glUniform1i(m_uBilinear, m_options.bilinear ? 1 : 0);
    glUniformMatrix4fv(m_uUnproject, 1, GL_FALSE, glm::value_ptr(glm::mat4(unproject)));
    glUniform1i(m_uRelight, m_options.relight && dbiCamera.eye != camera.eye ? 1 : 0);
    glUniform3fv(m_uEyeOld, 1, glm::value_ptr(dbiCamera.eye));
    glUniform3fv(m_uEyeNew, 1, glm::value_ptr(camera.eye));
    glUniform1i(m_uColor, 0);
    glUniform1i(m_uDepth, 1);
    glActiveTexture(GL_TEXTURE0);
    glBindTexture(GL_TEXTURE_2D, colorTex);
    glBindSampler(0, m_linear); // texelFetch ignores it; the bilinear lookup needs it
    glActiveTexture(GL_TEXTURE1);
    glBindTexture(GL_TEXTURE_2D, depthTex);
    glEnable(GL_PRIMITIVE_RESTART);
    glPrimitiveRestartIndex(kRestart);
    glBindVertexArray(m_vao);
    glDrawElements(GL_TRIANGLE_STRIP, m_indexCount, GL_UNSIGNED_INT, nullptr);
    glBindVertexArray(0);
    glDisable(GL_PRIMITIVE_RESTART);
    glBindTexture(GL_TEXTURE_2D, 0);
    glActiveTexture(GL_TEXTURE0);
    glBindSampler(0, 0);
    glBindTexture(GL_TEXTURE_2D, 0);
    glUseProgram(0);
}

} // namespace trephine::ui

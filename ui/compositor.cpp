#include "ui/compositor.h"

#include "libsim/error.h"
#include "ui/gl_program.h"

#include <glm/gtc/type_ptr.hpp>
#include <string>

namespace trephine::ui {

namespace {

const char* kMeshVs = R"(#version 330 core
layout(location = 0) in vec3 aPos;
layout(location = 1) in vec3 aNormal;
layout(location = 2) in vec4 aColor;
uniform mat4 uModel, uView, uProj;
out vec3 vNormal;
out vec3 vPosEye;
out vec4 vColor;
void main() {
    vec4 pe = uView * uModel * vec4(aPos, 1.0);
    vPosEye = pe.xyz;
    vNormal = mat3(uView * uModel) * aNormal;
    vColor = aColor;
    gl_Position = uProj * pe;
})";

const char* kMeshFs = R"(#version 330 core
in vec3 vNormal;
in vec3 vPosEye;
in vec4 vColor;
uniform vec4 uOwner;
uniform float uAlpha;
out vec4 fragColor;
void main() {
    vec3 n = normalize(vNormal);
    vec3 l = normalize(-vPosEye); // headlight, like the server's shading
    float d = abs(dot(n, l));
    vec3 base = vColor.a == 0.0 ? uOwner.rgb : vColor.rgb;
    vec3 c = base * (0.22 + 0.78 * d) + vec3(0.35) * pow(d, 40.0);
    fragColor = vec4(c, uAlpha);
})";

} // namespace

Compositor::Compositor() {
    m_meshProgram = linkProgram(kMeshVs, kMeshFs, "mesh");
    m_uModel = glGetUniformLocation(m_meshProgram, "uModel");
    m_uView = glGetUniformLocation(m_meshProgram, "uView");
    m_uProj = glGetUniformLocation(m_meshProgram, "uProj");
    m_uOwner = glGetUniformLocation(m_meshProgram, "uOwner");
    m_uAlpha = glGetUniformLocation(m_meshProgram, "uAlpha");
}

Compositor::~Compositor() {
    glDeleteTextures(1, &m_colorTex);
    glDeleteTextures(1, &m_depthTex);
    glDeleteFramebuffers(1, &m_dbiFbo);
    glDeleteFramebuffers(1, &m_fbo);
    glDeleteTextures(1, &m_fboColor);
    glDeleteRenderbuffers(1, &m_fboDepth);
    glDeleteProgram(m_meshProgram);
}

void Compositor::resize(int width, int height) {
    resizeDbi(width, height);
    resizeView(width, height);
}

void Compositor::resizeView(int width, int height) {
    if (width == m_width && height == m_height && m_fbo)
        return;
    m_width = width;
    m_height = height;
    makeColorDepthTarget(m_fbo, m_fboColor, m_fboDepth, width, height, "composite");
    if (!m_colorTex) // nothing held yet: an empty DBI of the view's size
        resizeDbi(width, height);
}

void Compositor::resizeDbi(int width, int height) {
    if (width == m_dbiWidth && height == m_dbiHeight && m_dbiFbo)
        return;
    m_dbiWidth = width;
    m_dbiHeight = height;
    auto makeTex = [&](GLuint& tex, GLint internal, GLenum format, GLenum type) {
        if (!tex)
            glGenTextures(1, &tex);
        glBindTexture(GL_TEXTURE_2D, tex);
        glTexImage2D(GL_TEXTURE_2D, 0, internal, width, height, 0, format, type, nullptr);
        glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_NEAREST);
        glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_NEAREST);
        glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_S, GL_CLAMP_TO_EDGE);
        glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_T, GL_CLAMP_TO_EDGE);
    };
    // The DBI itself, as a framebuffer to blit from: colour and depth textures of the composite's
    // formats, so that the blit is a copy (on llvmpipe a memcpy: 0.04 ms for 500 x 500, where a
    // shader pass writing gl_FragDepth took ~0.5 ms).
    makeTex(m_colorTex, GL_RGBA8, GL_RGBA, GL_UNSIGNED_BYTE);
    makeTex(m_depthTex, GL_DEPTH_COMPONENT32F, GL_DEPTH_COMPONENT, GL_FLOAT);
    glBindTexture(GL_TEXTURE_2D, 0);
    if (!m_dbiFbo)
        glGenFramebuffers(1, &m_dbiFbo);
    glBindFramebuffer(GL_FRAMEBUFFER, m_dbiFbo);
    glFramebufferTexture2D(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_TEXTURE_2D, m_colorTex, 0);
    glFramebufferTexture2D(GL_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, GL_TEXTURE_2D, m_depthTex, 0);
    const bool complete = glCheckFramebufferStatus(GL_FRAMEBUFFER) == GL_FRAMEBUFFER_COMPLETE;
    glBindFramebuffer(GL_FRAMEBUFFER, 0);
    if (!complete)
        throw Error("ui: the DBI framebuffer is incomplete");
    uploadRect(PixelRect{0, 0, width, height}, Dbi(width, height));
}

void Compositor::uploadFull(const Dbi& dbi) {
    if (dbi.width() != m_dbiWidth || dbi.height() != m_dbiHeight || dbi.width() != m_width ||
        dbi.height() != m_height)
        resize(dbi.width(), dbi.height());
    uploadRect(dbi.bounds(), dbi);
}

void Compositor::uploadRect(const PixelRect& rect, const Dbi& patch) {
    if (rect.empty() || !PixelRect{0, 0, m_dbiWidth, m_dbiHeight}.contains(rect) ||
        patch.width() != rect.w || patch.height() != rect.h)
        return;
    // The colour goes up opaque: the DBI's background carries alpha 0, the composite wants 1
    // everywhere, and a blit copies alpha as it is.
    const size_t bytes = size_t(rect.w) * size_t(rect.h) * 4;
    m_opaque.assign(patch.color(), patch.color() + bytes);
    for (size_t i = 3; i < bytes; i += 4)
        m_opaque[i] = 255;
    glPixelStorei(GL_UNPACK_ALIGNMENT, 1);
    glBindTexture(GL_TEXTURE_2D, m_colorTex);
    glTexSubImage2D(GL_TEXTURE_2D, 0, rect.x, rect.y, rect.w, rect.h, GL_RGBA, GL_UNSIGNED_BYTE,
                    m_opaque.data());
    glBindTexture(GL_TEXTURE_2D, m_depthTex);
    glTexSubImage2D(GL_TEXTURE_2D, 0, rect.x, rect.y, rect.w, rect.h, GL_DEPTH_COMPONENT, GL_FLOAT,
                    patch.depth());
}

GpuMesh Compositor::upload(const MeshData& mesh) {
    GpuMesh g;
    if (mesh.indices.empty())
        return g;
    glGenVertexArrays(1, &g.vao);
    glBindVertexArray(g.vao);
    glGenBuffers(1, &g.vbo);
    glBindBuffer(GL_ARRAY_BUFFER, g.vbo);
    glBufferData(GL_ARRAY_BUFFER, GLsizeiptr(mesh.vertices.size() * sizeof(MeshVertex)),
                 mesh.vertices.data(), GL_STATIC_DRAW);
    glGenBuffers(1, &g.ibo);
    glBindBuffer(GL_ELEMENT_ARRAY_BUFFER, g.ibo);
    glBufferData(GL_ELEMENT_ARRAY_BUFFER, GLsizeiptr(mesh.indices.size() * sizeof(uint32_t)),
                 mesh.indices.data(), GL_STATIC_DRAW);
    const auto stride = GLsizei(sizeof(MeshVertex));
    glEnableVertexAttribArray(0);
    glVertexAttribPointer(0, 3, GL_FLOAT, GL_FALSE, stride,
                          reinterpret_cast<void*>(offsetof(MeshVertex, position)));
    glEnableVertexAttribArray(1);
    glVertexAttribPointer(1, 3, GL_FLOAT, GL_FALSE, stride,
                          reinterpret_cast<void*>(offsetof(MeshVertex, normal)));
    glEnableVertexAttribArray(2);
    glVertexAttribPointer(2, 4, GL_FLOAT, GL_FALSE, stride,
                          reinterpret_cast<void*>(offsetof(MeshVertex, color)));
    glBindVertexArray(0);
    g.indexCount = GLsizei(mesh.indices.size());
    return g;
}

void Compositor::destroy(GpuMesh& g) {
    glDeleteBuffers(1, &g.vbo);
    glDeleteBuffers(1, &g.ibo);
    glDeleteVertexArrays(1, &g.vao);
    g = GpuMesh{};
}

void Compositor::bindTarget(const Camera& camera) {
    m_view = viewMatrix(camera);
    m_proj = projectionMatrix(camera);
    glBindFramebuffer(GL_FRAMEBUFFER, m_fbo);
    glViewport(0, 0, m_width, m_height);
    glDisable(GL_BLEND);
    glDisable(GL_SCISSOR_TEST);
    glDisable(GL_CULL_FACE);
    glEnable(GL_DEPTH_TEST);
    glDepthMask(GL_TRUE);
}

void Compositor::beginMeshes() {
    glDepthFunc(GL_LESS);
    glUseProgram(m_meshProgram);
    glUniformMatrix4fv(m_uView, 1, GL_FALSE, glm::value_ptr(m_view));
    glUniformMatrix4fv(m_uProj, 1, GL_FALSE, glm::value_ptr(m_proj));
}

void Compositor::beginEmpty(const Camera& camera) {
    bindTarget(camera);
    glClearColor(float(kBackgroundRgba[0]) / 255.0f, float(kBackgroundRgba[1]) / 255.0f,
                 float(kBackgroundRgba[2]) / 255.0f, 1.0f);
    glClearDepth(1.0);
    glClear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);
    beginMeshes();
}

void Compositor::begin(const Camera& camera) {
    // The restore is a copy, colour and depth at once, of the same size and formats: no fragment
    // shader writing gl_FragDepth for every pixel, which on llvmpipe is most of a composite frame
    // (docs/ui.md has the figures).
    glBindFramebuffer(GL_READ_FRAMEBUFFER, m_dbiFbo);
    glBindFramebuffer(GL_DRAW_FRAMEBUFFER, m_fbo);
    glDisable(GL_SCISSOR_TEST);
    glBlitFramebuffer(0, 0, m_width, m_height, 0, 0, m_width, m_height,
                      GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT, GL_NEAREST);
    bindTarget(camera);
    beginMeshes();
}

void Compositor::beginWarped(const Camera& dbiCamera, const Camera& camera) {
    Camera from = dbiCamera;
    from.width = m_dbiWidth; // the pixels held say which size they are
    from.height = m_dbiHeight;
    Camera to = camera;
    to.width = m_width;
    to.height = m_height;
    bindTarget(to);
    warp().draw(m_colorTex, m_depthTex, from, to);
    beginMeshes();
}

ViewWarp& Compositor::warp() {
    if (!m_warp)
        m_warp = std::make_unique<ViewWarp>();
    return *m_warp;
}

void Compositor::draw(const GpuMesh& mesh, const glm::mat4& model, glm::vec4 ownerColor,
                      const MeshStyle& style) {
    if (!mesh.valid())
        return;
    glUniformMatrix4fv(m_uModel, 1, GL_FALSE, glm::value_ptr(model));
    glUniform4fv(m_uOwner, 1, glm::value_ptr(ownerColor));
    glUniform1f(m_uAlpha, style.alpha);
    const bool blend = style.alpha < 1.0f;
    if (blend) { // over what is drawn, hiding nothing drawn after it
        glEnable(GL_BLEND);
        glBlendFunc(GL_SRC_ALPHA, GL_ONE_MINUS_SRC_ALPHA);
        glDepthMask(GL_FALSE);
    }
    glBindVertexArray(mesh.vao);
    glDrawElements(GL_TRIANGLES, mesh.indexCount, GL_UNSIGNED_INT, nullptr);
    if (blend) {
        glDisable(GL_BLEND);
        glDepthMask(GL_TRUE);
    }
}

void Compositor::blitTo(int x, int y) {
    glBindVertexArray(0);
    glDisable(GL_DEPTH_TEST);
    glBindFramebuffer(GL_READ_FRAMEBUFFER, m_fbo);
    glBindFramebuffer(GL_DRAW_FRAMEBUFFER, 0);
    glBlitFramebuffer(0, 0, m_width, m_height, x, y, x + m_width, y + m_height, GL_COLOR_BUFFER_BIT,
                      GL_NEAREST);
    glBindFramebuffer(GL_FRAMEBUFFER, 0);
}

Dbi Compositor::readBack() {
    Dbi out(m_width, m_height);
    glBindFramebuffer(GL_READ_FRAMEBUFFER, m_fbo);
    glPixelStorei(GL_PACK_ALIGNMENT, 1);
    glReadPixels(0, 0, m_width, m_height, GL_RGBA, GL_UNSIGNED_BYTE, out.color());
    glReadPixels(0, 0, m_width, m_height, GL_DEPTH_COMPONENT, GL_FLOAT, out.depth());
    glBindFramebuffer(GL_READ_FRAMEBUFFER, 0);
    return out;
}

void Compositor::readBackDepth(Dbi& into) {
    if (into.width() != m_width || into.height() != m_height)
        into = Dbi(m_width, m_height);
    glBindFramebuffer(GL_READ_FRAMEBUFFER, m_fbo);
    glPixelStorei(GL_PACK_ALIGNMENT, 1);
    glReadPixels(0, 0, m_width, m_height, GL_DEPTH_COMPONENT, GL_FLOAT, into.depth());
    glBindFramebuffer(GL_READ_FRAMEBUFFER, 0);
}

} // namespace trephine::ui

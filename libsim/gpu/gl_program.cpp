#include "libsim_gpu/gl_program.h"

#include "libsim/error.h"

#include <fmt/format.h>

#include <algorithm>
#include <initializer_list>
#include <string>

namespace trephine::gpu {

const char* const kFullscreenTriangleVs = R"(#version 330 core
void main() {
    vec2 p = vec2(gl_VertexID == 1 ? 3.0 : -1.0, gl_VertexID == 2 ? 3.0 : -1.0);
    gl_Position = vec4(p, 0.0, 1.0);
})";

namespace {

GLuint compile(GLenum type, const char* src, const char* what) {
    GLuint s = glCreateShader(type);
    glShaderSource(s, 1, &src, nullptr);
    glCompileShader(s);
    GLint ok = 0;
    glGetShaderiv(s, GL_COMPILE_STATUS, &ok);
    if (!ok) {
        char log[2048] = {}; // a shader GL refused (0) gets no log written
        glGetShaderInfoLog(s, sizeof log, nullptr, log);
        glDeleteShader(s);
        throw Error(std::string("gl: ") + what + " shader does not compile: " + log);
    }
    return s;
}

// Links the compiled shaders into a program, deleting them either way.
GLuint link(std::initializer_list<GLuint> shaders, const char* what) {
    GLuint p = glCreateProgram();
    for (GLuint s : shaders)
        glAttachShader(p, s);
    glLinkProgram(p);
    for (GLuint s : shaders)
        glDeleteShader(s);
    GLint ok = 0;
    glGetProgramiv(p, GL_LINK_STATUS, &ok);
    if (!ok) {
        char log[2048] = {};
        glGetProgramInfoLog(p, sizeof log, nullptr, log);
        glDeleteProgram(p);
        throw Error(std::string("gl: ") + what + " program does not link: " + log);
    }
    return p;
}

} // namespace

GLuint linkProgram(const char* vertexSource, const char* fragmentSource, const char* what) {
    GLuint v = compile(GL_VERTEX_SHADER, vertexSource, what);
    GLuint f = 0;
    try {
        f = compile(GL_FRAGMENT_SHADER, fragmentSource, what);
    } catch (...) {
        glDeleteShader(v);
        throw;
    }
    return link({v, f}, what);
}

GLuint linkComputeProgram(const char* source, const char* what) {
    return link({compile(GL_COMPUTE_SHADER, source, what)}, what);
}

void clearGlErrors() {
    while (glGetError() != GL_NO_ERROR) {
    }
}

void throwIfGlRefused(const std::string& what) {
    if (const GLenum e = glGetError(); e != GL_NO_ERROR) {
        clearGlErrors(); // GL may hold more than one
        throw Error(fmt::format("gpu: OpenGL refused {} (error 0x{:04x}{})", what, unsigned(e),
                                e == GL_OUT_OF_MEMORY ? ": out of memory" : ""));
    }
}

void makeColorDepthTarget(GLuint& fbo, GLuint& color, GLuint& depth, int width, int height,
                          const char* what) {
    // A size over the GL's limits, or memory it has not, leaves the old attachments in place and
    // the framebuffer complete: refused here, with one line, rather than read back undefined.
    GLint most = 0, mostRenderbuffer = 0;
    glGetIntegerv(GL_MAX_TEXTURE_SIZE, &most);
    glGetIntegerv(GL_MAX_RENDERBUFFER_SIZE, &mostRenderbuffer);
    most = std::min(most, mostRenderbuffer);
    if (width > most || height > most)
        throw Error(fmt::format("gl: the {} framebuffer's {} x {} pixels are over this OpenGL's "
                                "{} a side",
                                what, width, height, most));
    clearGlErrors();
    if (!color)
        glGenTextures(1, &color);
    glBindTexture(GL_TEXTURE_2D, color);
    glTexImage2D(GL_TEXTURE_2D, 0, GL_RGBA8, width, height, 0, GL_RGBA, GL_UNSIGNED_BYTE, nullptr);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_NEAREST);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_NEAREST);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_S, GL_CLAMP_TO_EDGE);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_T, GL_CLAMP_TO_EDGE);
    if (!depth)
        glGenRenderbuffers(1, &depth);
    glBindRenderbuffer(GL_RENDERBUFFER, depth);
    glRenderbufferStorage(GL_RENDERBUFFER, GL_DEPTH_COMPONENT32F, width, height);
    if (!fbo)
        glGenFramebuffers(1, &fbo);
    glBindFramebuffer(GL_FRAMEBUFFER, fbo);
    glFramebufferTexture2D(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_TEXTURE_2D, color, 0);
    glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, GL_RENDERBUFFER, depth);
    const bool complete = glCheckFramebufferStatus(GL_FRAMEBUFFER) == GL_FRAMEBUFFER_COMPLETE;
    glBindFramebuffer(GL_FRAMEBUFFER, 0);
    throwIfGlRefused(fmt::format("the {} framebuffer's {} x {} pixels", what, width, height));
    if (!complete)
        throw Error(std::string("gl: the ") + what + " framebuffer is incomplete");
}

} // namespace trephine::gpu

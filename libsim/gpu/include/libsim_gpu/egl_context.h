// An OpenGL core context through EGL with no display and no window: a headless server renders
// with compute shaders into buffers where the driver has OpenGL 4.3, else with fragment shaders
// (3.3). EGL's devices are tried first (a GPU's driver), then Mesa's surfaceless platform
// (llvmpipe where there is no GPU).
#pragma once

#include <memory>
#include <mutex>
#include <string>

namespace trephine::gpu {

// Which GL answered: GL_RENDERER and GL_VERSION, and whether it is a software rasteriser
// (llvmpipe, softpipe, SwiftShader...), which `--renderer auto` does not count as a GPU.
struct GlInfo {
    std::string renderer, version;
    bool software = false;
    bool compute = false; // a 4.3 context (compute shaders); else 3.3, fragment shaders only
};

// True for the GL_RENDERER strings of software rasterisers.
bool isSoftwareRenderer(const std::string& glRenderer);

class EglContext {
public:
    // The first context a hardware renderer gives, else the first any gives: 4.3 core where the
    // driver has it, else 3.3 core; with `compute` false 3.3 only, as a driver without 4.3
    // answers. Throws trephine::Error saying what is missing when none does (no libEGL driver,
    // no GL 3.3 core).
    static std::unique_ptr<EglContext> open(bool compute = true);
    // The process's one context, opened on first call and kept; null (with `why`, which may be
    // null) when open() failed.
    static std::shared_ptr<EglContext> shared(std::string* why);
    ~EglContext();
    EglContext(const EglContext&) = delete;
    EglContext& operator=(const EglContext&) = delete;

    const GlInfo& info() const { return m_info; }

    // Makes the context current on this thread for the scope and releases it after, so any
    // thread may use it; a second thread waits for the first's scope to end.
    class Current {
    public:
        explicit Current(const EglContext& context);
        ~Current();
        Current(const Current&) = delete;
        Current& operator=(const Current&) = delete;

    private:
        const EglContext& m_context;
        std::lock_guard<std::mutex> m_lock;
    };

private:
    EglContext(void* display, void* context, GlInfo info)
        : m_display(display), m_context(context), m_info(std::move(info)) {}
    void* m_display; // EGLDisplay, EGLContext: kept out of this header (EGL's defines X11 types)
    void* m_context;
    GlInfo m_info;
    mutable std::mutex m_mutex; // one thread in the context at a time
};

} // namespace trephine::gpu

#include "libsim_gpu/egl_context.h"

#include "libsim_gpu/gl.h"

#include "libsim/error.h"

#define EGL_NO_X11 1
#include <EGL/egl.h>
#include <EGL/eglext.h>

#include <algorithm>
#include <cctype>
#include <cstring>
#include <vector>

namespace trephine::gpu {

namespace {

bool hasExtension(const char* list, const char* name) {
    if (!list)
        return false;
    const size_t n = std::strlen(name);
    for (const char* p = std::strstr(list, name); p; p = std::strstr(p + 1, name))
        if ((p == list || p[-1] == ' ') && (p[n] == ' ' || p[n] == '\0'))
            return true;
    return false;
}

// EGL displays that need no window system: each EGL device's, then Mesa's surfaceless one.
std::vector<EGLDisplay> headlessDisplays() {
    std::vector<EGLDisplay> out;
    const char* client = eglQueryString(EGL_NO_DISPLAY, EGL_EXTENSIONS);
    auto getDisplay = reinterpret_cast<PFNEGLGETPLATFORMDISPLAYEXTPROC>(
        eglGetProcAddress("eglGetPlatformDisplayEXT"));
    if (!getDisplay)
        return out;
    auto queryDevices =
        reinterpret_cast<PFNEGLQUERYDEVICESEXTPROC>(eglGetProcAddress("eglQueryDevicesEXT"));
    if (queryDevices && hasExtension(client, "EGL_EXT_platform_device")) {
        EGLDeviceEXT devices[16];
        EGLint count = 0;
        if (queryDevices(16, devices, &count))
            for (EGLint i = 0; i < count; ++i)
                if (EGLDisplay d = getDisplay(EGL_PLATFORM_DEVICE_EXT, devices[i], nullptr))
                    out.push_back(d);
    }
    if (hasExtension(client, "EGL_MESA_platform_surfaceless"))
        if (EGLDisplay d = getDisplay(EGL_PLATFORM_SURFACELESS_MESA, EGL_DEFAULT_DISPLAY, nullptr))
            out.push_back(d);
    return out;
}

struct Candidate {
    EGLDisplay display = EGL_NO_DISPLAY;
    EGLContext context = EGL_NO_CONTEXT;
    GlInfo info;
};

// A core context on `display`, current for no surface: 4.3 (compute shaders) where the driver
// has it and `compute` asks for it, else 3.3 (fragment shaders); `why` says what failed.
bool tryDisplay(EGLDisplay display, bool compute, Candidate& out, std::string& why) {
    EGLint major = 0, minor = 0;
    if (!eglInitialize(display, &major, &minor)) {
        why = "eglInitialize failed";
        return false;
    }
    const char* ext = eglQueryString(display, EGL_EXTENSIONS);
    EGLConfig config = EGL_NO_CONFIG_KHR;
    if (!hasExtension(ext, "EGL_KHR_surfaceless_context") || !eglBindAPI(EGL_OPENGL_API)) {
        why = "no surfaceless desktop OpenGL";
        eglTerminate(display);
        return false;
    }
    if (!hasExtension(ext, "EGL_KHR_no_config_context")) {
        // A device display may have no window configs (eglChooseConfig's default).
        const EGLint want[] = {EGL_RENDERABLE_TYPE, EGL_OPENGL_BIT, EGL_SURFACE_TYPE,
                               EGL_PBUFFER_BIT, EGL_NONE};
        EGLint n = 0;
        if (!eglChooseConfig(display, want, &config, 1, &n) || n < 1) {
            why = "no OpenGL config";
            eglTerminate(display);
            return false;
        }
    }
    EGLContext context = EGL_NO_CONTEXT;
    bool gotCompute = false;
    for (const EGLint version : {43, 33}) {
        if (version == 43 && !compute)
            continue;
        const EGLint attributes[] = {EGL_CONTEXT_MAJOR_VERSION,
                                     version / 10,
                                     EGL_CONTEXT_MINOR_VERSION,
                                     version % 10,
                                     EGL_CONTEXT_OPENGL_PROFILE_MASK,
                                     EGL_CONTEXT_OPENGL_CORE_PROFILE_BIT,
                                     EGL_NONE};
        context = eglCreateContext(display, config, EGL_NO_CONTEXT, attributes);
        if (context != EGL_NO_CONTEXT &&
            eglMakeCurrent(display, EGL_NO_SURFACE, EGL_NO_SURFACE, context)) {
            gotCompute = version == 43;
            break;
        }
        if (context != EGL_NO_CONTEXT)
            eglDestroyContext(display, context);
        context = EGL_NO_CONTEXT;
    }
    if (context == EGL_NO_CONTEXT) {
        why = "no OpenGL 3.3 core context"; // the display stays: another context may live on it
        return false;
    }
    auto str = [](GLenum e) {
        const GLubyte* s = glGetString(e);
        return s ? std::string(reinterpret_cast<const char*>(s)) : std::string("?");
    };
    out = {display, context, {str(GL_RENDERER), str(GL_VERSION), false, gotCompute}};
    out.info.software = isSoftwareRenderer(out.info.renderer);
    eglMakeCurrent(display, EGL_NO_SURFACE, EGL_NO_SURFACE, EGL_NO_CONTEXT);
    return true;
}

} // namespace

bool isSoftwareRenderer(const std::string& glRenderer) {
    std::string s = glRenderer;
    std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return std::tolower(c); });
    for (const char* name : {"llvmpipe", "softpipe", "swiftshader", "swrast", "software"})
        if (s.find(name) != std::string::npos)
            return true;
    return false;
}

std::unique_ptr<EglContext> EglContext::open(bool compute) {
    std::vector<Candidate> found;
    std::string why = "no EGL platform without a display (EGL_EXT_platform_device or "
                      "EGL_MESA_platform_surfaceless; install libegl1 and a GL driver)";
    for (EGLDisplay d : headlessDisplays()) {
        Candidate c;
        if (tryDisplay(d, compute, c, why))
            found.push_back(c);
        if (!found.empty() && !found.back().info.software)
            break;
    }
    if (found.empty())
        throw Error("gpu: no OpenGL 3.3 core context through EGL: " + why);
    // A hardware renderer if one answered (the last tried), else the first.
    auto best = std::find_if(found.begin(), found.end(), [](auto& c) { return !c.info.software; });
    if (best == found.end())
        best = found.begin();
    // The others' contexts go; their displays stay initialised, as ~EglContext leaves its own:
    // another context of the process may live on one.
    for (auto it = found.begin(); it != found.end(); ++it)
        if (it != best)
            eglDestroyContext(it->display, it->context);
    return std::unique_ptr<EglContext>(new EglContext(best->display, best->context, best->info));
}

// Kept to the end of the process and never destroyed: terminating EGL from a static destructor
// may run after the driver's own statics are gone.
std::shared_ptr<EglContext> EglContext::shared(std::string* why) {
    static std::string failure;
    static const auto* context =
        new std::shared_ptr<EglContext>([]() -> std::shared_ptr<EglContext> {
            try {
                return open();
            } catch (const Error& e) {
                failure = e.what();
                return nullptr;
            }
        }());
    if (why)
        *why = failure;
    return *context;
}

// The display stays initialised: EGL gives one handle a device, so terminating it would end the
// process's other contexts on it.
EglContext::~EglContext() {
    eglDestroyContext(m_display, m_context);
}

EglContext::Current::Current(const EglContext& context)
    : m_context(context), m_lock(context.m_mutex) {
    // The bound API is per thread, and EGL releases the current context of the thread's API:
    // this thread may not be the one that made the context.
    eglBindAPI(EGL_OPENGL_API);
    if (!eglMakeCurrent(context.m_display, EGL_NO_SURFACE, EGL_NO_SURFACE, context.m_context))
        throw Error("gpu: the EGL context cannot be made current (it is current on another "
                    "thread)");
}

EglContext::Current::~Current() {
    eglMakeCurrent(m_context.m_display, EGL_NO_SURFACE, EGL_NO_SURFACE, EGL_NO_CONTEXT);
}

} // namespace trephine::gpu

#include "ui/window.h"

#include "libsim/error.h"
#include "ui/gl.h"

#define GLFW_INCLUDE_NONE
#include <GLFW/glfw3.h>
#include <imgui.h>
#include <imgui_impl_glfw.h>
#include <imgui_impl_opengl3.h>

#include <cstdlib>

namespace trephine::ui {

namespace {
std::string g_glfwError;
void onGlfwError(int, const char* text) {
    g_glfwError = text ? text : "unknown GLFW error";
}
} // namespace

bool displayAvailable(std::string* why) {
    const char* d = std::getenv("DISPLAY");
    const char* w = std::getenv("WAYLAND_DISPLAY");
    if ((!d || !*d) && (!w || !*w)) {
        if (why)
            *why = "no DISPLAY is set";
        return false;
    }
    glfwSetErrorCallback(onGlfwError);
    if (!glfwInit()) {
        if (why)
            *why = "GLFW cannot start: " + g_glfwError;
        return false;
    }
    // A display without a usable OpenGL 3.3 core (an X server with no GLX, ssh -X to one) is no
    // window either: a demo asks here, before starting its server, so it can run headless.
    glfwDefaultWindowHints();
    glfwWindowHint(GLFW_CONTEXT_VERSION_MAJOR, 3);
    glfwWindowHint(GLFW_CONTEXT_VERSION_MINOR, 3);
    glfwWindowHint(GLFW_OPENGL_PROFILE, GLFW_OPENGL_CORE_PROFILE);
    glfwWindowHint(GLFW_OPENGL_FORWARD_COMPAT, GLFW_TRUE);
    glfwWindowHint(GLFW_VISIBLE, GLFW_FALSE);
    GLFWwindow* probe = glfwCreateWindow(1, 1, "trephine", nullptr, nullptr);
    glfwDefaultWindowHints();
    if (!probe) {
        if (why)
            *why = "no OpenGL 3.3 core context: " + g_glfwError;
        return false;
    }
    glfwDestroyWindow(probe);
    return true; // glfwInit is reference-free; Window initialises again (a no-op) and terminates
}

Window::Window(const WindowConfig& config) : m_imgui(config.imgui) {
    glfwSetErrorCallback(onGlfwError);
    if (!glfwInit())
        throw Error("ui: cannot open a window (" + g_glfwError + "); is DISPLAY set?");
    glfwWindowHint(GLFW_CONTEXT_VERSION_MAJOR, 3);
    glfwWindowHint(GLFW_CONTEXT_VERSION_MINOR, 3);
    glfwWindowHint(GLFW_OPENGL_PROFILE, GLFW_OPENGL_CORE_PROFILE);
    glfwWindowHint(GLFW_OPENGL_FORWARD_COMPAT, GLFW_TRUE);
    glfwWindowHint(GLFW_RESIZABLE, GLFW_FALSE);
    glfwWindowHint(GLFW_VISIBLE, config.visible ? GLFW_TRUE : GLFW_FALSE);
    m_window =
        glfwCreateWindow(config.width, config.height, config.title.c_str(), nullptr, nullptr);
    if (!m_window) {
        std::string e = g_glfwError;
        glfwTerminate();
        throw Error("ui: no OpenGL 3.3 core context (" + e + ")");
    }
    glfwMakeContextCurrent(m_window);
    // Ours first: ImGui's backend, installed next, calls it from its own key callback.
    glfwSetWindowUserPointer(m_window, this);
    glfwSetKeyCallback(m_window, &Window::onKey);
    glfwSwapInterval(0); // the frame loop paces itself; llvmpipe has no vblank to wait for
    glfwGetFramebufferSize(m_window, &m_width, &m_height);
    if (m_imgui) {
        IMGUI_CHECKVERSION();
        ImGui::CreateContext();
        ImGui::GetIO().IniFilename = nullptr; // no imgui.ini litter in the working directory
        ImGui::StyleColorsDark();
        ImGuiStyle& s = ImGui::GetStyle();
        s.WindowRounding = 4.0f;
        s.FrameRounding = 3.0f;
        s.WindowBorderSize = 1.0f;
        ImGui_ImplGlfw_InitForOpenGL(m_window, true);
        ImGui_ImplOpenGL3_Init("#version 330 core");
    }
}

Window::~Window() {
    if (m_imgui) {
        ImGui_ImplOpenGL3_Shutdown();
        ImGui_ImplGlfw_Shutdown();
        ImGui::DestroyContext();
    }
    glfwDestroyWindow(m_window);
    glfwTerminate();
}

bool Window::shouldClose() const {
    return glfwWindowShouldClose(m_window);
}
void Window::requestClose() {
    glfwSetWindowShouldClose(m_window, GLFW_TRUE);
}

void Window::onKey(GLFWwindow* window, int key, int, int action, int mods) {
    auto* self = static_cast<Window*>(glfwGetWindowUserPointer(window));
    if (self && (action == GLFW_PRESS || action == GLFW_REPEAT))
        self->m_queued.push_back({key, mods});
}

void Window::injectKey(int key, int action, int mods) {
    if (m_imgui)
        ImGui_ImplGlfw_KeyCallback(m_window, key, glfwGetKeyScancode(key), action, mods);
    else
        onKey(m_window, key, 0, action, mods);
}

void Window::beginFrame() {
    glfwPollEvents();
    m_keys.swap(m_queued);
    m_queued.clear();
    glfwGetFramebufferSize(m_window, &m_width, &m_height);
    glBindFramebuffer(GL_FRAMEBUFFER, 0);
    glViewport(0, 0, m_width, m_height);
    glClearColor(0.09f, 0.10f, 0.12f, 1.0f);
    glClear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);
    if (m_imgui) {
        ImGui_ImplOpenGL3_NewFrame();
        ImGui_ImplGlfw_NewFrame();
        ImGui::NewFrame();
    }
}

void Window::endFrame(Dbi* capture) {
    if (m_imgui) {
        ImGui::Render();
        glBindFramebuffer(GL_FRAMEBUFFER, 0);
        glViewport(0, 0, m_width, m_height);
        ImGui_ImplOpenGL3_RenderDrawData(ImGui::GetDrawData());
    }
    if (capture)
        *capture = readFramebuffer();
    glfwSwapBuffers(m_window);
}

void Window::waitEvents(double timeoutS) {
    glfwWaitEventsTimeout(timeoutS);
}

void Window::resize(int width, int height) {
    if (width != m_width || height != m_height)
        glfwSetWindowSize(m_window, width, height);
}

void Window::wake() {
    glfwPostEmptyEvent();
}

Dbi Window::readFramebuffer() const {
    Dbi out(m_width, m_height);
    glBindFramebuffer(GL_READ_FRAMEBUFFER, 0);
    glReadBuffer(GL_BACK);
    glPixelStorei(GL_PACK_ALIGNMENT, 1);
    glReadPixels(0, 0, m_width, m_height, GL_RGBA, GL_UNSIGNED_BYTE, out.color());
    return out;
}

} // namespace trephine::ui

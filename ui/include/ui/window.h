// A GLFW window with an OpenGL 3.3 core context and Dear ImGui 1.86 (GLFW + OpenGL3 backends).
// One per process; the main thread owns it and everything GL.
#pragma once

#include "libsim/dbi.h"

#include <string>
#include <vector>

struct GLFWwindow;

namespace trephine::ui {

// Whether a window can open here: glfwInit succeeds (needs an X display). `why` says why not.
bool displayAvailable(std::string* why = nullptr);

struct WindowConfig {
    int width = 920;
    int height = 760;
    std::string title = "Trephine";
    bool visible = true;
    bool imgui = true;
};

// A key pressed (or repeated), as GLFW's key callback reported it.
struct KeyPress {
    int key = 0;  // GLFW_KEY_*
    int mods = 0; // GLFW_MOD_*
    bool operator==(const KeyPress&) const = default;
};

class Window {
public:
    // Throws trephine::Error with one line when GLFW, the context or ImGui cannot start.
    explicit Window(const WindowConfig& config);
    ~Window();
    Window(const Window&) = delete;
    Window& operator=(const Window&) = delete;

    bool shouldClose() const;
    void requestClose();
    // Polls events, clears the window, starts an ImGui frame.
    void beginFrame();
    // Renders ImGui over the scene and swaps; when capture is given, reads the finished frame
    // into it first (row 0 at the bottom).
    void endFrame(Dbi* capture = nullptr);
    // Sleeps until an event arrives, wake() is called, or `timeoutS` passes: an idle window's
    // pause between frames.
    void waitEvents(double timeoutS);
    // Asks for a new size (as the user dragging a corner); width() and height() follow once the
    // next frame's events have come.
    void resize(int width, int height);
    // Any thread: ends a waitEvents now (a client thread with something new to show).
    static void wake();
    // The back buffer as it is now (call between drawing and endFrame), row 0 at the bottom.
    Dbi readFramebuffer() const;

    // The keys pressed since the frame before began, in order. ImGui 1.86 polls key state once a
    // frame, so a tap whose press and release fall in one frame never reaches IsKeyPressed; this
    // queue, filled by GLFW's key callback, keeps it.
    const std::vector<KeyPress>& keyPresses() const { return m_keys; }
    // [Tests] A key event as if GLFW had reported it: through the callbacks the window installed
    // (ImGui's, which hands it on to the queue), so a test taps a key inside one frame.
    void injectKey(int key, int action, int mods = 0);

    int width() const { return m_width; }
    int height() const { return m_height; }
    GLFWwindow* handle() const { return m_window; }

private:
    GLFWwindow* m_window = nullptr;
    static void onKey(GLFWwindow* window, int key, int scancode, int action, int mods);
    bool m_imgui = true;
    std::vector<KeyPress> m_keys;   // this frame's
    std::vector<KeyPress> m_queued; // arriving for the next frame
    int m_width = 0, m_height = 0;
};

// Writes a framebuffer read by readFramebuffer as a top-down RGB PNG.
void writeScreenshot(const std::string& path, const Dbi& framebuffer);

} // namespace trephine::ui

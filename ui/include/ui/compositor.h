// The paper's two-pass hybrid rendering (section 3.3). Pass 1 restores the DBI into an offscreen
// framebuffer (RGBA8 colour, 32-bit float depth) by blitting colour and depth from a second
// framebuffer of the same formats that holds the DBI itself (colour uploaded opaque);
// pass 2 draws meshes depth-tested against it with the matrices the server rendered the DBI with.
// Both framebuffers are the DBI's size, so pixels map 1:1, and the composite is blitted into the
// window. Image updates re-upload only their rectangle. While a new view is on its way (or after
// a resize) pass 1 is the DBI warped to the window's camera instead (ui/view_warp.h), and the
// composite may be another size than the DBI.
#pragma once

#include "libsim/camera.h"
#include "libsim/dbi.h"
#include "ui/gl.h"
#include "ui/mesh.h"
#include "ui/view_warp.h"

#include <glm/mat4x4.hpp>
#include <glm/vec4.hpp>
#include <memory>
#include <vector>

namespace trephine::ui {

struct GpuMesh {
    GLuint vao = 0, vbo = 0, ibo = 0;
    GLsizei indexCount = 0;
    bool valid() const { return vao != 0; }
};

// How pass 2 draws one mesh: `alpha` below 1 blends it over the picture, still depth-tested,
// without writing depth (a tool that would hide the cut).
struct MeshStyle {
    float alpha = 1.0f;
};

class Compositor {
public:
    Compositor(); // needs a current GL 3.3 core context
    ~Compositor();
    Compositor(const Compositor&) = delete;
    Compositor& operator=(const Compositor&) = delete;

    // (Re)allocates the textures and framebuffer for a DBI of this size (background filled).
    void resize(int width, int height);
    // Resizes the composite only: the DBI held stays as it is, for beginWarped to scale.
    void resizeView(int width, int height);
    int width() const { return m_width; } // the composite's
    int height() const { return m_height; }
    glm::ivec2 dbiSize() const { return {m_dbiWidth, m_dbiHeight}; }

    // Whole-image upload (join, view change) and the per-update sub-rectangle upload.
    void uploadFull(const Dbi& dbi);
    void uploadRect(const PixelRect& rect, const Dbi& patch);

    GpuMesh upload(const MeshData& mesh);
    void destroy(GpuMesh& mesh);

    // Pass 1: binds the framebuffer, restores the DBI's colour and depth.
    void begin(const Camera& camera);
    // Pass 1 for a camera the DBI was not rendered for: the DBI (rendered with `dbiCamera`, of
    // the DBI's size) warped to `camera` (of the composite's size). Pass 2 then uses `camera`.
    void beginWarped(const Camera& dbiCamera, const Camera& camera);
    // The warp's settings (tests, benchmarks).
    ViewWarp& warp();
    // Pass 1 for a picture drawn by someone else (the replicated-volume client's ray cast): binds
    // the framebuffer, clears colour to the background and depth to 1 (far), sets up pass 2's
    // matrices, and restores nothing. The caller then draws its picture with gl_FragDepth in the
    // DBI's convention (e.g. VolumeView::draw) before the meshes.
    void beginEmpty(const Camera& camera);
    // Pass 2: one mesh with its model matrix; vertices with alpha 0 take ownerColor.
    void draw(const GpuMesh& mesh, const glm::mat4& model, glm::vec4 ownerColor = glm::vec4(1),
              const MeshStyle& style = {});
    // Copies the composite into the bound window framebuffer with its bottom-left at (x, y).
    void blitTo(int x, int y);

    // The composite's colour (RGBA8) and depth, row 0 at the bottom.
    Dbi readBack();
    // Its depth only, into `into`'s depth (`into` is made the composite's size first, black, when
    // it is another size): all that picking and the marks' occlusion read, half readBack's bytes.
    void readBackDepth(Dbi& into);

private:
    void bindTarget(const Camera& camera);
    void beginMeshes();

    void resizeDbi(int width, int height);

    int m_width = 0, m_height = 0;                       // the composite
    int m_dbiWidth = 0, m_dbiHeight = 0;                 // the DBI's textures
    std::unique_ptr<ViewWarp> m_warp;                    // made on first use
    GLuint m_colorTex = 0, m_depthTex = 0, m_dbiFbo = 0; // the DBI as uploaded
    GLuint m_fbo = 0, m_fboColor = 0, m_fboDepth = 0;    // the composite
    GLuint m_meshProgram = 0;
    std::vector<uint8_t> m_opaque; // uploadRect's colour with alpha 255
    GLint m_uModel = -1, m_uView = -1, m_uProj = -1, m_uOwner = -1, m_uAlpha = -1;
    glm::mat4 m_view{1.0f}, m_proj{1.0f};
};

} // namespace trephine::ui

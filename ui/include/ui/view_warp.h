// The DBI a client holds, drawn for a camera it was not rendered for (issue 32): while the server
// renders a new view, or after a resize, the window shows the old picture warped to the new camera
// within the frame of the change. Each DBI pixel is a vertex of a grid, unprojected with the DBI's
// camera and reprojected with the new one; the mesh breaks where depth jumps and holes show the
// farther side. docs/rendering.md#client-view-warping.
#pragma once

#include "libsim/camera.h"
#include "ui/gl.h"

#include <glm/vec2.hpp>

namespace trephine::ui {

struct WarpOptions {
    // Grid vertices every `gridStep` pixels (1: one per pixel). llvmpipe pays per triangle (500 x
    // 500: ~50 ms of CPU at step 1, ~2 ms at 4) while a 5-degree orbit still matches 99.2 % of
    // pixels at 4 (99.5 % at 1): benchmark_ui BM_WarpFrame, BM_WarpMatch.
    int gridStep = 4;
    // A grid triangle whose depth rises faster than this many pixel footprints per pixel (the
    // tangent of the surface's slant to the view plane, 8: 83 degrees) spans a depth jump: where
    // it is stretched it shows the farther side's colour, never a rubber sheet of the near one.
    float breakSlope = 8.0f;
    // Colour between pixel centres: bilinear (true) or the nearest pixel's.
    bool bilinear = true;
    // Re-light the server's headlight for the new eye (normals from the mesh's facets).
    bool relight = true;
};

class ViewWarp {
public:
    ViewWarp(); // needs a current GL 3.3 core context
    ~ViewWarp();
    ViewWarp(const ViewWarp&) = delete;
    ViewWarp& operator=(const ViewWarp&) = delete;

    void setOptions(const WarpOptions& o) { m_options = o; }
    const WarpOptions& options() const { return m_options; }

    // Draws the DBI (colour RGBA8 and DEPTH_COMPONENT32F textures of `dbiCamera`'s size, rendered
    // with `dbiCamera`) as seen by `camera` into the bound framebuffer, whose viewport the caller
    // set to camera's size: clears colour to the background and depth to 1, then draws the mesh
    // depth-tested, writing depth. Leaves the depth test on, GL_LESS, no program or VAO bound.
    // For the same camera the picture is the DBI's colour bit for bit.
    void draw(GLuint colorTex, GLuint depthTex, const Camera& dbiCamera, const Camera& camera);

private:
    void buildGrid(glm::ivec2 size, int step);

    WarpOptions m_options;
    GLuint m_program = 0, m_vao = 0, m_vbo = 0, m_ibo = 0, m_linear = 0;
    GLsizei m_indexCount = 0;
    glm::ivec2 m_gridSize{0};
    int m_gridStep = 0;
    GLint m_uWarp = -1, m_uDbiSize = -1, m_uStep = -1, m_uBgDepth = -1, m_uNearFar = -1,
          m_uBreak = -1, m_uColor = -1, m_uDepth = -1, m_uBilinear = -1, m_uUnproject = -1,
          m_uRelight = -1, m_uEyeOld = -1, m_uEyeNew = -1;
};

} // namespace trephine::ui

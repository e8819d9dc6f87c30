// The two-pass compositor on Mesa llvmpipe (needs a display: scripts/test runs ctest under
// xvfb-run). Depth compositing is checked pixel by pixel against the DBI's depth.
#include "ui/compositor.h"
#include "ui/window.h"

#include "gl_window_test.h"

#include "libsim/camera.h"

#include <glm/gtc/matrix_transform.hpp>
#include <glm/gtx/quaternion.hpp>
#include <gtest/gtest.h>

#include <cstring>
#include <memory>

using namespace trephine;
using namespace trephine::ui;

namespace {

constexpr uint8_t kBone[4] = {235, 225, 200, 255};

Camera testCamera() {
    Camera c;
    c.eye = {0, 0, 300};
    c.fovYDeg = 12.0f;
    c.nearMm = 150.0f;
    c.farMm = 450.0f;
    c.width = c.height = 200;
    return c;
}

// A tilted bone plane z = 0.3 x, with exact GL window depth per pixel.
Dbi planeDbi(const Camera& cam) {
    Dbi d(cam.width, cam.height);
    glm::dmat4 vp = viewProjection(cam);
    glm::dmat4 inv = glm::inverse(vp);
    for (int y = 0; y < cam.height; ++y)
        for (int x = 0; x < cam.width; ++x) {
            glm::dvec2 ndc(2.0 * (x + 0.5) / cam.width - 1.0, 2.0 * (y + 0.5) / cam.height - 1.0);
            glm::dvec4 a = inv * glm::dvec4(ndc, -1, 1), b = inv * glm::dvec4(ndc, 1, 1);
            glm::dvec3 p0 = glm::dvec3(a) / a.w, p1 = glm::dvec3(b) / b.w, dir = p1 - p0;
            // (p0 + t dir).z = 0.3 (p0 + t dir).x
            double t = (0.3 * p0.x - p0.z) / (dir.z - 0.3 * dir.x);
            glm::dvec3 p = p0 + t * dir;
            uint8_t* c = d.color(x, y);
            for (int i = 0; i < 4; ++i)
                c[i] = kBone[i];
            d.depth()[d.index(x, y)] = windowDepth(vp, p);
        }
    return d;
}

class CompositorTest : public trephine::testing::GlWindowTest {
protected:
    void SetUp() override {
        GlWindowTest::SetUp();
        if (window)
            comp = std::make_unique<Compositor>();
    }
    void TearDown() override {
        comp.reset();
        GlWindowTest::TearDown();
    }
    std::unique_ptr<Compositor> comp;
};

} // namespace

TEST_F(CompositorTest, RestoresTheDbiExactly) {
    Camera cam = testCamera();
    Dbi dbi = planeDbi(cam);
    comp->uploadFull(dbi);
    comp->begin(cam);
    Dbi out = comp->readBack();
    EXPECT_EQ(compare(out, dbi).maxDepthError, 0.0f); // gl_FragDepth into a 32-bit float buffer
    EXPECT_EQ(compare(out, dbi).maxColorError, 0);
}

// The depth-only read back (the volume design's picking) gives readBack's depth, resizing a Dbi
// of another size and leaving the colour of one of the right size alone.
TEST_F(CompositorTest, ReadBackDepthGivesTheCompositesDepth) {
    Camera cam = testCamera();
    Dbi dbi = planeDbi(cam);
    comp->uploadFull(dbi);
    comp->begin(cam);
    const Dbi full = comp->readBack();
    Dbi small(3, 2);
    comp->readBackDepth(small);
    ASSERT_EQ(small.width(), cam.width);
    ASSERT_EQ(small.height(), cam.height);
    Dbi kept = dbi;
    std::fill(kept.depth(), kept.depth() + size_t(cam.width) * size_t(cam.height), 0.5f);
    comp->readBackDepth(kept);
    for (const Dbi* d : {&small, &kept})
        for (int y = 0; y < cam.height; ++y)
            for (int x = 0; x < cam.width; ++x)
                ASSERT_EQ(d->depth(x, y), full.depth(x, y)) << x << "," << y;
    EXPECT_EQ(compare(kept, dbi).maxColorError, 0) << "the colour is not read";
}

TEST_F(CompositorTest, ToolIsHiddenExactlyWhereTheDbiIsNearer) {
    Camera cam = testCamera();
    Dbi dbi = planeDbi(cam);
    GpuMesh burr = comp->upload(makeToolMesh(ToolShape::burr(6.0f)));
    // The burr's centre 2 mm behind the plane, its shaft leaning out through it.
    glm::mat4 model =
        glm::translate(glm::mat4(1), glm::vec3(0, 0, -2)) *
        glm::mat4_cast(glm::rotation(glm::vec3(0, 0, 1), glm::normalize(glm::vec3(0.6f, 0.2f, 1))));
    // The tool alone (DBI background: depth 1 everywhere).
    comp->uploadFull(Dbi(cam.width, cam.height));
    comp->begin(cam);
    comp->draw(burr, model, {0.2f, 0.4f, 0.9f, 1});
    Dbi toolOnly = comp->readBack();
    // The tool composited with the bone.
    comp->uploadFull(dbi);
    comp->begin(cam);
    comp->draw(burr, model, {0.2f, 0.4f, 0.9f, 1});
    Dbi composite = comp->readBack();
    comp->blitTo(0, 0);
    Dbi screen = window->readFramebuffer();

    int hidden = 0, shown = 0;
    for (int y = 0; y < cam.height; ++y)
        for (int x = 0; x < cam.width; ++x) {
            float t = toolOnly.depth(x, y), d = dbi.depth(x, y);
            ASSERT_EQ(std::memcmp(screen.color(x, y), composite.color(x, y), 3), 0)
                << "the window shows the composite 1:1 at " << x << "," << y;
            if (t >= 1.0f)
                continue;
            if (t < d) { // the tool is nearer: it shows
                ++shown;
                ASSERT_EQ(composite.depth(x, y), t) << x << "," << y;
                ASSERT_EQ(std::memcmp(composite.color(x, y), toolOnly.color(x, y), 3), 0);
            } else { // the bone is nearer or equal: the DBI's pixel stays
                ++hidden;
                ASSERT_EQ(composite.depth(x, y), d) << x << "," << y;
                ASSERT_EQ(std::memcmp(composite.color(x, y), kBone, 3), 0) << x << "," << y;
            }
        }
    EXPECT_GT(hidden, 50);
    EXPECT_GT(shown, 100);
    comp->destroy(burr);
}

TEST_F(CompositorTest, SubRectangleUpdateChangesOnlyItsRectangle) {
    Camera cam = testCamera();
    Dbi dbi = planeDbi(cam);
    comp->uploadFull(dbi);
    comp->begin(cam);
    Dbi before = comp->readBack();
    PixelRect rect{50, 60, 40, 30};
    Dbi patch(rect.w, rect.h);
    for (int y = 0; y < rect.h; ++y)
        for (int x = 0; x < rect.w; ++x) {
            uint8_t* c = patch.color(x, y);
            c[0] = 120, c[1] = 40, c[2] = 30, c[3] = 255;
            patch.depth()[patch.index(x, y)] = 0.25f;
        }
    comp->uploadRect(rect, patch);
    comp->begin(cam);
    Dbi after = comp->readBack();
    DbiDiff diff = compare(before, after);
    EXPECT_EQ(diff.bounds, rect);
    EXPECT_EQ(diff.differingPixels, rect.area());
    Dbi expected = dbi;
    expected.apply(patch, rect.x, rect.y);
    EXPECT_TRUE(compare(after, expected).identical()) << compare(after, expected).describe();
}

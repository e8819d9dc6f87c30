// The GPU ray caster (VolumeView) against the CPU Renderer on Mesa llvmpipe (needs a display:
// xvfb-run). Same camera, same volume: depth, hit mask and colour agree, and after an erosion a
// box update brings the GPU picture to the CPU render of the eroded volume.
#include "ui/compositor.h"
#include "ui/volume_view.h"
#include "ui/window.h"

#include "dbi_agreement.h"
#include "gl_window_test.h"

#include "libsim/camera.h"
#include "libsim/dirty_rect.h"
#include "libsim/error.h"
#include "libsim/renderer.h"
#include "libsim/skull.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <sstream>

using namespace trephine;
using namespace trephine::ui;

namespace {

using trephine::testing::Agreement;
using trephine::testing::agree;
using trephine::testing::expectAgreement;

class VolumeViewTest : public trephine::testing::GlWindowTest {
protected:
    void SetUp() override {
        GlWindowTest::SetUp();
        if (window)
            view = std::make_unique<VolumeView>();
    }
    void TearDown() override {
        view.reset();
        GlWindowTest::TearDown();
    }
    std::unique_ptr<VolumeView> view;
};

Camera sphereCamera(const Volume& v) {
    Camera c;
    c.eye = {18.0f, 25.0f, 140.0f}; // off-axis, so rays cross voxel faces obliquely
    c.target = {0, 0, 0};
    c.fovYDeg = 30.0f;
    c.width = c.height = 200;
    fitNearFar(c, glm::vec3(0), 0.5f * glm::length(v.extentMm()));
    return c;
}

} // namespace

TEST_F(VolumeViewTest, SphereMatchesTheCpuRenderer) {
    Volume sphere = makeSphere(64);
    Camera cam = sphereCamera(sphere);
    view->upload(sphere);
    view->render(cam);
    Dbi gpu = view->readBack();
    Dbi cpu = Renderer(sphere).render(cam);
    Agreement a = agree(gpu, cpu, cam, 1.0f);
    expectAgreement(a);
}

TEST_F(VolumeViewTest, SkullMatchesTheCpuRenderer) {
    Volume skull = makeSkull(64);
    for (const char* preset : {"paper", "working"}) {
        SCOPED_TRACE(preset);
        Camera cam = cameraPreset(preset, skull, {200, 200});
        view->upload(skull);
        view->render(cam);
        Dbi gpu = view->readBack();
        Dbi cpu = Renderer(skull).render(cam);
        float voxel = std::min({skull.spacing().x, skull.spacing().y, skull.spacing().z});
        expectAgreement(agree(gpu, cpu, cam, voxel));
    }
}

TEST_F(VolumeViewTest, UpdateBoxShowsTheErosionLikeTheCpuRender) {
    Volume sphere = makeSphere(64);
    Camera cam = sphereCamera(sphere);
    view->upload(sphere);
    view->render(cam);
    Dbi before = view->readBack();
    // Carve a 12^3 box out of the sphere's front, where the camera sees it.
    Box3i box{{26, 30, 44}, {38, 42, 56}};
    sphere.fill(box, 0, Material::Air);
    VolumeUpdateStats st = view->updateBox(sphere, box);
    EXPECT_EQ(st.voxels, 12 * 12 * 12);
    EXPECT_EQ(st.gradientVoxels, 14 * 14 * 14);
    view->render(cam);
    Dbi after = view->readBack();
    Dbi cpu = Renderer(sphere).render(cam);
    expectAgreement(agree(after, cpu, cam, 1.0f));

    // The GPU picture changed, and only where the box projects.
    DbiDiff d = compare(before, after);
    EXPECT_GT(d.differingPixels, 200) << d.describe();
    PixelRect screen = dirtyScreenRect(cam, sphere, box);
    EXPECT_TRUE(screen.contains(d.bounds)) << d.describe();
}

// A volume wider than this OpenGL's 3D textures (less the gradients' apron) is refused with a
// message naming the limit, instead of uploading nothing and drawing a blank view; the view
// stays usable for a volume that fits.
TEST_F(VolumeViewTest, AVolumeTooLargeForTheTexturesIsRefusedWithTheLimit) {
    GLint maxSize = 0;
    glGetIntegerv(GL_MAX_3D_TEXTURE_SIZE, &maxSize);
    ASSERT_GT(maxSize, 8);
    Volume wide({maxSize - 1, 4, 4}, glm::vec3(1.0f)); // fits alone, not with the apron
    try {
        view->upload(wide);
        FAIL() << "a " << maxSize - 1 << "-voxel-wide volume was accepted";
    } catch (const trephine::Error& e) {
        const std::string what = e.what();
        EXPECT_NE(what.find("too large"), std::string::npos) << what;
        EXPECT_NE(what.find(std::to_string(maxSize)), std::string::npos) << what;
    }
    EXPECT_TRUE(view->empty());
    const Volume sphere = makeSphere(32);
    view->upload(sphere);
    EXPECT_FALSE(view->empty());
    EXPECT_EQ(glGetError(), GLenum(GL_NO_ERROR));
}

// Empty-space skipping over the brick texture leaves every pixel as it was: samples sit at the
// same k * dt, and only samples proven below the iso-value are leapt over.
TEST_F(VolumeViewTest, SkippingEmptySpaceChangesNoPixel) {
    Volume skull = makeSkull(64);
    std::vector<Camera> cams;
    for (const char* preset : {"paper", "working", "left"})
        cams.push_back(cameraPreset(preset, skull, {160, 160}));
    skull.fill({{20, 20, 40}, {44, 44, 64}}, 0, Material::Air); // a hole to look into
    view->upload(skull);
    for (const Camera& cam : cams) {
        SCOPED_TRACE(describe(cam));
        view->setSkipEmpty(false);
        view->render(cam);
        const Dbi plain = view->readBack();
        view->setSkipEmpty(true);
        view->render(cam);
        const Dbi skipped = view->readBack();
        EXPECT_TRUE(skipped == plain) << compare(skipped, plain).describe();
        EXPECT_GT(compare(plain, Dbi(160, 160)).differingPixels, 1000) << "the skull shows";
    }
}

// updateBox keeps the brick texture in step both ways: bone set where every brick was empty (a
// plate in the air in front of the sphere) shows, as in the CPU render.
TEST_F(VolumeViewTest, UpdateBoxShowsBoneAddedInEmptySpace) {
    Volume sphere = makeSphere(64);
    Camera cam = sphereCamera(sphere);
    view->upload(sphere);
    const Box3i plate{{24, 24, 60}, {40, 40, 62}}; // in front of the sphere, towards the eye
    for (int z = plate.lo.z; z < plate.hi.z; ++z)
        for (int y = plate.lo.y; y < plate.hi.y; ++y)
            for (int x = plate.lo.x; x < plate.hi.x; ++x)
                sphere.set(x, y, z, 255, Material::Cortical);
    view->updateBox(sphere, plate);
    view->render(cam);
    const Dbi gpu = view->readBack();
    const Dbi cpu = Renderer(sphere).render(cam);
    expectAgreement(agree(gpu, cpu, cam, 1.0f));
    EXPECT_GT(compare(gpu, Renderer(makeSphere(64)).render(cam)).differingPixels, 100)
        << "the plate shows";
}

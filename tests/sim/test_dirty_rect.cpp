// BB_volume -> BB_screen: the projection itself, the conservative cases, and the property that
// matters: after any erosion every pixel that changed lies inside BB_screen.
#include "libsim/dirty_rect.h"

#include "libsim/drill.h"
#include "libsim/renderer.h"
#include "libsim/skull.h"
#include "libsim/thread_pool.h"

#include <glm/gtx/quaternion.hpp>
#include <gtest/gtest.h>
#include <random>

namespace trephine {
namespace {

TEST(DirtyRect, EmptyBoxGivesEmptyRect) {
    Volume v({32, 32, 32}, glm::vec3(1.0f));
    Camera c = cameraPreset("front", v, {100, 80});
    EXPECT_TRUE(dirtyScreenRect(c, v, Box3i{}).empty());
}

TEST(DirtyRect, ProjectsTheGrownCorners) {
    Volume v({64, 64, 64}, glm::vec3(0.5f));
    Camera c = cameraPreset("top", v, {300, 200});
    Box3i box = Box3i::fromMinMax({30, 30, 50}, {34, 33, 52});
    PixelRect r = dirtyScreenRect(c, v, box, 2.0f);
    // By hand: faces 30 - 2 .. 34 + 2 voxels -> (f - 32) * 0.5 mm = -2 .. 2 mm on x, and so on.
    glm::dmat4 vp = viewProjection(c);
    double x0 = 1e9, x1 = -1e9, y0 = 1e9, y1 = -1e9;
    for (int i = 0; i < 8; ++i) {
        glm::dvec3 p((i & 1) ? 2.0 : -2.0, (i & 2) ? 1.5 : -2.0, (i & 4) ? 11.0 : 8.0);
        WindowPoint w = projectToWindow(vp, c, p);
        x0 = std::min(x0, w.window.x), x1 = std::max(x1, w.window.x);
        y0 = std::min(y0, w.window.y), y1 = std::max(y1, w.window.y);
    }
    EXPECT_EQ(r.x, int(std::floor(x0)));
    EXPECT_EQ(r.y, int(std::floor(y0)));
    EXPECT_EQ(r.x + r.w, int(std::ceil(x1)));
    EXPECT_EQ(r.y + r.h, int(std::ceil(y1)));
    // A bigger stencil never gives a smaller rectangle.
    EXPECT_TRUE(dirtyScreenRect(c, v, box, 3.0f).contains(r));
}

TEST(DirtyRect, ClipsToTheWindowAndGoesFullWhenBehindTheEye) {
    Volume v({64, 64, 64}, glm::vec3(1.0f));
    Camera c;
    c.eye = {0, 0, 60};
    c.target = {0, 0, 0};
    c.up = {0, 1, 0};
    c.nearMm = 1;
    c.farMm = 200;
    c.width = 64;
    c.height = 48;
    // Around the eye (z 54..66 mm): corners behind it, so the whole window.
    PixelRect all = dirtyScreenRect(c, v, Box3i::fromMinMax({30, 30, 88}, {34, 34, 92}));
    EXPECT_EQ(all, (PixelRect{0, 0, 64, 48}));
    // Wide (x -34..34 mm) but in front: clipped to the window's width, not its height.
    PixelRect wide = dirtyScreenRect(c, v, Box3i::fromMinMax({0, 30, 30}, {64, 34, 34}));
    EXPECT_EQ(wide.x, 0);
    EXPECT_EQ(wide.w, 64);
    EXPECT_GT(wide.h, 0);
    EXPECT_LT(wide.h, 48);
    // In front of the eye but outside the frustum: empty.
    EXPECT_TRUE(dirtyScreenRect(c, v, Box3i::fromMinMax({60, 30, 80}, {64, 34, 84})).empty());
}

TEST(DirtyRect, FlipRowsConvertsToTopLeftOrigin) {
    PixelRect r{10, 5, 20, 7}; // rows 5..11 from the bottom of a 100-row window
    PixelRect top = flipRows(r, 100);
    EXPECT_EQ(top, (PixelRect{10, 88, 20, 7})); // rows 88..94 from the top
    EXPECT_EQ(flipRows(top, 100), r);
}

// The property BB_screen exists for: render before, drill, render after; every pixel whose colour
// or depth changed lies inside BB_screen. Random burrs of 1-6 mm, random places and depths.
void checkContainment(Volume volume, const std::vector<std::string>& presets, int drills,
                      uint32_t seed) {
    ThreadPool pool;
    Renderer renderer(volume, &pool);
    std::mt19937 rng(seed);
    int nonEmpty = 0;
    for (const std::string& preset : presets) {
        Camera camera = cameraPreset(preset, volume, {180, 150});
        Dbi before = renderer.render(camera);
        for (int i = 0; i < drills; ++i) {
            std::uniform_int_distribution<int> px(0, camera.width - 1), py(0, camera.height - 1);
            RayHit hit;
            for (int tries = 0; tries < 500 && !hit.hit; ++tries)
                hit = renderer.castRay(camera, px(rng), py(rng));
            ASSERT_TRUE(hit.hit);
            float diameter = std::uniform_real_distribution<float>(1.0f, 6.0f)(rng);
            float depth = std::uniform_real_distribution<float>(-1.0f, 3.0f)(rng);
            // Tilt the stroke up to ~45 degrees off the view ray, so boxes are not view-aligned.
            glm::vec3 jitter(std::uniform_real_distribution<float>(-0.7f, 0.7f)(rng),
                             std::uniform_real_distribution<float>(-0.7f, 0.7f)(rng),
                             std::uniform_real_distribution<float>(-0.7f, 0.7f)(rng));
            glm::vec3 dir = glm::normalize(hit.direction + jitter);
            Driller driller(ToolShape::burr(diameter));
            ToolPose pose;
            pose.orientation = glm::rotation(glm::vec3(0, 0, 1), -dir);
            Box3i changed;
            for (int step = 0; step < 8; ++step) {
                pose.position = glm::vec3(hit.position) + dir * (depth + 0.25f * step);
                changed.merge(driller.drill(volume, pose, 1.0f, 0.04f).changed);
            }
            renderer.volumeChanged(changed);
            PixelRect dirty = dirtyScreenRect(camera, volume, changed);
            Dbi after = renderer.render(camera);
            DbiDiff diff = compare(before, after);
            if (diff.differingPixels > 0)
                nonEmpty++;
            ASSERT_TRUE(dirty.contains(diff.bounds)) << preset << " drill " << i << ": BB_screen "
                                                     << describe(dirty) << ", " << diff.describe();
            // And re-rendering only BB_screen into the old frame gives the new frame.
            renderer.render(camera, dirty, before);
            ASSERT_EQ(before, after);
        }
    }
    EXPECT_GT(nonEmpty, drills * int(presets.size()) / 2) << "most drills should change pixels";
}

TEST(DirtyRect, EveryChangedPixelIsInsideBBScreenOnTheSkull) {
    checkContainment(makeSkull(64), {"working", "top", "left", "paper"}, 25, 1234);
}

TEST(DirtyRect, EveryChangedPixelIsInsideBBScreenOnTheSphere) {
    checkContainment(makeSphere(48), {"front", "top"}, 25, 99);
}

// Hard cases for BB_screen: eyes inside the volume or a few voxels from it, views along an axis,
// boxes at the volume's faces and corners, any change of a box's voxels (down to air or up to
// solid). Rendered without skipping or caches, so only the rectangle is under test.
TEST(DirtyRect, HoldsEveryChangedPixelForEyesInsideOrNearTheVolume) {
    std::mt19937 rng(77);
    Volume volume({24, 20, 22}, glm::vec3(1.0f, 1.25f, 0.8f));
    std::uniform_int_distribution<int> byte(0, 255);
    for (int z = 0; z < 22; ++z)
        for (int y = 0; y < 20; ++y)
            for (int x = 0; x < 24; ++x)
                if (byte(rng) < 70)
                    volume.set(x, y, z, uint8_t(byte(rng)), Material::Cortical);
    ThreadPool pool;
    RenderOptions plain;
    plain.skipEmpty = false;
    Renderer renderer(volume, &pool, plain);
    std::uniform_real_distribution<float> unit(-1.0f, 1.0f);
    const glm::vec3 ext = volume.extentMm();
    int cases = 0, changedCases = 0;
    for (int i = 0; i < 300; ++i) {
        SCOPED_TRACE(i);
        Camera c;
        c.width = 48;
        c.height = 40;
        c.fovYDeg = 70.0f;
        c.nearMm = 0.05f;
        c.farMm = 200.0f;
        // Inside the volume or within a few voxels of its faces.
        c.eye = glm::vec3(unit(rng), unit(rng), unit(rng)) * (0.5f * ext + 4.0f);
        if (i % 3 == 0) { // along an axis
            glm::vec3 d(0.0f);
            d[i / 3 % 3] = (i / 9) % 2 ? 1.0f : -1.0f;
            c.target = c.eye + d * 10.0f;
            c.up = d.z != 0.0f ? glm::vec3(0, 1, 0) : glm::vec3(0, 0, 1);
        } else {
            c.target = glm::vec3(unit(rng), unit(rng), unit(rng)) * 0.5f * ext;
            c.up = glm::vec3(0, 0, 1);
            if (glm::length(glm::cross(glm::normalize(c.target - c.eye), c.up)) < 0.1f)
                c.up = glm::vec3(1, 0, 0);
        }
        const Dbi before = renderer.render(c);
        // A box anywhere, often at a face or corner.
        glm::ivec3 lo(0), hi(0);
        for (int a = 0; a < 3; ++a) {
            const int n = volume.dims()[a];
            const int len = std::uniform_int_distribution<int>(1, 5)(rng);
            const int where = std::uniform_int_distribution<int>(0, 2)(rng);
            lo[a] = where == 0   ? 0
                    : where == 1 ? n - len
                                 : std::uniform_int_distribution<int>(0, n - len)(rng);
            hi[a] = lo[a] + len;
        }
        const Box3i box = Box3i::fromMinMax(lo, hi);
        Volume saved = volume;
        const bool up = i % 2 == 0;
        for (int z = lo.z; z < hi.z; ++z)
            for (int y = lo.y; y < hi.y; ++y)
                for (int x = lo.x; x < hi.x; ++x)
                    volume.set(x, y, z, up ? 255 : 0, up ? Material::Cortical : Material::Air);
        renderer.rebuild();
        const Dbi after = renderer.render(c);
        const DbiDiff diff = compare(before, after);
        const PixelRect dirty = dirtyScreenRect(c, volume, box);
        ++cases;
        if (diff.differingPixels > 0)
            ++changedCases;
        ASSERT_TRUE(diff.differingPixels == 0 || dirty.contains(diff.bounds))
            << describe(c) << ": BB_screen " << describe(dirty) << ", " << diff.describe();
        volume = saved;
        renderer.rebuild();
    }
    EXPECT_GT(changedCases, cases / 4);
}

} // namespace
} // namespace trephine

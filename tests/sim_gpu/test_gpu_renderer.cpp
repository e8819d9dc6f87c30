// The server's GPU renderer through EGL with no display (Mesa's llvmpipe here): a rectangle is
// its full frame bit for bit, it agrees with the CPU Renderer within VolumeView's tolerance on
// skull:128 views, and after an erosion the uploaded box shows it.
#include "libsim_gpu/gl.h"
#include "libsim_gpu/gpu_renderer.h"
#include "libsim_gpu/volume_raycaster.h"

#include "dbi_agreement.h"
#include "gpu_test.h"

#include "libsim/dirty_rect.h"
#include "libsim/error.h"
#include "libsim/renderer.h"
#include "libsim/skull.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <memory>
#include <random>
#include <thread>

using namespace trephine;
using trephine::testing::agree;
using trephine::testing::expectAgreement;

namespace {

using GpuRendererTest = trephine::testing::GpuTest;

float smallestSpacing(const Volume& v) {
    return std::min({v.spacing().x, v.spacing().y, v.spacing().z});
}

// Random rectangles (some reaching past the window, clipped) and single pixels, each rendered
// alone into a background frame: their pixels are the full frame's, the rest stays background.
void expectRectanglesAreTheFullFrame(gpu::GpuRenderer& r, const Camera& cam, unsigned seed) {
    const Dbi full = r.render(cam);
    std::mt19937 rng(seed);
    auto pick = [&](int lo, int hi) { return std::uniform_int_distribution<int>(lo, hi)(rng); };
    for (int i = 0; i < 24; ++i) {
        PixelRect rect = i < 6 ? PixelRect{pick(0, cam.width - 1), pick(0, cam.height - 1), 1, 1}
                               : PixelRect{pick(-20, cam.width - 1), pick(-20, cam.height - 1),
                                           pick(1, cam.width), pick(1, cam.height)};
        SCOPED_TRACE(describe(rect));
        Dbi frame(cam.width, cam.height);
        r.render(cam, rect, frame, nullptr);
        const PixelRect in = intersect(rect, frame.bounds());
        EXPECT_TRUE(frame.extract(in) == full.extract(in));
        frame.apply(Dbi(in.w, in.h), in.x, in.y); // background where the rectangle was
        EXPECT_TRUE(frame == Dbi(cam.width, cam.height)) << "pixels outside the rectangle";
    }
}

} // namespace

TEST_F(GpuRendererTest, ARectangleIsItsFullFrameBitForBit) {
    Volume skull = makeSkull(64);
    gpu::GpuRenderer r(skull, egl);
    for (const char* preset : {"working", "paper"}) {
        SCOPED_TRACE(preset);
        expectRectanglesAreTheFullFrame(r, cameraPreset(preset, skull, {200, 160}), 7);
    }
    // And after an erosion uploaded as a box.
    const Box3i hole{{20, 20, 40}, {44, 44, 64}};
    skull.fill(hole, 0, Material::Air);
    r.volumeChanged(hole);
    expectRectanglesAreTheFullFrame(r, cameraPreset("paper", skull, {200, 160}), 11);
}

TEST_F(GpuRendererTest, MatchesTheCpuRendererOnSkull128Views) {
    const Volume skull = makeSkull(128);
    gpu::GpuRenderer gpuRenderer(skull, egl);
    const Renderer cpuRenderer(skull);
    for (const char* preset : {"working", "paper", "top", "front", "left", "back"}) {
        SCOPED_TRACE(preset);
        const Camera cam = cameraPreset(preset, skull, {256, 256});
        expectAgreement(
            agree(gpuRenderer.render(cam), cpuRenderer.render(cam), cam, smallestSpacing(skull)));
    }
}

// A cut into the bone the working view looks at: the GPU's box upload shows it as the CPU
// renderer does, and the picture changes only inside BB_screen.
TEST_F(GpuRendererTest, AnErodedBoxShowsAsInTheCpuRender) {
    Volume skull = makeSkull(128);
    const Camera cam = cameraPreset("working", skull, {256, 256});
    gpu::GpuRenderer gpuRenderer(skull, egl);
    Renderer cpuRenderer(skull);
    const Dbi before = gpuRenderer.render(cam);
    const RayHit centre = cpuRenderer.castRay(cam, cam.width / 2, cam.height / 2);
    ASSERT_TRUE(centre.hit);
    const glm::ivec3 v = glm::ivec3(
        glm::floor(glm::vec3(centre.position) / skull.spacing() + glm::vec3(skull.dims()) * 0.5f));
    const Box3i cut{v - 6, v + 6};
    skull.fill(cut, 0, Material::Air);
    gpuRenderer.volumeChanged(cut);
    cpuRenderer.volumeChanged(cut);
    const Dbi after = gpuRenderer.render(cam);
    expectAgreement(agree(after, cpuRenderer.render(cam), cam, smallestSpacing(skull)));
    const DbiDiff d = compare(before, after);
    EXPECT_GT(d.differingPixels, 100) << d.describe();
    EXPECT_TRUE(dirtyScreenRect(cam, skull, cut).contains(d.bounds)) << d.describe();
}

TEST(RendererChoice, NamesAreCpuGpuOrAuto) {
    EXPECT_EQ(gpu::parseRendererChoice("cpu"), gpu::RendererChoice::Cpu);
    EXPECT_EQ(gpu::parseRendererChoice("gpu"), gpu::RendererChoice::Gpu);
    EXPECT_EQ(gpu::parseRendererChoice("auto"), gpu::RendererChoice::Auto);
    try {
        gpu::parseRendererChoice("GPU0");
        FAIL() << "GPU0 was taken";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("cpu, gpu or auto"), std::string::npos) << e.what();
    }
}

// cpu never opens EGL; gpu takes whatever GL EGL gives (llvmpipe too); auto takes it only when
// it is not a software renderer, and says why it did not.
TEST_F(GpuRendererTest, AutoCountsASoftwareRendererAsNoGpu) {
    std::string why;
    EXPECT_FALSE(gpu::chooseRenderer(gpu::RendererChoice::Cpu, &why));
    EXPECT_NE(why.find("CPU"), std::string::npos) << why;
    EXPECT_TRUE(gpu::chooseRenderer(gpu::RendererChoice::Gpu, &why));
    EXPECT_NE(why.find(egl->info().renderer), std::string::npos) << why;
    const bool automatic = bool(gpu::chooseRenderer(gpu::RendererChoice::Auto, &why));
    EXPECT_EQ(automatic, !egl->info().software) << why;
    if (egl->info().software) {
        EXPECT_NE(why.find("software"), std::string::npos) << why;
    }
}

TEST(GlRendererName, SoftwareRasterisersAreKnownByName) {
    EXPECT_TRUE(gpu::isSoftwareRenderer("llvmpipe (LLVM 15.0.6, 256 bits)"));
    EXPECT_TRUE(gpu::isSoftwareRenderer("softpipe"));
    EXPECT_TRUE(gpu::isSoftwareRenderer("Google SwiftShader"));
    EXPECT_FALSE(gpu::isSoftwareRenderer("NVIDIA H200/PCIe/SSE2"));
    EXPECT_FALSE(gpu::isSoftwareRenderer("AMD Radeon RX 7900 XTX (radeonsi, navi31, LLVM 15.0.7)"));
}

// Which GL answered (scripts/gpu-check prints it): an OpenGL of at least 3.3, and 4.3 (compute
// shaders) when the context says so, named.
TEST_F(GpuRendererTest, EglContextSaysWhichRendererAnswered) {
    std::printf("  GL renderer: %s, OpenGL %s, %s shaders%s\n", egl->info().renderer.c_str(),
                egl->info().version.c_str(), egl->info().compute ? "compute" : "fragment",
                egl->info().software ? " (software)" : "");
    EXPECT_FALSE(egl->info().renderer.empty());
    int major = 0, minor = 0;
    ASSERT_EQ(std::sscanf(egl->info().version.c_str(), "%d.%d", &major, &minor), 2)
        << egl->info().version;
    EXPECT_GE(major * 10 + minor, egl->info().compute ? 43 : 33) << egl->info().version;
}

// A driver without OpenGL 4.3 still renders the server's pictures on its GPU: on a 3.3 context,
// as such a driver gives, the renderer casts the same ray in fragments, so its frames, its
// rectangles and its eroded boxes are the compute renderer's pixels bit for bit. The context
// goes at the end and the process's own one stays.
TEST_F(GpuRendererTest, WithoutOpenGl43TheRendererCastsInFragments) {
    Volume skull = makeSkull(64);
    gpu::GpuRenderer shared(skull, egl);
    // The working view is placed on the bone's surface: placed before the cut.
    const Camera views[] = {cameraPreset("working", skull, {200, 160}),
                            cameraPreset("paper", skull, {200, 160})};
    const Camera& paper = views[1];
    Dbi last;
    {
        const std::shared_ptr<gpu::EglContext> gl33 = gpu::EglContext::open(false);
        EXPECT_FALSE(gl33->info().compute);
        gpu::GpuRenderer fragments(skull, gl33);
        EXPECT_NE(fragments.describe().find("fragment shaders"), std::string::npos)
            << fragments.describe();
        if (egl->info().compute) {
            EXPECT_EQ(shared.describe().find("fragment"), std::string::npos) << shared.describe();
        }
        auto expectTheSame = [&](unsigned seed) {
            for (const Camera& cam : views) {
                const DbiDiff d = compare(fragments.render(cam), shared.render(cam));
                EXPECT_EQ(d.differingPixels, 0) << d.describe();
                expectRectanglesAreTheFullFrame(fragments, cam, seed);
            }
        };
        expectTheSame(5);
        const Box3i hole{{20, 20, 40}, {44, 44, 64}};
        skull.fill(hole, 0, Material::Air);
        fragments.volumeChanged(hole);
        shared.volumeChanged(hole);
        expectTheSame(13);
        last = fragments.render(paper);
        // A view wider than the GL's viewport is refused in one line, not read back undefined.
        GLint most[2] = {};
        {
            gpu::EglContext::Current current(*gl33);
            glGetIntegerv(GL_MAX_VIEWPORT_DIMS, most);
        }
        const Camera wide = cameraPreset("paper", skull, {most[0] + 1, 1});
        try {
            Dbi frame(wide.width, wide.height);
            fragments.render(wide, frame.bounds(), frame, nullptr);
            FAIL() << "a view wider than the viewport's " << most[0] << " pixels was rendered";
        } catch (const Error& e) {
            EXPECT_NE(std::string(e.what()).find("viewport"), std::string::npos) << e.what();
        }
        EXPECT_TRUE(fragments.render(paper) == last) << "after the refusal";
    }
    EXPECT_TRUE(shared.render(paper) == last) << "the process's context after the other went";
}

// The server's compute pipeline and the window's fragment one run the same ray: on the same
// views and rectangles (the frame, a rectangle inside, a band of rows as the server's step
// renders, and one of the band's area but another shape) they give the same pixels.
TEST_F(GpuRendererTest, TheComputeAndFragmentPipelinesCastTheSameRays) {
    if (!egl->info().compute)
        GTEST_SKIP() << "OpenGL " << egl->info().version << ": no compute shaders";
    const Volume skull = makeSkull(64);
    gpu::EglContext::Current current(*egl);
    gpu::VolumeRaycaster compute(gpu::VolumeRaycaster::Pipeline::Compute);
    gpu::VolumeRaycaster fragment(gpu::VolumeRaycaster::Pipeline::Fragment);
    { // nothing uploaded: nothing cast or read back
        const Camera cam = cameraPreset("working", skull, {40, 30});
        Dbi none(cam.width, cam.height);
        compute.render(cam);
        compute.readBack(none);
        EXPECT_TRUE(none == Dbi(cam.width, cam.height));
    }
    compute.upload(skull);
    fragment.upload(skull);
    for (const char* preset : {"working", "paper", "left"}) {
        SCOPED_TRACE(preset);
        const Camera cam = cameraPreset(preset, skull, {150, 120});
        for (const PixelRect rect : {PixelRect{0, 0, 150, 120}, PixelRect{37, 11, 61, 70},
                                     PixelRect{0, 37, 150, 4}, PixelRect{20, 50, 75, 8}}) {
            SCOPED_TRACE(describe(rect));
            Dbi a(cam.width, cam.height), b(cam.width, cam.height);
            compute.render(cam, rect);
            compute.readBack(a);
            fragment.render(cam, rect);
            fragment.readBack(b);
            const DbiDiff d = compare(a, b);
            EXPECT_EQ(d.differingPixels, 0) << d.describe();
        }
    }
}

// The server renders on its simulation thread, an inspection may come from another: the context
// is made current for each call and released after, whichever thread made it.
TEST_F(GpuRendererTest, RendersFromAnyThreadOneAtATime) {
    const Volume skull = makeSkull(64);
    const Camera cam = cameraPreset("working", skull, {96, 96});
    gpu::GpuRenderer r(skull, egl);
    const Dbi here = r.render(cam);
    for (int i = 0; i < 3; ++i) {
        Dbi there;
        std::thread([&] { there = r.render(cam); }).join();
        EXPECT_TRUE(there == here) << "from another thread, pass " << i;
        EXPECT_TRUE(r.render(cam) == here) << "back on this thread, pass " << i;
    }
}

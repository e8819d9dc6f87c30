// The ray caster: exact GL depth, background pixels, per-pixel independence (rectangles, tiles,
// threads), empty-space skipping that changes nothing, the brick grid after erosion, and a CPU
// composite of client geometry against the DBI.
#include "libsim/renderer.h"

#include "libsim/brick_grid.h"
#include "libsim/dirty_rect.h"
#include "libsim/drill.h"
#include "libsim/skull.h"
#include "libsim/thread_pool.h"

#include <atomic>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstring>
#include <glm/gtc/quaternion.hpp>
#include <glm/gtx/quaternion.hpp>
#include <gtest/gtest.h>
#include <latch>
#include <mutex>
#include <pthread.h>
#include <random>
#include <set>
#include <string>
#include <sys/resource.h>
#include <sys/syscall.h>
#include <thread>
#include <unistd.h>
#include <vector>

namespace trephine {
namespace {

// The ray through a pixel centre, computed independently of the renderer from the matrices.
struct TestRay {
    glm::dvec3 origin;
    glm::dvec3 dir;
};
TestRay pixelRay(const Camera& c, double px, double py) {
    glm::dmat4 inv = glm::inverse(viewProjection(c));
    glm::dvec2 ndc(px / c.width * 2.0 - 1.0, py / c.height * 2.0 - 1.0);
    glm::dvec4 a = inv * glm::dvec4(ndc, -1.0, 1.0), b = inv * glm::dvec4(ndc, 1.0, 1.0);
    glm::dvec3 pa = glm::dvec3(a) / a.w, pb = glm::dvec3(b) / b.w;
    return {glm::dvec3(c.eye), glm::normalize(pb - pa)};
}

// A random camera around (or inside) a volume of bounding radius r: eye at r x [dist) along a
// random direction, looking near the centre (within targetScale r), random roll and field of view.
struct RandomCameras {
    std::uniform_real_distribution<float> unit{-1.0f, 1.0f}, dist, fov;
    float targetScale;

    RandomCameras(float distLo, float distHi, float fovLo, float fovHi, float targetScale = 0.3f)
        : dist(distLo, distHi), fov(fovLo, fovHi), targetScale(targetScale) {}

    Camera operator()(std::mt19937& rng, float r, int width, int height) {
        Camera c;
        glm::vec3 dir = glm::normalize(glm::vec3(unit(rng), unit(rng), unit(rng)) + 1e-3f);
        c.eye = dir * r * dist(rng);
        c.target = glm::vec3(unit(rng), unit(rng), unit(rng)) * r * targetScale;
        c.up = glm::normalize(glm::cross(dir, glm::vec3(unit(rng), unit(rng), unit(rng))));
        c.fovYDeg = fov(rng);
        c.width = width;
        c.height = height;
        fitNearFar(c, glm::vec3(0.0f), r);
        return c;
    }
};

bool isBackground(const Dbi& d, int x, int y) {
    return d.depth(x, y) == kBackgroundDepth && std::memcmp(d.color(x, y), kBackgroundRgba, 4) == 0;
}

// Drills a few random burr strokes into bone that `camera` sees; returns the changed box.
Box3i drillSomewhere(Volume& volume, const Renderer& renderer, const Camera& camera,
                     std::mt19937& rng) {
    std::uniform_int_distribution<int> px(0, camera.width - 1), py(0, camera.height - 1);
    std::uniform_real_distribution<float> diameter(1.0f, 6.0f), depth(-1.0f, 4.0f);
    for (int attempt = 0; attempt < 200; ++attempt) {
        RayHit hit = renderer.castRay(camera, px(rng), py(rng));
        if (!hit.hit)
            continue;
        Driller driller(ToolShape::burr(diameter(rng)));
        ToolPose pose;
        pose.orientation = glm::rotation(glm::vec3(0, 0, 1), -hit.direction);
        glm::vec3 start = glm::vec3(hit.position) + hit.direction * depth(rng);
        Box3i changed;
        for (int step = 0; step < 6; ++step) {
            pose.position = start + hit.direction * (0.3f * step);
            changed.merge(driller.drill(volume, pose, 1.0f, 0.05f).changed);
        }
        if (!changed.empty())
            return changed;
    }
    ADD_FAILURE() << "found no bone to drill";
    return {};
}

// A view as the server keeps one: its frame and hit cache, first filled by a full render.
struct CachedView {
    Camera camera;
    HitCache cache;
    Dbi frame;
};

// The working, top, left and paper views of `volume` at 140 x 110.
std::vector<CachedView> cachedViews(const Renderer& renderer, const Volume& volume) {
    std::vector<CachedView> views;
    for (const char* preset : {"working", "top", "left", "paper"}) {
        CachedView v{cameraPreset(preset, volume, {140, 110}), {}, {}};
        v.frame = renderer.render(v.camera, &v.cache);
        views.push_back(std::move(v));
    }
    return views;
}

TEST(Renderer, DepthOnTheSphereIsTheAnalyticSurfaceDepth) {
    const int n = 64;
    Volume sphere = makeSphere(n);
    const double radius = sphereRadiusMm(n);
    ThreadPool pool;
    Renderer renderer(sphere, &pool);
    for (const char* preset : {"front", "top", "working"}) {
        SCOPED_TRACE(preset);
        Camera c = cameraPreset(preset, sphere, {200, 160});
        Dbi dbi = renderer.render(c);
        glm::dmat4 vp = viewProjection(c);
        int compared = 0, background = 0;
        double worst = 0.0;
        for (int y = 0; y < c.height; ++y)
            for (int x = 0; x < c.width; ++x) {
                TestRay r = pixelRay(c, x + 0.5, y + 0.5);
                // Closest approach of the ray to the centre (the origin).
                double tc = -glm::dot(r.origin, r.dir);
                double miss = glm::length(r.origin + tc * r.dir);
                if (miss > radius + 2.5) { // beyond the density ramp and the trilinear support
                    EXPECT_TRUE(isBackground(dbi, x, y)) << x << "," << y;
                    background++;
                    continue;
                }
                if (miss > radius * 0.95) // grazing rays: depth error grows as 1 / cos
                    continue;
                ASSERT_LT(dbi.depth(x, y), 1.0f) << x << "," << y;
                EXPECT_EQ(dbi.color(x, y)[3], 255);
                double t = tc - std::sqrt(radius * radius - miss * miss);
                glm::dvec3 surface = r.origin + t * r.dir;
                double expectedZ = eyeZFromWindowDepth(c, windowDepth(vp, surface));
                double gotZ = eyeZFromWindowDepth(c, dbi.depth(x, y));
                // Along the ray the iso-surface error (makeSphere: ~0.01 mm) grows by 1 / cos of
                // the incidence angle, at most ~3.2 here; the refinement is exact to ~1e-3 mm and
                // float depth adds ~1e-4 mm. 0.05 mm is a twentieth of a voxel.
                double err = std::abs(gotZ - expectedZ);
                worst = std::max(worst, err);
                EXPECT_LT(err, 0.05) << x << "," << y;
                compared++;
            }
        EXPECT_GT(compared, 500);
        EXPECT_GT(background, 1000);
        std::printf("[ info ] %s: %d pixels compared, worst eye-z error %.4f mm\n", preset,
                    compared, worst);
    }
}

TEST(Renderer, EmptyVolumeGivesBackgroundEverywhere) {
    Volume empty({32, 32, 32}, glm::vec3(1.0f));
    Renderer renderer(empty);
    Camera c = cameraPreset("front", empty, {40, 30});
    EXPECT_EQ(renderer.render(c), Dbi(40, 30));
}

TEST(Renderer, RectangleRenderIsBitForBitTheFullRender) {
    Volume skull = makeSkull(64);
    ThreadPool pool;
    Renderer renderer(skull, &pool);
    std::mt19937 rng(7);
    for (const char* preset : {"working", "top", "left"}) {
        SCOPED_TRACE(preset);
        Camera c = cameraPreset(preset, skull, {150, 110});
        Dbi full = renderer.render(c);
        for (int i = 0; i < 20; ++i) {
            std::uniform_int_distribution<int> x0(0, c.width - 1), y0(0, c.height - 1);
            PixelRect r{x0(rng), y0(rng), 0, 0};
            r.w = std::uniform_int_distribution<int>(1, c.width - r.x)(rng);
            r.h = std::uniform_int_distribution<int>(1, c.height - r.y)(rng);
            Dbi part = renderer.renderRect(c, r);
            ASSERT_EQ(part, full.extract(r)) << describe(r);
            // Rendering into a frame touches only the rectangle.
            Dbi frame(c.width, c.height);
            renderer.render(c, r, frame);
            Dbi expected(c.width, c.height);
            expected.apply(full.extract(r), r.x, r.y);
            ASSERT_EQ(frame, expected) << describe(r);
        }
        // Single pixels, one thread, other tile sizes.
        Renderer single(skull, nullptr, RenderOptions{.tileSize = 7});
        EXPECT_EQ(single.render(c), full);
        for (int i = 0; i < 50; ++i) {
            int x = std::uniform_int_distribution<int>(0, c.width - 1)(rng);
            int y = std::uniform_int_distribution<int>(0, c.height - 1)(rng);
            EXPECT_EQ(single.renderRect(c, {x, y, 1, 1}), full.extract({x, y, 1, 1}));
        }
    }
}

// A new image is the background; an unfilled one has only its size until written, and an
// extracted rectangle is exactly the pixels it covers.
TEST(Dbi, ANewImageIsBackgroundAndAnExtractIsItsRectangle) {
    const Dbi blank(7, 5);
    for (int y = 0; y < 5; ++y)
        for (int x = 0; x < 7; ++x) {
            ASSERT_EQ(std::memcmp(blank.color(x, y), kBackgroundRgba, 4), 0) << x << "," << y;
            ASSERT_EQ(blank.depth(x, y), kBackgroundDepth) << x << "," << y;
        }
    Dbi image = Dbi::unfilled(7, 5);
    EXPECT_EQ(image.bounds(), PixelRect(0, 0, 7, 5));
    for (int i = 0; i < 35; ++i) {
        std::memset(image.color() + 4 * i, i, 4);
        image.depth()[i] = float(i) / 35.0f;
    }
    const Dbi part = image.extract({2, 1, 4, 3});
    ASSERT_EQ(part.bounds(), PixelRect(0, 0, 4, 3));
    for (int y = 0; y < 3; ++y)
        for (int x = 0; x < 4; ++x) {
            EXPECT_EQ(std::memcmp(part.color(x, y), image.color(x + 2, y + 1), 4), 0);
            EXPECT_EQ(part.depth(x, y), image.depth(x + 2, y + 1));
        }
}

// An empty volume renders the background into every pixel of the rectangle, whole or in bulk
// pieces: a server's new frames start unfilled.
TEST(Renderer, AnEmptyVolumeRendersTheBackgroundEverywhere) {
    const Camera c = cameraPreset("top", makeSkull(32), {9, 7});
    Volume none;
    Renderer renderer(none);
    Dbi frame = Dbi::unfilled(9, 7);
    auto scribble = [&] {
        std::memset(frame.color(), 0x55, 4 * 9 * 7);
        std::fill_n(frame.depth(), 9 * 7, 0.5f);
    };
    scribble();
    renderer.render(c, {0, 0, 9, 7}, frame, nullptr);
    EXPECT_EQ(frame, Dbi(9, 7));
    scribble();
    HitCache cache;
    EXPECT_EQ(renderer.renderBulk(
                  c, {0, 0, 9, 7}, frame, &cache, [] { return false; }, 0),
              9);
    EXPECT_EQ(frame, Dbi(9, 7));
}

// The pool returns only when every item has run, each exactly once, also when its workers wake
// late (more threads than cores) and for jobs smaller than the pool; back-to-back jobs never see
// each other's items.
TEST(ThreadPool, RunsEveryItemOnceAndWaitsForAll) {
    for (int threads : {1, 2, 5}) {
        SCOPED_TRACE(threads);
        ThreadPool pool(threads);
        EXPECT_EQ(pool.size(), threads);
        std::mt19937 rng(3);
        for (int job = 0; job < 300; ++job) {
            int count = std::uniform_int_distribution<int>(0, 40)(rng);
            std::vector<std::atomic<int>> hits(size_t(count) + 1);
            std::atomic<int> done{0};
            pool.parallelFor(count, [&](int i) {
                if (i % 7 == 3)
                    std::this_thread::yield();
                hits[size_t(i)].fetch_add(1);
                done.fetch_add(1);
            });
            ASSERT_EQ(done.load(), count);
            for (int i = 0; i < count; ++i)
                ASSERT_EQ(hits[size_t(i)].load(), 1) << "job " << job << " item " << i;
            ASSERT_EQ(hits[size_t(count)].load(), 0);
        }
    }
}

// The workers are named after their pool ("render-1", ...; cut to Linux's 15 bytes), the caller
// keeps its own name. Every item waits until all have started, so each thread runs exactly one.
TEST(ThreadPool, NamesItsWorkersAfterThePool) {
    auto namesOf = [](ThreadPool& pool) {
        std::latch started(pool.size());
        std::mutex mutex;
        std::multiset<std::string> names;
        pool.parallelFor(pool.size(), [&](int) {
            char name[16] = {};
            pthread_getname_np(pthread_self(), name, sizeof name);
            {
                std::lock_guard lock(mutex);
                names.insert(name);
            }
            started.arrive_and_wait();
        });
        return names;
    };
    char caller[16] = {};
    pthread_getname_np(pthread_self(), caller, sizeof caller);
    ThreadPool render(3, "render");
    EXPECT_EQ(namesOf(render), (std::multiset<std::string>{caller, "render-1", "render-2"}));
    ThreadPool longName(2, "a-very-long-pool-name");
    EXPECT_EQ(namesOf(longName), (std::multiset<std::string>{caller, "a-very-long-p-1"}));
}

// A job that may stop does its first items and no others, each once: `atLeast` of them without
// asking, then as many as were started before `stop` said so (asked from any thread; a worker's
// first item is claimed without asking), exactly those on one thread.
TEST(ThreadPool, AJobThatStopsHasDoneItsFirstItemsAndNoOthers) {
    for (int threads : {1, 2, 5}) {
        SCOPED_TRACE(threads);
        ThreadPool pool(threads);
        std::mt19937 rng(5);
        for (int job = 0; job < 300; ++job) {
            const int count = std::uniform_int_distribution<int>(1, 60)(rng);
            const int stopAfter = std::uniform_int_distribution<int>(0, 70)(rng);
            const int atLeast = std::uniform_int_distribution<int>(0, 8)(rng);
            std::vector<std::atomic<int>> hits(static_cast<size_t>(count));
            std::atomic<int> done{0};
            const int got = pool.parallelForUntil(
                count,
                [&](int i) {
                    if (i % 5 == 2)
                        std::this_thread::yield();
                    hits[size_t(i)].fetch_add(1);
                    done.fetch_add(1);
                },
                [&] { return done.load() >= stopAfter; }, atLeast);
            ASSERT_EQ(done.load(), got) << "job " << job;
            const int owed = std::min(count, std::max(atLeast, stopAfter));
            if (threads == 1) {
                ASSERT_EQ(got, owed) << "job " << job;
            }
            ASSERT_GE(got, owed) << "job " << job;
            ASSERT_LE(got, std::min(count, owed + threads)) << "job " << job;
            for (int i = 0; i < count; ++i)
                ASSERT_EQ(hits[size_t(i)].load(), i < got ? 1 : 0)
                    << "job " << job << " item " << i;
        }
    }
}

// A background pool's work runs on its workers, at its nice value; the caller only waits.
TEST(ThreadPool, ABackgroundPoolsWorkRunsOnItsWorkersAtItsNiceValue) {
    ThreadPool background(2, "bulk", 7);
    EXPECT_EQ(background.size(), 2);
    const pid_t caller = pid_t(syscall(SYS_gettid));
    const int callerNice = getpriority(PRIO_PROCESS, id_t(caller)); // 0, unless run under nice
    std::mutex mutex;
    std::set<pid_t> threads;
    std::set<int> nices;
    for (int job = 0; job < 20; ++job)
        background.parallelFor(8, [&](int) {
            const pid_t self = pid_t(syscall(SYS_gettid));
            errno = 0;
            const int nice = getpriority(PRIO_PROCESS, id_t(self));
            std::lock_guard lock(mutex);
            threads.insert(self);
            nices.insert(nice);
        });
    EXPECT_EQ(threads.count(caller), 0u);
    EXPECT_LE(threads.size(), 2u);
    EXPECT_EQ(nices, std::set<int>{7});
    EXPECT_EQ(getpriority(PRIO_PROCESS, id_t(caller)), callerNice) << "the caller keeps its own";
    // Stopped at once, it does the first 3, and at most each worker's first item more.
    const int stopped = background.parallelForUntil(
        8, [](int) {}, [] { return true; }, 3);
    EXPECT_GE(stopped, 3);
    EXPECT_LE(stopped, 5);
    // Owed more than it has, it does them all, each once, and no more.
    std::vector<std::atomic<int>> hits(20);
    EXPECT_EQ(background.parallelForUntil(
                  8,
                  [&](int i) {
                      hits[size_t(i)].fetch_add(1);
                      std::this_thread::sleep_for(std::chrono::milliseconds(1));
                  },
                  [] { return true; }, 20),
              8);
    for (int i = 0; i < 20; ++i)
        EXPECT_EQ(hits[size_t(i)].load(), i < 8 ? 1 : 0) << "item " << i;
}

// A background pool's workers may wait long for the CPU. Nudged, the waiting caller asks `stop`
// itself: it does the first `atLeast` items the workers have not claimed, claims no others, and
// waits only for the items the workers run.
TEST(ThreadPool, ANudgedCallerStopsAJobItsWorkersAreNotRunning) {
    ThreadPool background(2, "bulk", 7);
    std::atomic<bool> stop{false};
    std::latch busy(2);               // both workers hold an item
    std::atomic<bool> release{false}; // ... until this
    std::atomic<int> byCaller{0};
    std::vector<std::atomic<int>> hits(100);
    int got = -1;
    std::thread job([&] {
        const pid_t self = pid_t(syscall(SYS_gettid));
        got = background.parallelForUntil(
            100,
            [&](int i) {
                hits[size_t(i)].fetch_add(1);
                if (pid_t(syscall(SYS_gettid)) == self) {
                    byCaller.fetch_add(1);
                    return;
                }
                busy.count_down();
                while (!release.load())
                    std::this_thread::sleep_for(std::chrono::milliseconds(1));
            },
            [&] { return stop.load(); }, 5);
    });
    busy.wait();
    stop = true;
    background.nudge();
    // The caller does items 2-4 while the workers still hold 0 and 1.
    for (int waited = 0; byCaller.load() < 3 && waited < 10000; ++waited)
        std::this_thread::sleep_for(std::chrono::milliseconds(1));
    EXPECT_EQ(byCaller.load(), 3);
    release = true;
    job.join();
    EXPECT_EQ(got, 5);
    for (int i = 0; i < 100; ++i)
        ASSERT_EQ(hits[size_t(i)].load(), i < 5 ? 1 : 0) << "item " << i;
}

// Bulk pieces (columns of tiles, stopped anywhere, on a background pool) assemble the full
// frame bit for bit, through the hit cache too.
TEST(Renderer, BulkPiecesStoppedAnywhereChangeNoBit) {
    Volume skull = makeSkull(48);
    ThreadPool pool(2), bulk(2, "bulk", 5);
    Renderer renderer(skull, &pool);
    renderer.setBulkPool(&bulk);
    std::mt19937 rng(11);
    for (const char* preset : {"paper", "top"}) {
        SCOPED_TRACE(preset);
        const Camera c = cameraPreset(preset, skull, {131, 77});
        const Dbi reference = renderer.render(c);
        Dbi frame(c.width, c.height);
        HitCache cache;
        int pieces = 0;
        for (int y = 0; y < c.height;) {
            const int rows = std::min(c.height - y, 1 + int(rng() % 20));
            for (int x = 0; x < c.width; ++pieces) {
                std::atomic<int> asked{0};
                const int stopAt = int(rng() % 4);
                const int w = renderer.renderBulk(c, {x, y, c.width - x, rows}, frame, &cache,
                                                  [&] { return ++asked > stopAt; });
                ASSERT_GT(w, 0);
                x += w;
            }
            y += rows;
        }
        EXPECT_GT(pieces, 2 * (c.height / 20)) << "pieces stopped part-way";
        EXPECT_TRUE(frame == reference) << compare(frame, reference).describe();
        // Through the cache filled above, and stopped after `atLeast` pixels' worth: two
        // columns, and at most one more for each worker that claimed its first without asking.
        Dbi again(c.width, c.height);
        const int w = renderer.renderBulk(
            c, {0, 0, c.width, c.height}, again, &cache, [] { return true; }, 16 * c.height + 1);
        EXPECT_GE(w, 32);
        EXPECT_LE(w, 32 + 16 * bulk.size());
        EXPECT_EQ(renderer.renderBulk(c, {w, 0, c.width - w, c.height}, again, &cache,
                                      [] { return false; }),
                  c.width - w);
        EXPECT_TRUE(again == reference);
    }
}

// Tiles of any size over a pool of any size give the same image (items are claimed dynamically).
TEST(Renderer, TileSizeAndThreadsChangeNoBit) {
    Volume skull = makeSkull(48);
    Camera c = cameraPreset("working", skull, {97, 61});
    Dbi reference = Renderer(skull, nullptr, RenderOptions{.tileSize = 97}).render(c);
    for (int threads : {2, 3}) {
        ThreadPool pool(threads);
        for (int tile : {4, 16, 32})
            EXPECT_EQ(Renderer(skull, &pool, RenderOptions{.tileSize = tile}).render(c), reference)
                << threads << " threads, tile " << tile;
    }
}

TEST(Renderer, SkippingEmptySpaceChangesNoBit) {
    Volume skull = makeSkull(64);
    ThreadPool pool;
    Renderer skipping(skull, &pool);
    Renderer marching(skull, &pool, RenderOptions{.skipEmpty = false});
    for (const std::string& preset : cameraPresetNames()) {
        SCOPED_TRACE(preset);
        Camera c = cameraPreset(preset, skull, {120, 100});
        Dbi a = skipping.render(c);
        Dbi b = marching.render(c);
        EXPECT_TRUE(a == b) << compare(a, b).describe();
    }
}

// Rays nearly along a volume axis leap down columns of empty bricks (BrickGrid::run): the update
// study's view of holes cut to increasing depth, whose rays run beside the cut's walls, renders
// bit for bit as without skipping, uncached and through the hit cache.
TEST(Renderer, ColumnLeapsBesideCutWallsChangeNoBit) {
    Volume skull = makeSkull(64);
    skull.setSpacing(glm::vec3(paperSpacingMm(64)));
    ThreadPool pool;
    Renderer skipping(skull, &pool);
    Renderer marching(skull, &pool, RenderOptions{.skipEmpty = false});
    for (const char* preset : {"paper", "top"}) {
        SCOPED_TRACE(preset);
        const Camera c = cameraPreset(preset, skull, {160, 160});
        HitCache cache;
        Dbi cached = skipping.render(c, &cache);
        for (int n : {6, 14, 24, 40}) {
            SCOPED_TRACE(n);
            const Box3i box = surfaceBox(skull, n);
            skull.fill(box, 0, Material::Air);
            skipping.volumeChanged(box);
            marching.volumeChanged(box);
            Dbi truth = marching.render(c);
            Dbi a = skipping.render(c);
            ASSERT_TRUE(a == truth) << compare(a, truth).describe();
            skipping.render(c, dirtyScreenRect(c, skull, box), cached, &cache);
            ASSERT_TRUE(cached == truth) << compare(cached, truth).describe();
        }
        skull = makeSkull(64);
        skull.setSpacing(glm::vec3(paperSpacingMm(64)));
        skipping.rebuild();
        marching.rebuild();
    }
}

// Hits refined and differentiated eight at a time (vector lanes) give the pixels of the scalar
// path bit for bit: every preset and random cameras (inside the volume too, so that hits near its
// faces take the scalar border path beside batched ones), an anisotropic volume, and a drilled
// skull seen through a hit cache.
TEST(Renderer, BatchedHitsChangeNoBit) {
    std::mt19937 rng(11);
    Volume aniso = makeSkull(48);
    aniso.setSpacing({0.9f, 1.3f, 1.7f});
    for (Volume v : {makeSkull(64), makeSphere(40), aniso}) {
        ThreadPool pool;
        Renderer batched(v, &pool);
        Renderer scalar(v, &pool, RenderOptions{.batchHits = false});
        for (const std::string& preset : cameraPresetNames()) {
            Camera c = cameraPreset(preset, v, {83, 67});
            Dbi a = batched.render(c), b = scalar.render(c);
            ASSERT_TRUE(a == b) << preset << ": " << compare(a, b).describe();
        }
        float r = 0.5f * glm::length(v.extentMm());
        RandomCameras cameras(0.2f, 3.0f, 5.0f, 90.0f);
        for (int i = 0; i < 16; ++i) {
            const Camera c = cameras(rng, r, 70, 50);
            Dbi a = batched.render(c), b = scalar.render(c);
            ASSERT_TRUE(a == b) << describe(c) << ": " << compare(a, b).describe();
        }
    }
    // Cached re-renders after drilling take the batched path from resumed hits.
    Volume skull = makeSkull(64);
    Renderer batched(skull);
    Renderer scalar(skull, nullptr, RenderOptions{.batchHits = false});
    const Camera c = cameraPreset("working", skull, {96, 96});
    HitCache cache;
    Dbi frame = batched.render(c, &cache);
    SurfaceSite site = defaultBurrSite(skull);
    Driller driller(ToolShape::burr(4.0f));
    ToolPose pose;
    pose.position = site.position - site.normal * 1.5f;
    Box3i changed = driller.drill(skull, pose, 1.0f, 0.05f).changed;
    ASSERT_FALSE(changed.empty());
    batched.volumeChanged(changed);
    scalar.volumeChanged(changed);
    batched.render(c, dirtyScreenRect(c, skull, changed), frame, &cache);
    Dbi b = scalar.render(c);
    EXPECT_TRUE(frame == b) << compare(frame, b).describe();
}

// The tile loop's AVX2 build (RenderOptions::avx2, taken where the CPU has AVX2) gives the
// baseline build's pixels bit for bit: presets and random cameras (hits on the volume's faces
// too) on three volumes, one anisotropic, and cached re-renders of a drilled skull.
TEST(Renderer, Avx2BuildChangesNoBit) {
    if (!__builtin_cpu_supports("avx2") || !__builtin_cpu_supports("bmi2"))
        GTEST_SKIP() << "this CPU has no AVX2: every render takes the baseline build";
    std::mt19937 rng(12);
    Volume aniso = makeSkull(48);
    aniso.setSpacing({0.9f, 1.3f, 1.7f});
    // Scattered bone voxels up to every face, in partial bricks: the eight-sample march's lanes
    // stop at the faces, at empty bricks and between bricks everywhere.
    auto scattered = [&](glm::ivec3 dims) {
        Volume v(dims, glm::vec3(1.0f));
        std::bernoulli_distribution bone(0.03);
        for (size_t i = 0; i < size_t(dims.x) * dims.y * dims.z; ++i)
            v.densityData()[i] = bone(rng) ? 255 : 0;
        return v;
    };
    for (Volume v :
         {makeSkull(64), makeSphere(40), aniso, scattered({37, 29, 23}), scattered({3, 9, 7})}) {
        ThreadPool pool;
        Renderer wide(v, &pool);
        Renderer baseline(v, &pool, RenderOptions{.avx2 = false});
        for (const std::string& preset : cameraPresetNames()) {
            if (preset == "working" && v.dims().x < 40)
                continue; // the scattered volumes have no burr-hole site
            Camera c = cameraPreset(preset, v, {83, 67});
            Dbi a = wide.render(c), b = baseline.render(c);
            ASSERT_TRUE(a == b) << preset << ": " << compare(a, b).describe();
        }
        float r = 0.5f * glm::length(v.extentMm());
        RandomCameras cameras(0.2f, 3.0f, 5.0f, 90.0f);
        for (int i = 0; i < 16; ++i) {
            const Camera c = cameras(rng, r, 70, 50);
            Dbi a = wide.render(c), b = baseline.render(c);
            ASSERT_TRUE(a == b) << describe(c) << ": " << compare(a, b).describe();
        }
    }
    Volume skull = makeSkull(64);
    Renderer wide(skull);
    Renderer baseline(skull, nullptr, RenderOptions{.avx2 = false});
    const Camera c = cameraPreset("working", skull, {96, 96});
    HitCache wideCache, baselineCache;
    Dbi a = wide.render(c, &wideCache), b = baseline.render(c, &baselineCache);
    ASSERT_TRUE(a == b) << compare(a, b).describe();
    SurfaceSite site = defaultBurrSite(skull);
    Driller driller(ToolShape::burr(4.0f));
    ToolPose pose;
    for (int i = 0; i < 6; ++i) {
        pose.position = site.position - site.normal * (0.5f * float(i));
        Box3i changed = driller.drill(skull, pose, 1.0f, 0.05f).changed;
        wide.volumeChanged(changed);
        baseline.volumeChanged(changed);
        const PixelRect rect = dirtyScreenRect(c, skull, changed);
        wide.render(c, rect, a, &wideCache);
        baseline.render(c, rect, b, &baselineCache);
        ASSERT_TRUE(a == b) << "stroke " << i << ": " << compare(a, b).describe();
    }
}

// Rays that skim a flat face march many samples through bricks that hold surface: the AVX2
// build's packets of eight rays stop at their step limit there and the lanes go on alone. Wide,
// baseline and unskipped renders agree bit for bit, and so do rectangles of odd widths (packets
// of fewer than eight rays) with the full frame.
TEST(Renderer, PacketsOfRaysSkimmingAFaceChangeNoBit) {
    Volume box = makeBox(64); // a solid cube over voxels [16, 48) on each axis
    ThreadPool pool;
    Renderer wide(box, &pool);
    Renderer baseline(box, &pool, RenderOptions{.avx2 = false});
    Renderer marching(box, &pool, RenderOptions{.skipEmpty = false});
    for (float above : {0.05f, 0.3f, 1.5f}) {
        const float top = box.voxelCenter({0, 0, 47}).z + 0.5f * box.spacing().z;
        Camera c;
        c.eye = {-70.0f, 3.0f, top + above};
        c.target = {40.0f, -2.0f, top - 0.4f * above};
        c.up = {0.0f, 0.0f, 1.0f};
        c.fovYDeg = 12.0f;
        c.nearMm = 5.0f;
        c.farMm = 400.0f;
        c.width = 61;
        c.height = 45;
        const Dbi a = wide.render(c);
        ASSERT_TRUE(a == baseline.render(c))
            << above << ": " << compare(a, baseline.render(c)).describe();
        ASSERT_TRUE(a == marching.render(c))
            << above << ": " << compare(a, marching.render(c)).describe();
        for (const PixelRect& r :
             {PixelRect(3, 5, 13, 9), PixelRect(0, 20, 61, 1), PixelRect(17, 0, 5, 45)}) {
            Dbi part(c.width, c.height);
            wide.render(c, r, part);
            for (int y = r.y; y < r.y + r.h; ++y)
                for (int x = r.x; x < r.x + r.w; ++x) {
                    ASSERT_EQ(std::memcmp(part.color(x, y), a.color(x, y), 4), 0) << x << "," << y;
                    ASSERT_EQ(part.depth()[part.index(x, y)], a.depth()[a.index(x, y)])
                        << x << "," << y;
                }
        }
    }
}
// Rays in a plane of the axes (a direction component exactly zero) take marchSpan's own slab
// code in the AVX2 build's eight-lane set-up: a camera on the x axis, level, one pixel row high,
// puts every ray of its row in the plane z = 0. Wide and baseline agree bit for bit, and the
// middle rays hit the sphere centred in that plane.
TEST(Renderer, RaysInAPlaneOfTheAxesChangeNoBit) {
    Volume sphere = makeSphere(40);
    ThreadPool pool;
    Renderer wide(sphere, &pool);
    Renderer baseline(sphere, &pool, RenderOptions{.avx2 = false});
    for (const glm::vec3 eye : {glm::vec3(-150.0f, 0.0f, 0.0f), glm::vec3(0.0f, 150.0f, 0.0f)}) {
        Camera c;
        c.eye = eye;
        c.target = {0.0f, 0.0f, 0.0f};
        c.up = {0.0f, 0.0f, 1.0f};
        c.fovYDeg = 0.5f; // a row 61 pixels wide spans ~30 degrees
        c.nearMm = 5.0f;
        c.farMm = 400.0f;
        c.width = 61;
        c.height = 1;
        const Dbi a = wide.render(c), b = baseline.render(c);
        ASSERT_TRUE(a == b) << describe(c) << ": " << compare(a, b).describe();
        int hits = 0;
        for (int x = 0; x < c.width; ++x)
            hits += a.depth()[a.index(x, 0)] < kBackgroundDepth;
        EXPECT_GT(hits, c.width / 4);
    }
}

// Random cameras around and inside the volume, near and far, narrow and wide: skipping (bricks,
// cell masks, cone blocks) never changes a bit.
TEST(Renderer, SkippingChangesNoBitFromAnyCamera) {
    std::mt19937 rng(3);
    for (Volume v : {makeSkull(64), makeSphere(40)}) {
        ThreadPool pool;
        Renderer skipping(v, &pool);
        Renderer marching(v, &pool, RenderOptions{.skipEmpty = false});
        float r = 0.5f * glm::length(v.extentMm());
        RandomCameras cameras(0.2f, 4.0f, 5.0f, 100.0f);
        for (int i = 0; i < 24; ++i) {
            const Camera c = cameras(rng, r, 90, 70);
            Dbi a = skipping.render(c), b = marching.render(c);
            ASSERT_TRUE(a == b) << describe(c) << ": " << compare(a, b).describe();
        }
    }
}

// The cone march goes on through clear trilinear cells near the surface: scattered single voxels
// just above and just below the iso-value (127, 128, 255), seen through narrow fields of view so
// that the cones are thin, render bit for bit as without skipping.
TEST(Renderer, ConeMarchThroughClearCellsChangesNoBit) {
    Volume v({48, 40, 44}, glm::vec3(0.7f, 0.8f, 0.75f));
    std::mt19937 rng(5);
    std::uniform_int_distribution<int> x(0, 47), y(0, 39), z(0, 43), pick(0, 3);
    const uint8_t values[4] = {127, 128, 129, 255};
    for (int i = 0; i < 400; ++i)
        v.set(x(rng), y(rng), z(rng), values[pick(rng)], Material::Cortical);
    for (int i = 10; i < 38; ++i) // a thin plate, one voxel thick
        for (int j = 8; j < 32; ++j)
            v.set(i, j, 22, 160, Material::Diploe);
    ThreadPool pool;
    Renderer skipping(v, &pool);
    Renderer marching(v, &pool, RenderOptions{.skipEmpty = false});
    float r = 0.5f * glm::length(v.extentMm());
    RandomCameras cameras(1.2f, 6.0f, 3.0f, 30.0f, 0.2f);
    int hits = 0;
    for (int i = 0; i < 16; ++i) {
        const Camera c = cameras(rng, r, 160, 120);
        Dbi a = skipping.render(c), b = marching.render(c);
        ASSERT_TRUE(a == b) << describe(c) << ": " << compare(a, b).describe();
        for (int py = 0; py < c.height; ++py)
            for (int px = 0; px < c.width; ++px)
                hits += a.depth(px, py) < kBackgroundDepth;
    }
    EXPECT_GT(hits, 1000);
}

TEST(Renderer, BrickGridStaysCorrectAfterErosion) {
    Volume skull = makeSkull(64);
    ThreadPool pool;
    Renderer renderer(skull, &pool);
    std::mt19937 rng(11);
    Camera c = cameraPreset("working", skull, {120, 100});
    for (int i = 0; i < 12; ++i) {
        Box3i changed = drillSomewhere(skull, renderer, c, rng);
        renderer.volumeChanged(changed);
        BrickGrid fresh(skull);
        ASSERT_EQ(renderer.bricks().maxData(), fresh.maxData());
        glm::ivec3 nb = fresh.dims();
        for (int z = 0; z < nb.z; ++z)
            for (int y = 0; y < nb.y; ++y)
                for (int x = 0; x < nb.x; ++x) {
                    // Distances may lag behind (lower bounds) but never claim too much.
                    ASSERT_LE(renderer.bricks().distance({x, y, z}), fresh.distance({x, y, z}));
                    ASSERT_EQ(renderer.bricks().occupied({x, y, z}), fresh.occupied({x, y, z}));
                    ASSERT_EQ(renderer.bricks().cellMask({x, y, z}), fresh.cellMask({x, y, z}));
                }
        Dbi updated = renderer.render(c);
        Renderer rebuilt(skull, &pool);
        Renderer marching(skull, &pool, RenderOptions{.skipEmpty = false});
        ASSERT_EQ(updated, rebuilt.render(c));
        ASSERT_EQ(updated, marching.render(c));
    }
    // Drilling only empties bricks: no full distance pass after the first build.
    EXPECT_EQ(renderer.bricks().fullDistancePasses(), 1);
}

TEST(Renderer, BrickGridRecomputesDistancesWhenBoneAppears) {
    Volume v({40, 40, 40}, glm::vec3(1.0f));
    BrickGrid grid(v);
    EXPECT_FALSE(grid.occupied({5, 5, 5}));
    v.set(21, 21, 21, 255, Material::Cortical);
    grid.update(v, Box3i::fromMinMax({21, 21, 21}, {22, 22, 22}));
    BrickGrid fresh(v);
    EXPECT_EQ(grid.maxData(), fresh.maxData());
    for (int i = 0; i < 10; ++i)
        EXPECT_EQ(grid.distance({i, 5, 5}), fresh.distance({i, 5, 5}));
    EXPECT_TRUE(grid.occupied({5, 5, 5}));
}

// The update study's cut (surfaceBox), cut to air.
Box3i cutSurfaceBox(Volume& v, int n, int shiftX = 0) {
    const Box3i box = surfaceBox(v, n, shiftX);
    v.fill(box, 0, Material::Air);
    return box;
}

// After erosion the distances around the emptied bricks are recomputed: one cut into a freshly
// built grid leaves it equal to a grid built from scratch, distances included (so rays through
// the hole leap as far as they can), and never a full distance pass.
TEST(Renderer, BrickGridDistancesAroundACutAreExact) {
    for (int n : {6, 24, 40}) {
        SCOPED_TRACE(n);
        Volume v = makeSkull(64);
        BrickGrid grid(v);
        BrickGrid before = grid;
        Box3i box = cutSurfaceBox(v, n);
        EXPECT_FALSE(grid.update(v, box)) << "a cut is erosion";
        BrickGrid fresh(v);
        ASSERT_EQ(grid.maxData(), fresh.maxData());
        glm::ivec3 nb = fresh.dims();
        int grown = 0;
        for (int z = 0; z < nb.z; ++z)
            for (int y = 0; y < nb.y; ++y)
                for (int x = 0; x < nb.x; ++x) {
                    ASSERT_EQ(grid.distance({x, y, z}), fresh.distance({x, y, z}))
                        << x << "," << y << "," << z;
                    ASSERT_EQ(grid.cellMask({x, y, z}), fresh.cellMask({x, y, z}));
                    grown += fresh.distance({x, y, z}) > before.distance({x, y, z}) + 1;
                }
        if (n >= 24) {
            EXPECT_GT(grown, 0) << "the hole's distances should have grown beyond 1";
        }
        EXPECT_EQ(grid.fullDistancePasses(), 1);
    }
}

// Cuts one after another (nested and side by side): distances never claim too much.
TEST(Renderer, BrickGridDistancesStayLowerBoundsOverManyCuts) {
    Volume v = makeSkull(64);
    BrickGrid grid(v);
    for (auto [n, shift] : {std::pair{8, 0}, {20, 0}, {12, 14}, {30, -6}, {4, 20}}) {
        Box3i box = cutSurfaceBox(v, n, shift);
        EXPECT_FALSE(grid.update(v, box));
        BrickGrid fresh(v);
        ASSERT_EQ(grid.maxData(), fresh.maxData());
        glm::ivec3 nb = fresh.dims();
        for (int z = 0; z < nb.z; ++z)
            for (int y = 0; y < nb.y; ++y)
                for (int x = 0; x < nb.x; ++x) {
                    ASSERT_LE(grid.distance({x, y, z}), fresh.distance({x, y, z}));
                    ASSERT_EQ(grid.occupied({x, y, z}), fresh.occupied({x, y, z}));
                }
    }
    EXPECT_EQ(grid.fullDistancePasses(), 1);
}

// Runs of empty bricks against their definition (count the empty bricks from b on, along each
// axis and direction) after build, after every cut (update recomputes the lines through the
// bricks that emptied) and after bone appears (a full rebuild).
TEST(Renderer, BrickGridRunsAreRunsOfEmptyBricks) {
    Volume v = makeSkull(64);
    BrickGrid grid(v);
    auto expectRuns = [](const BrickGrid& g) {
        const glm::ivec3 nb = g.dims();
        for (int z = 0; z < nb.z; ++z)
            for (int y = 0; y < nb.y; ++y)
                for (int x = 0; x < nb.x; ++x)
                    for (int a = 0; a < 3; ++a)
                        for (int dir : {-1, 1}) {
                            int run = 0;
                            for (glm::ivec3 b(x, y, z); b[a] >= 0 && b[a] < nb[a]; b[a] += dir) {
                                if (g.maxDensity(b) >= kSurfaceDensity)
                                    break;
                                ++run;
                            }
                            ASSERT_EQ(int(g.run({x, y, z}, a, dir > 0)), std::min(run, 255))
                                << x << "," << y << "," << z << " axis " << a << " dir " << dir;
                        }
    };
    expectRuns(grid);
    for (auto [n, shift] : {std::pair{8, 0}, {20, 0}, {12, 14}, {30, -6}}) {
        Box3i box = cutSurfaceBox(v, n, shift);
        EXPECT_FALSE(grid.update(v, box));
        expectRuns(grid);
    }
    const Box3i filled = Box3i::fromMinMax({20, 20, 20}, {30, 28, 26});
    v.fill(filled, 255, Material::Cortical);
    EXPECT_TRUE(grid.update(v, filled)) << "bone appeared";
    expectRuns(grid);
}

// The chamfer passes against the definition: the Chebyshev distance, in bricks, to the nearest
// brick that may hold surface, on random sparse bone; and after emptying a block of it, update()
// against the same definition (lower bound everywhere, exact in and around the emptied block).
TEST(Renderer, BrickGridDistancesAreChebyshevDistances) {
    Volume v({44, 40, 36}, glm::vec3(1.0f));
    std::mt19937 rng(5);
    std::uniform_int_distribution<int> x(0, 43), y(0, 39), z(0, 35);
    for (int i = 0; i < 12; ++i)
        v.set(x(rng), y(rng), z(rng), 200, Material::Cortical);
    for (int zz = 20; zz < 30; ++zz) // a slab, emptied below
        for (int yy = 4; yy < 36; ++yy)
            for (int xx = 6; xx < 40; ++xx)
                v.set(xx, yy, zz, 255, Material::Cortical);
    auto expectChebyshev = [](const BrickGrid& g, bool exact) {
        glm::ivec3 nb = g.dims();
        std::vector<glm::ivec3> occupied;
        for (int bz = 0; bz < nb.z; ++bz)
            for (int by = 0; by < nb.y; ++by)
                for (int bx = 0; bx < nb.x; ++bx)
                    if (g.maxDensity({bx, by, bz}) >= kSurfaceDensity)
                        occupied.push_back({bx, by, bz});
        for (int bz = 0; bz < nb.z; ++bz)
            for (int by = 0; by < nb.y; ++by)
                for (int bx = 0; bx < nb.x; ++bx) {
                    int best = BrickGrid::kMaxDistance;
                    for (glm::ivec3 o : occupied) {
                        glm::ivec3 d = glm::abs(o - glm::ivec3(bx, by, bz));
                        best = std::min(best, std::max({d.x, d.y, d.z}));
                    }
                    if (exact) {
                        ASSERT_EQ(g.distance({bx, by, bz}), best) << bx << "," << by << "," << bz;
                    } else {
                        ASSERT_LE(g.distance({bx, by, bz}), best) << bx << "," << by << "," << bz;
                    }
                }
    };
    BrickGrid grid(v);
    expectChebyshev(grid, true);
    Box3i hole = Box3i::fromMinMax({14, 10, 20}, {34, 30, 30});
    for (int zz = hole.lo.z; zz < hole.hi.z; ++zz)
        for (int yy = hole.lo.y; yy < hole.hi.y; ++yy)
            for (int xx = hole.lo.x; xx < hole.hi.x; ++xx)
                v.set(xx, yy, zz, 0, Material::Air);
    EXPECT_FALSE(grid.update(v, hole));
    expectChebyshev(grid, true); // one cut into an exact grid: exact again
    EXPECT_EQ(grid.fullDistancePasses(), 1);
}

TEST(Renderer, MaterialsGetTheirColours) {
    // Cortical bone on the left half, exposed dura on the right, seen from above.
    Volume v({32, 32, 32}, glm::vec3(1.0f));
    for (int z = 0; z < 12; ++z)
        for (int y = 4; y < 28; ++y)
            for (int x = 4; x < 28; ++x)
                v.set(x, y, z, x < 16 ? 240 : 180, x < 16 ? Material::Cortical : Material::Dura);
    Renderer renderer(v);
    Camera c = cameraPreset("top", v, {100, 100});
    Dbi d = renderer.render(c);
    glm::dmat4 vp = viewProjection(c);
    auto pixelOf = [&](glm::dvec3 p) {
        WindowPoint w = projectToWindow(vp, c, p);
        return glm::ivec2(int(w.window.x), int(w.window.y));
    };
    glm::ivec2 bone = pixelOf({-6, 0, -4}), dura = pixelOf({6, 0, -4});
    const uint8_t* cb = d.color(bone.x, bone.y);
    const uint8_t* cd = d.color(dura.x, dura.y);
    EXPECT_GT(cb[0], 150);
    EXPECT_GT(cb[2], 120);         // ivory: blue not far below red
    EXPECT_GT(cd[0], 1.6 * cd[1]); // pinkish red
    EXPECT_EQ(cb[3], 255);
    EXPECT_EQ(cd[3], 255);
}

TEST(Renderer, CastRayAgreesWithTheImage) {
    Volume sphere = makeSphere(48);
    Renderer renderer(sphere);
    Camera c = cameraPreset("front", sphere, {64, 48});
    Dbi d = renderer.render(c);
    for (int y = 0; y < c.height; y += 3)
        for (int x = 0; x < c.width; x += 3) {
            RayHit h = renderer.castRay(c, x, y);
            EXPECT_EQ(h.hit, d.depth(x, y) < 1.0f);
            EXPECT_EQ(h.depth, d.depth(x, y));
            if (h.hit) { // the hit point is on the sphere, the normal points outwards
                EXPECT_GT(glm::dot(glm::normalize(glm::vec3(h.position)), h.normal), 0.99f);
            }
        }
}

// On a density ramp (a different slope per axis, anisotropic spacing) central differences are the
// slopes exactly and every lerp of equal values returns them, so wherever the shading stencil lies
// inside the volume the normal is exactly -gradient / |gradient|: each component comes from its
// own axis and its own spacing. Near the faces (air outside) the border path takes over; there
// the bone's surface turns along the volume's faces, and normals stay unit vectors.
TEST(Renderer, NormalsOnADensityRampAreTheRampsGradient) {
    const glm::ivec3 n(40, 36, 32);
    const glm::vec3 spacing(1.0f, 1.5f, 2.0f);
    Volume ramp(n, spacing);
    const glm::ivec3 slope(1, 2, 3); // density per voxel along x, y, z
    for (int z = 0; z < n.z; ++z)
        for (int y = 0; y < n.y; ++y)
            for (int x = 0; x < n.x; ++x) {
                int d = 128 + slope.x * (x - n.x / 2) + slope.y * (y - n.y / 2) +
                        slope.z * (z - n.z / 2);
                ASSERT_TRUE(d >= 0 && d <= 255);
                ramp.set(x, y, z, uint8_t(d), d >= 128 ? Material::Cortical : Material::Air);
            }
    Renderer renderer(ramp);
    const glm::vec3 grad = glm::vec3(slope) / spacing; // density per mm
    const float len = std::sqrt(grad.x * grad.x + grad.y * grad.y + grad.z * grad.z);
    const glm::vec3 expected = -grad / len;
    // Looking at the iso-plane from the air side, a little off its normal.
    Camera c = cameraLookingAt(glm::vec3(0.0f), glm::normalize(expected + glm::vec3(0.1f, 0, 0)),
                               150.0f, 40.0f, {60, 50}, ramp);
    int interior = 0, border = 0;
    for (int y = 0; y < c.height; ++y)
        for (int x = 0; x < c.width; ++x) {
            RayHit h = renderer.castRay(c, x, y);
            if (!h.hit)
                continue;
            glm::vec3 v = ramp.toVoxel(glm::vec3(h.position));
            bool inside = v.x >= 3 && v.y >= 3 && v.z >= 3 && v.x <= n.x - 4 && v.y <= n.y - 4 &&
                          v.z <= n.z - 4;
            if (inside) {
                ++interior;
                EXPECT_EQ(h.normal, expected) << "pixel " << x << ", " << y;
            } else {
                ++border;
                EXPECT_NEAR(glm::length(h.normal), 1.0f, 1e-5f) << "pixel " << x << ", " << y;
            }
        }
    EXPECT_GT(interior, 300);
    EXPECT_GT(border, 20);
}

// A client draws a triangle half in front of and half behind the bone surface and depth-tests it
// against the DBI (GL_LESS). Rasterised here on the CPU with the same matrices: window z is
// interpolated linearly in screen space, as GL does.
TEST(Renderer, ClientGeometryCompositesWithTheDbiPixelForPixel) {
    const int n = 64;
    Volume box = makeBox(n); // faces at +-16 mm; iso-surface 128/255 of a voxel beyond the centre
    const double face = 15.5 + 128.0 / 255.0;
    Renderer renderer(box);
    Camera c = cameraPreset("front", box, {300, 300}); // from +y
    Dbi dbi = renderer.render(c);
    glm::dmat4 vp = viewProjection(c);

    // The triangle's plane y = 16 - 2x/3 crosses the front face along x = 0.
    const glm::dvec3 tri[3] = {{-12, 24, -10}, {12, 8, -10}, {0, 16, 12}};
    glm::dvec3 w[3];
    for (int i = 0; i < 3; ++i)
        w[i] = projectToWindow(vp, c, tri[i]).window;
    auto edge = [](glm::dvec2 a, glm::dvec2 b, glm::dvec2 p) {
        return (b.x - a.x) * (p.y - a.y) - (b.y - a.y) * (p.x - a.x);
    };
    double area = edge(w[0], w[1], w[2]);
    glm::dvec3 normal = glm::normalize(glm::cross(tri[1] - tri[0], tri[2] - tri[0]));

    int visible = 0, hidden = 0, mismatches = 0;
    for (int y = 0; y < c.height; ++y)
        for (int x = 0; x < c.width; ++x) {
            glm::dvec2 p(x + 0.5, y + 0.5);
            double b0 = edge(w[1], w[2], p) / area, b1 = edge(w[2], w[0], p) / area,
                   b2 = edge(w[0], w[1], p) / area;
            if (b0 < 0 || b1 < 0 || b2 < 0)
                continue;
            float fragDepth = float(b0 * w[0].z + b1 * w[1].z + b2 * w[2].z);
            bool shown = fragDepth < dbi.depth(x, y);
            // Analytic: the triangle's point under this pixel is in front of the face when y >
            // face.
            TestRay r = pixelRay(c, p.x, p.y);
            double t = glm::dot(tri[0] - r.origin, normal) / glm::dot(r.dir, normal);
            glm::dvec3 q = r.origin + t * r.dir;
            if (std::abs(q.y - face) < 0.01) // a hundredth of a voxel: too close to call
                continue;
            bool expected = q.y > face;
            mismatches += shown != expected;
            (expected ? visible : hidden)++;
        }
    EXPECT_EQ(mismatches, 0);
    EXPECT_GT(visible, 500);
    EXPECT_GT(hidden, 500);
}

// [SECTION] Hit cache: dirty re-renders that resume at the last first hit

// The server's path: one cache per view filled by a full render; after each erosion only BB_screen
// is re-rendered through the cache. The frame must equal an uncached full render bit for bit, and
// so must a full render through the cache after all the strokes (pixels outside the rectangles
// then resume at indices computed many strokes earlier).
TEST(HitCache, CachedDirtyRendersAreBitForBitUncachedFullRenders) {
    Volume skull = makeSkull(64);
    ThreadPool pool;
    Renderer renderer(skull, &pool);
    std::vector<CachedView> views = cachedViews(renderer, skull);
    for (const CachedView& v : views) {
        EXPECT_TRUE(v.cache.validFor(renderer, v.camera));
        EXPECT_EQ(v.frame, renderer.render(v.camera)) << describe(v.camera);
    }
    std::mt19937 rng(21);
    int64_t resumedBefore = 0;
    for (int stroke = 0; stroke < 16; ++stroke) {
        CachedView& drilled = views[size_t(stroke) % views.size()];
        Box3i changed = drillSomewhere(skull, renderer, drilled.camera, rng);
        renderer.volumeChanged(changed);
        for (CachedView& v : views) {
            SCOPED_TRACE(describe(v.camera));
            ASSERT_TRUE(v.cache.validFor(renderer, v.camera)) << "erosion keeps caches valid";
            PixelRect rect = dirtyScreenRect(v.camera, skull, changed);
            renderer.render(v.camera, rect, v.frame, &v.cache);
            Dbi expected = renderer.render(v.camera);
            ASSERT_TRUE(v.frame == expected)
                << "stroke " << stroke << ": " << compare(v.frame, expected).describe();
        }
    }
    for (CachedView& v : views) {
        resumedBefore += v.cache.resumed();
        ASSERT_EQ(renderer.render(v.camera, &v.cache), renderer.render(v.camera));
    }
    EXPECT_GT(resumedBefore, 1000) << "the dirty renders should have resumed from the cache";
}

// The server's re-render of a drilled view: renderChanged keeps the pixels whose cached hit lies
// clear of the change, on the AVX2 and the baseline build and with a step of 2 voxels (whose
// margin the stencil's half voxel of slack does not cover), and the frame is still an uncached
// full render bit for bit, stroke after stroke, from cameras looking at the drilling from every
// side (a hit behind the change, beside it and in front of it).
TEST(HitCache, ReRendersOfAChangeKeepPixelsClearOfItAndStayBitForBit) {
    for (const RenderOptions& options :
         {RenderOptions{}, RenderOptions{.avx2 = false}, RenderOptions{.stepVoxels = 2.0f}}) {
        SCOPED_TRACE(::testing::Message()
                     << "AVX2 " << options.avx2 << ", step " << options.stepVoxels);
        Volume skull = makeSkull(64);
        ThreadPool pool;
        Renderer renderer(skull, &pool, options);
        std::vector<CachedView> views = cachedViews(renderer, skull);
        std::mt19937 rng(34);
        int64_t area = 0;
        for (int stroke = 0; stroke < 16; ++stroke) {
            Box3i changed = drillSomewhere(skull, renderer, views[size_t(stroke) % 4].camera, rng);
            renderer.volumeChanged(changed);
            for (CachedView& v : views) {
                SCOPED_TRACE(describe(v.camera));
                PixelRect rect = dirtyScreenRect(v.camera, skull, changed);
                area += rect.area();
                renderer.renderChanged(v.camera, rect, v.frame, v.cache, changed);
                Dbi expected = renderer.render(v.camera);
                ASSERT_TRUE(v.frame == expected)
                    << "stroke " << stroke << ": " << compare(v.frame, expected).describe();
            }
        }
        int64_t kept = 0, resumed = 0;
        for (const CachedView& v : views)
            kept += v.cache.kept(), resumed += v.cache.resumed();
        EXPECT_GT(kept, area / 10) << "of " << area << " pixels re-rendered";
        EXPECT_LE(kept + resumed, area) << "a kept pixel is not rendered, so not resumed";
        EXPECT_LT(kept, area) << "pixels at the change must be rendered";
    }
}

// What renderChanged keeps is the frame's: told of a box that misses the change, it leaves the
// drilled pixels as they were (so the box, not a re-render, decides), and told of none of it
// with an unknown cache it renders them all.
TEST(HitCache, ReRendersTrustTheBoxTheyAreGiven) {
    Volume skull = makeSkull(64);
    ThreadPool pool;
    Renderer renderer(skull, &pool);
    Camera camera = cameraPreset("working", skull, {140, 110});
    HitCache cache;
    Dbi frame = renderer.render(camera, &cache);
    const Dbi before = frame;
    std::mt19937 rng(5);
    Box3i changed = drillSomewhere(skull, renderer, camera, rng);
    renderer.volumeChanged(changed);
    const PixelRect rect = dirtyScreenRect(camera, skull, changed);
    const Dbi expected = renderer.render(camera);
    ASSERT_GT(compare(before, expected).differingPixels, 20u) << "the drilling should show";
    // A box far from the drilling: every pixel of the rectangle hits clear of it.
    const glm::ivec3 corner(0, 0, 0);
    renderer.renderChanged(camera, rect, frame, cache, Box3i::fromMinMax(corner, corner + 1));
    EXPECT_TRUE(frame == before) << compare(frame, before).describe();
    EXPECT_EQ(cache.kept(), rect.area());
    // A fresh cache knows no hit, so nothing is kept.
    HitCache fresh;
    Dbi stale = before;
    renderer.renderChanged(camera, stale.bounds(), stale, fresh,
                           Box3i::fromMinMax(corner, corner + 1));
    EXPECT_TRUE(stale == expected) << compare(stale, expected).describe();
    EXPECT_EQ(fresh.kept(), 0);
}

// The update study's case at test size: the paper's view, surface boxes cut out one after
// another, each BB_screen re-rendered through the view's cache: bit for bit an uncached full render
// and a render without skipping.
TEST(HitCache, CutHolesRenderBitForBitThroughTheCache) {
    Volume skull = makeSkull(64);
    skull.setSpacing(glm::vec3(paperSpacingMm(64)));
    ThreadPool pool;
    Renderer renderer(skull, &pool);
    Camera camera = cameraPreset("paper", skull, {160, 160});
    HitCache cache;
    Dbi frame = renderer.render(camera, &cache);
    for (auto [n, shift] : {std::pair{5, 0}, {20, 0}, {12, 16}, {36, 0}}) {
        SCOPED_TRACE(n);
        Box3i box = cutSurfaceBox(skull, n, shift);
        renderer.volumeChanged(box);
        ASSERT_TRUE(cache.validFor(renderer, camera));
        PixelRect rect = dirtyScreenRect(camera, skull, box);
        renderer.render(camera, rect, frame, &cache);
        Dbi expected = Renderer(skull, &pool).render(camera);
        ASSERT_TRUE(frame == expected) << compare(frame, expected).describe();
        Renderer marching(skull, &pool, RenderOptions{.skipEmpty = false});
        ASSERT_TRUE(frame == marching.render(camera));
    }
}

// Erosion at the iso-value's edge: voxels of 126..130 lowered by 1 or 2 at a time, so samples
// cross 128 by the smallest steps there are. A sample that rose by an ulp where its corners went
// down (a + t (b - a) can) would make the cached render disagree. (renderChanged's box here spans
// most of the volume.)
TEST(HitCache, ErosionByTheSmallestStepsStaysBitForBit) {
    Volume v({40, 36, 32}, glm::vec3(0.8f));
    std::mt19937 rng(8);
    std::uniform_int_distribution<int> level(126, 130);
    for (int z = 8; z < 24; ++z)
        for (int y = 0; y < 36; ++y)
            for (int x = 0; x < 40; ++x)
                v.set(x, y, z, uint8_t(level(rng)), Material::Cortical);
    ThreadPool pool(2);
    Renderer renderer(v, &pool);
    std::vector<Camera> cameras;
    for (const char* preset : {"top", "front", "left"})
        cameras.push_back(cameraPreset(preset, v, {96, 80}));
    // Each view twice: re-rendered with render() and with renderChanged().
    std::vector<HitCache> caches(cameras.size()), changedCaches(cameras.size());
    std::vector<Dbi> frames, changedFrames;
    for (size_t i = 0; i < cameras.size(); ++i) {
        frames.push_back(renderer.render(cameras[i], &caches[i]));
        changedFrames.push_back(renderer.render(cameras[i], &changedCaches[i]));
    }
    std::uniform_int_distribution<int> x(0, 39), y(0, 35), z(8, 23), by(1, 2);
    int changedPixels = 0;
    for (int round = 0; round < 12; ++round) {
        Box3i changed;
        for (int i = 0; i < 300; ++i) {
            glm::ivec3 p(x(rng), y(rng), z(rng));
            uint8_t d = v.density(p.x, p.y, p.z);
            v.set(p.x, p.y, p.z, uint8_t(std::max(0, d - by(rng))), Material::Cortical);
            changed.merge(Box3i::fromMinMax(p, p + 1));
        }
        renderer.volumeChanged(changed);
        for (size_t i = 0; i < cameras.size(); ++i) {
            Dbi old = frames[i];
            PixelRect rect = dirtyScreenRect(cameras[i], v, changed);
            renderer.render(cameras[i], rect, frames[i], &caches[i]);
            renderer.renderChanged(cameras[i], rect, changedFrames[i], changedCaches[i], changed);
            Dbi expected = renderer.render(cameras[i]);
            ASSERT_TRUE(frames[i] == expected)
                << "round " << round << ": " << compare(frames[i], expected).describe();
            ASSERT_TRUE(changedFrames[i] == expected)
                << "round " << round << ": " << compare(changedFrames[i], expected).describe();
            changedPixels += int(compare(old, expected).differingPixels);
        }
    }
    EXPECT_GT(changedPixels, 1000) << "the erosion should have moved the surface";
}

// Anything that may raise a density invalidates every cache: rebuild(), and a brick that gains
// surface through volumeChanged. A stale cache would hide the new bone (its rays would resume
// behind it).
TEST(HitCache, RaisedDensityInvalidatesTheCache) {
    Volume skull = makeSkull(64);
    Renderer renderer(skull);
    Camera c = cameraPreset("working", skull, {100, 90});
    HitCache cache;
    Dbi frame = renderer.render(c, &cache);
    // A plate of bone in front of the surface, between the eye and the skull.
    glm::vec3 toEye = glm::normalize(c.eye - c.target);
    glm::ivec3 centre = glm::ivec3(skull.toVoxel(c.target + toEye * 60.0f));
    // Clipped to the volume: the box reaches past its faces (writing there corrupted the heap).
    Box3i plate = Box3i::fromMinMax(centre - 6, centre + 6).intersect(skull.bounds());
    ASSERT_FALSE(plate.empty());
    for (int z = plate.lo.z; z < plate.hi.z; ++z)
        for (int y = plate.lo.y; y < plate.hi.y; ++y)
            for (int x = plate.lo.x; x < plate.hi.x; ++x)
                skull.set(x, y, z, 255, Material::Cortical);
    const uint64_t generation = renderer.generation();
    renderer.rebuild();
    EXPECT_NE(renderer.generation(), generation);
    EXPECT_FALSE(cache.validFor(renderer, c));
    PixelRect all = frame.bounds();
    renderer.render(c, all, frame, &cache);
    Dbi expected = renderer.render(c);
    ASSERT_TRUE(frame == expected) << compare(frame, expected).describe();
    EXPECT_TRUE(cache.validFor(renderer, c));
    EXPECT_EQ(cache.resumed(), 0) << "a restarted cache knows nothing";

    // The same through volumeChanged: a brick that gains surface (a corner of the field, air in
    // the skull) bumps the generation.
    Box3i more = Box3i::fromMinMax({1, 1, 1}, {5, 5, 5});
    ASSERT_FALSE(renderer.bricks().occupied({0, 0, 0}));
    for (int z = more.lo.z; z < more.hi.z; ++z)
        for (int y = more.lo.y; y < more.hi.y; ++y)
            for (int x = more.lo.x; x < more.hi.x; ++x)
                skull.set(x, y, z, 255, Material::Cortical);
    renderer.volumeChanged(more);
    EXPECT_FALSE(cache.validFor(renderer, c));
    renderer.render(c, all, frame, &cache);
    expected = renderer.render(c);
    ASSERT_TRUE(frame == expected) << compare(frame, expected).describe();
}

// A cache kept across a rise in density the renderer cannot see (bone put back in a narrow cut,
// every brick still occupied, volumeChanged instead of rebuild) breaks the cache's contract: its
// pixels may be wrong, but the render must not crash or leave depths outside [0, 1]. Unguarded,
// the refinement's secant extrapolated out of the volume (a segfault in a volume client).
TEST(HitCache, ACacheKeptAcrossARiseStillRendersSafely) {
    Volume sphere = makeSphere(48);
    ThreadPool pool(2);
    Renderer renderer(sphere, &pool);
    const Camera c = cameraPreset("top", sphere, {128, 128});
    HitCache cache;
    Dbi frame = renderer.render(c, &cache);
    const Volume original = sphere;
    const Box3i box{{22, 22, 36}, {26, 26, 46}};
    for (int round = 0; round < 3; ++round) {
        sphere.fill(box, 0, Material::Air);
        renderer.volumeChanged(box);
        renderer.render(c, frame.bounds(), frame, &cache);
        for (int z = box.lo.z; z < box.hi.z; ++z)
            for (int y = box.lo.y; y < box.hi.y; ++y)
                for (int x = box.lo.x; x < box.hi.x; ++x)
                    sphere.set(x, y, z, original.density(x, y, z), original.material(x, y, z));
        renderer.volumeChanged(box); // against the contract: rebuild() is due
        renderer.render(c, frame.bounds(), frame, &cache);
        for (int i = 0; i < frame.width() * frame.height(); ++i)
            ASSERT_TRUE(frame.depth()[i] >= 0.0f && frame.depth()[i] <= 1.0f) << i;
    }
}

// A cache is bound to its camera (and window size): handed another view it restarts instead of
// resuming rays at indices of other rays.
TEST(HitCache, ACacheForAnotherCameraIsNeverUsed) {
    Volume skull = makeSkull(48);
    Renderer renderer(skull);
    Camera a = cameraPreset("top", skull, {80, 60});
    Camera b = cameraPreset("front", skull, {80, 60});
    Camera wide = a;
    wide.width = 96;
    HitCache cache;
    renderer.render(a, &cache);
    EXPECT_TRUE(cache.validFor(renderer, a));
    EXPECT_FALSE(cache.validFor(renderer, b));
    EXPECT_FALSE(cache.validFor(renderer, wide));
    EXPECT_EQ(renderer.render(b, &cache), renderer.render(b));
    EXPECT_TRUE(cache.validFor(renderer, b));
    EXPECT_FALSE(cache.validFor(renderer, a));
    EXPECT_EQ(renderer.render(wide, &cache), renderer.render(wide));
    // Another renderer of the same volume has its own generation.
    Renderer other(skull);
    EXPECT_FALSE(cache.validFor(other, wide));
    cache.clear();
    EXPECT_FALSE(cache.validFor(renderer, wide));
}

// Restarted for another view of the same size, a cache forgets the old view's rows as rectangles
// reach them: rows not yet rendered resume nowhere, and a frame rendered a rectangle at a time,
// in any order, is the fresh render's.
TEST(HitCache, ARestartedCacheRendersRectanglesAsAfresh) {
    Volume skull = makeSkull(48);
    Renderer renderer(skull);
    const Camera a = cameraPreset("top", skull, {80, 60});
    const Camera b = cameraPreset("front", skull, {80, 60});
    HitCache cache;
    renderer.render(a, &cache);
    int known = 0;
    for (int y = 0; y < 60; ++y)
        for (int x = 0; x < 80; ++x)
            known += cache.resumeIndex(x, y) != 0;
    ASSERT_GT(known, 0) << "the first view leaves indices behind";
    Dbi frame(80, 60);
    renderer.render(b, {30, 20, 20, 10}, frame, &cache);
    for (int y : {0, 19, 30, 59})
        for (int x = 0; x < 80; ++x)
            ASSERT_EQ(cache.resumeIndex(x, y), 0) << x << "," << y;
    for (const PixelRect& r : {PixelRect{0, 20, 30, 10}, PixelRect{50, 0, 30, 60},
                               PixelRect{0, 30, 50, 30}, PixelRect{0, 0, 50, 20}})
        renderer.render(b, r, frame, &cache);
    EXPECT_EQ(frame, renderer.render(b));
    // Eroded, the cached re-render still matches an uncached one.
    std::mt19937 rng(7);
    renderer.volumeChanged(drillSomewhere(skull, renderer, b, rng));
    renderer.render(b, {0, 0, 80, 60}, frame, &cache);
    EXPECT_EQ(frame, renderer.render(b));
    // A larger view: its arrays are new and unset, and rows are zeroed as rectangles reach them.
    const Camera c = cameraPreset("left", skull, {120, 90});
    Dbi larger = Dbi::unfilled(120, 90);
    for (const PixelRect& r :
         {PixelRect{0, 45, 120, 45}, PixelRect{60, 0, 60, 45}, PixelRect{0, 0, 60, 45}})
        renderer.render(c, r, larger, &cache);
    EXPECT_EQ(larger, renderer.render(c));
    renderer.render(c, larger.bounds(), larger, &cache);
    EXPECT_EQ(larger, renderer.render(c)) << "the cache's own resume indices";
}

} // namespace
// Sample indices are int: sample k of a ray is at k * dt from the eye, dt half the smallest
// spacing. With 0.001 mm voxels (the smallest a volume may have) and the eye 1e6 mm out on every
// axis (trephine render --eye allows it) the volume's samples have indices around 3.5e9, past
// INT_MAX: converting them was undefined behaviour (x86 gave INT_MIN and every ray missed). The
// renderer widens the step instead (to 1.6e-3 mm here), so the same plate seen from 1e6 mm away
// shows as it does from an equivalent view ten times nearer (indices 3.5e8, step unchanged),
// whose field of view is ten times wider. Far out, float positions are coarse (the eye is 1e9
// voxels away: ulp 64 voxels along z), so depths agree to 0.5 mm, and the silhouette may differ by
// a pixel.
TEST(Renderer, AFarEyeAndTheSmallestSpacingKeepSampleIndicesInIntAndThePicture) {
    // A plate 48 x 48 mm and 0.9 mm thick: 1 mm voxels across, 0.001 mm through.
    const glm::ivec3 dims{64, 64, 1024};
    Volume volume(dims, glm::vec3(1.0f, 1.0f, 0.001f));
    for (int z = 64; z < 960; ++z)
        for (int y = 8; y < 56; ++y)
            for (int x = 8; x < 56; ++x) {
                const size_t i = volume.index(x, y, z);
                volume.densityData()[i] = 255;
                volume.materialData()[i] = uint8_t(Material::Cortical);
            }
    Renderer renderer(volume);
    auto view = [&](float distanceScale) {
        Camera c;
        c.eye = glm::vec3(1.0f, 1.0f, 1.0f) * distanceScale;
        c.target = glm::vec3(0.0f);
        c.up = glm::vec3(0.0f, 0.0f, 1.0f);
        // 80 mm across at the plate, whatever the distance.
        const double distance = double(glm::length(c.eye));
        c.fovYDeg = float(glm::degrees(2.0 * std::atan(40.0 / distance)));
        c.width = c.height = 32;
        fitNearFar(c, glm::vec3(0.0f), 45.0f);
        return c;
    };
    const Camera farView = view(1.0e6f), nearView = view(1.0e5f);
    ASSERT_GT(double(glm::length(farView.eye)) / (0.5 * 0.001), double(INT32_MAX));
    const Dbi far = renderer.render(farView), near = renderer.render(nearView);
    int hits = 0, differ = 0;
    double worstMm = 0.0;
    for (int y = 0; y < 32; ++y)
        for (int x = 0; x < 32; ++x) {
            const bool farHit = !isBackground(far, x, y), nearHit = !isBackground(near, x, y);
            if (farHit != nearHit) {
                ++differ;
                continue;
            }
            if (!farHit)
                continue;
            ++hits;
            // Depth behind the target, in eye-space millimetres.
            const double a =
                -eyeZFromWindowDepth(farView, far.depth(x, y)) - double(glm::length(farView.eye));
            const double b = -eyeZFromWindowDepth(nearView, near.depth(x, y)) -
                             double(glm::length(nearView.eye));
            worstMm = std::max(worstMm, std::abs(a - b));
        }
    EXPECT_GT(hits, 150) << "the plate covers about a quarter of the window";
    EXPECT_LE(differ, 8) << "more than the silhouette differs";
    EXPECT_LT(worstMm, 0.5);
    // A ray straight down the middle agrees too (castRay takes the same path as render).
    const RayHit farRay = renderer.castRay(farView, 16, 16);
    const RayHit nearRay = renderer.castRay(nearView, 16, 16);
    ASSERT_TRUE(farRay.hit);
    ASSERT_TRUE(nearRay.hit);
    EXPECT_LT(glm::length(farRay.position - nearRay.position), 0.5);
    std::printf("[ info ] far eye: %d bone pixels alike, %d differ, worst depth %.4f mm, "
                "hit points %.4f mm apart\n",
                hits, differ, worstMm, double(glm::length(farRay.position - nearRay.position)));
}

// A frame larger than the camera's window (a caller's mistake the assert names, gone from a
// release build): only the camera's window is rendered, and its hit cache, sized by the camera,
// is never read or written past its end (ASan: a heap overflow before).
TEST(Renderer, AFrameLargerThanTheCameraRendersOnlyTheCamerasWindow) {
    Volume v = makeSphere(32);
    Renderer r(v);
    const Camera camera = cameraPreset("top", v, {32, 32});
#ifdef NDEBUG
    Dbi frame(64, 64);
    for (int y = 0; y < 64; ++y)
        for (int x = 0; x < 64; ++x)
            std::memset(frame.color(x, y), 7, 4);
    HitCache cache;
    r.render(camera, frame.bounds(), frame, &cache);
    EXPECT_EQ(frame.color(40, 40)[0], 7) << "beyond the camera's window: untouched";
    EXPECT_EQ(frame.color(10, 40)[0], 7);
    EXPECT_NE(frame.color(16, 16)[0], 7) << "the window itself is rendered";
#else
    GTEST_SKIP() << "a debug build asserts on the mismatch";
#endif
}

} // namespace trephine

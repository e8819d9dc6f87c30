// `trephine render`: one depth-buffered image of a volume, optionally after drilling burr holes at
// pixels, optionally only a rectangle. Rendering lives in libsim (renderer.h), files in sim_image
// (dbi_io.h); this is only wiring and flag checking.
#include "modes.h"

#include "libsim/camera.h"
#include "libsim/dirty_rect.h"
#include "libsim/error.h"
#include "libsim/hole.h"
#include "libsim/renderer.h"
#include "libsim/thread_pool.h"
#include "libsim/tool_catalogue.h"
#include "libsim/volume_io.h"
#include "libsim_image/dbi_io.h"
#include "libsim_image/volume_slices.h"
#include "net/scene.h"

#include <algorithm>
#include <charconv>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fmt/format.h>
#include <memory>
#include <string>
#include <vector>

namespace trephine::app {

namespace {

struct RenderOptionsCli {
    std::string volume = "skull:256";
    std::string camera = "working";
    std::string eye, target, up;
    float fov = 0.0f;
    std::string size = "500x500";
    std::string out, png, rect;
    std::vector<std::string> drills;
    int threads = 0;
};

// "a,b,c" -> exactly n numbers, or an Error naming the flag.
std::vector<double> parseNumbers(const std::string& flag, const std::string& text, size_t n,
                                 const char* example) {
    std::vector<double> values;
    const char* p = text.data();
    const char* end = text.data() + text.size();
    while (p <= end) {
        const char* comma = std::find(p, end, ',');
        double v = 0.0;
        auto [ptr, ec] = std::from_chars(p, comma, v);
        if (ec != std::errc() || ptr != comma || p == comma || !std::isfinite(v))
            throw Error(flag + " " + text + ": expected " + example);
        values.push_back(v);
        p = comma + 1;
    }
    if (values.size() != n)
        throw Error(flag + " " + text + ": expected " + example);
    return values;
}

glm::vec3 parseVec3(const std::string& flag, const std::string& text) {
    std::vector<double> v = parseNumbers(flag, text, 3, "x,y,z in mm, e.g. 0,-300,0");
    // A float holds more, but a camera kilometres away sees nothing of a skull.
    constexpr double kMaxMm = 1e6;
    for (double c : v)
        if (std::abs(c) > kMaxMm)
            throw Error(flag + " " + text + ": each coordinate must be within +-1e6 mm");
    return glm::vec3(float(v[0]), float(v[1]), float(v[2]));
}

glm::ivec2 parseSize(const std::string& text) {
    size_t x = text.find('x');
    int w = 0, h = 0;
    bool ok = x != std::string::npos;
    if (ok) {
        auto [p1, e1] = std::from_chars(text.data(), text.data() + x, w);
        auto [p2, e2] = std::from_chars(text.data() + x + 1, text.data() + text.size(), h);
        ok = e1 == std::errc() && e2 == std::errc() && p1 == text.data() + x &&
             p2 == text.data() + text.size();
    }
    if (!ok || w <= 0 || h <= 0 || w > 16384 || h > 16384)
        throw Error("--size " + text + ": expected WIDTHxHEIGHT in pixels, e.g. 500x500");
    return {w, h};
}

int asInt(const std::string& flag, const std::string& text, double v) {
    if (v != std::floor(v) || std::abs(v) > 1e6)
        throw Error(flag + " " + text + ": pixel coordinates must be whole numbers");
    return int(v);
}

struct DrillAt {
    int px, py; // top-left origin
    float depthMm, diameterMm;
    std::string text;
};

DrillAt parseDrill(const std::string& text) {
    const char* example = "PX,PY,DEPTH_MM,DIAMETER_MM, e.g. 250,250,3,4";
    std::vector<double> v = parseNumbers("--drill-at", text, 4, example);
    DrillAt d{asInt("--drill-at", text, v[0]), asInt("--drill-at", text, v[1]), float(v[2]),
              float(v[3]), text};
    if (d.depthMm < 0.0f || d.depthMm > 100.0f)
        throw Error("--drill-at " + text + ": depth must be 0 to 100 mm");
    const ToolType& burr = toolType(ToolKind::Burr);
    if (!(d.diameterMm >= burr.minDiameterMm && d.diameterMm <= burr.maxDiameterMm))
        throw Error("--drill-at " + text + ": the burr diameter must be " +
                    std::to_string(int(burr.minDiameterMm)) + " to " +
                    std::to_string(int(burr.maxDiameterMm)) + " mm");
    return d;
}

double msSince(std::chrono::steady_clock::time_point t0) {
    return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

std::string describeBox(const Box3i& b) {
    if (b.empty())
        return "empty";
    return fmt::format("{} {} {} {} {} {}", b.lo.x, b.lo.y, b.lo.z, b.hi.x, b.hi.y, b.hi.z);
}

// The flags that need the window's size, read and checked before any work: the drills, the
// rectangle (top-left origin) and the outputs' names and folders (a wrong --png or a missing
// folder fails before the render and before --out is written).
struct RenderJob {
    glm::ivec2 size{0};
    std::vector<DrillAt> drills;
    PixelRect rectTop{};
};

RenderJob checkedJob(const RenderOptionsCli& o) {
    RenderJob job;
    job.size = parseSize(o.size);
    for (const std::string& t : o.drills)
        job.drills.push_back(parseDrill(t));
    if (!o.rect.empty()) {
        std::vector<double> v = parseNumbers("--rect", o.rect, 4,
                                             "X,Y,W,H in pixels from the top-left, e.g. 0,0,64,64");
        job.rectTop = {asInt("--rect", o.rect, v[0]), asInt("--rect", o.rect, v[1]),
                       asInt("--rect", o.rect, v[2]), asInt("--rect", o.rect, v[3])};
        if (job.rectTop.empty() || !PixelRect{0, 0, job.size.x, job.size.y}.contains(job.rectTop))
            throw Error("--rect " + o.rect + ": must be a non-empty rectangle inside the " +
                        o.size + " window");
    }
    if (o.out.empty() && o.png.empty())
        std::printf("note: no --out or --png given; rendering for timing only\n");
    if (!o.out.empty()) {
        checkDbiExrPath(o.out);
        checkOutputFolder("--out", o.out);
    }
    if (!o.png.empty()) {
        checkColorPngPath(o.png);
        checkOutputFolder("--png", o.png);
    }
    return job;
}

// The volume, with the paper's spacing for `--camera paper`.
Volume openForRender(const RenderOptionsCli& o, glm::ivec2 size) {
    const auto t0 = std::chrono::steady_clock::now();
    Volume volume = openVolume(o.volume);
    const glm::ivec3 dims = volume.dims();
    std::printf("volume %s: %d x %d x %d voxels, spacing %g mm (loaded in %.0f ms)\n",
                o.volume.c_str(), dims.x, dims.y, dims.z, volume.spacing().x, msSince(t0));
    if (o.camera == "paper") {
        int n = std::max({dims.x, dims.y, dims.z});
        float s = paperSpacingMm(n);
        volume.setSpacing(glm::vec3(s));
        std::printf("camera paper: spacing set to %.4f mm so the %d-voxel volume's front face "
                    "spans %g px at %g mm with a %g degree field of view (paper, section 4.1)\n",
                    s, n, kPaperProjectedPx * size.y / kPaperWindowPx, kPaperDistanceMm,
                    kPaperFovYDeg);
    }
    return volume;
}

// --eye, --target, --up and --fov over the preset's camera.
void applyCustomCamera(const RenderOptionsCli& o, const Volume& volume, Camera& camera) {
    bool custom = false;
    if (!o.eye.empty())
        camera.eye = parseVec3("--eye", o.eye), custom = true;
    if (!o.target.empty())
        camera.target = parseVec3("--target", o.target), custom = true;
    if (!o.up.empty())
        camera.up = parseVec3("--up", o.up), custom = true;
    if (o.fov != 0.0f) {
        if (!(o.fov > 0.5f && o.fov < 170.0f))
            throw Error("--fov " + std::to_string(o.fov) + ": must be between 0.5 and 170 degrees");
        camera.fovYDeg = o.fov;
        custom = true;
    }
    if (!custom)
        return;
    glm::vec3 forward = camera.target - camera.eye;
    if (glm::length(forward) < 1e-3f)
        throw Error("--eye and --target must differ");
    if (glm::length(glm::cross(forward, camera.up)) < 1e-6f * glm::length(forward))
        throw Error("--up must not be parallel to the view direction");
    fitNearFar(camera, glm::vec3(0.0f), 0.5f * glm::length(volume.extentMm()));
}

Camera renderCamera(const RenderOptionsCli& o, const Volume& volume, glm::ivec2 size) {
    Camera camera = cameraPreset(o.camera, volume, size);
    // A saved session's scene beside the volume: its presets, as the server computed them before
    // the save (the drilled skull's site has moved; the view a preset names has not). Not `paper`,
    // which sets its own spacing.
    const std::string volumeFile = volumeFileOf(o.volume);
    std::error_code ec;
    if (o.camera != "paper" && !volumeFile.empty() &&
        std::filesystem::is_regular_file(net::scenePathFor(volumeFile), ec))
        if (const auto saved =
                net::presetCamera(net::sceneForVolume(volume, volumeFile), o.camera, size)) {
            camera = *saved;
            std::printf("camera %s: from the saved scene %s\n", o.camera.c_str(),
                        net::scenePathFor(volumeFile).c_str());
        }
    applyCustomCamera(o, volume, camera);
    std::printf("camera %s: %s\n", o.camera.c_str(), describe(camera).c_str());
    return camera;
}

// Every --drill-at in turn, each at the bone under its pixel now: BB_volume of them all.
Box3i drillAll(const RenderOptionsCli& o, const RenderJob& job, const Camera& camera,
               Volume& volume, Renderer& renderer) {
    Box3i bbVolume;
    for (size_t i = 0; i < job.drills.size(); ++i) {
        const DrillAt& d = job.drills[i];
        if (d.px < 0 || d.py < 0 || d.px >= job.size.x || d.py >= job.size.y)
            throw Error("--drill-at " + d.text + ": pixel outside the " + o.size + " window");
        RayHit hit = renderer.castRay(camera, d.px, job.size.y - 1 - d.py);
        if (!hit.hit)
            throw Error("--drill-at " + d.text + ": no bone under pixel (" + std::to_string(d.px) +
                        ", " + std::to_string(d.py) + "); pick a pixel that shows bone");
        const HoleResult hole =
            drillHoleAlong(volume, glm::vec3(hit.position), hit.direction, d.depthMm, d.diameterMm);
        const bool dura = hole.touchedDura;
        const Box3i& changed = hole.changed;
        renderer.volumeChanged(changed);
        bbVolume.merge(changed);
        std::printf("drill %zu: burr %g mm at pixel (%d, %d), surface (%.2f, %.2f, %.2f) mm, "
                    "%g mm deep%s; changed voxels %s\n",
                    i + 1, d.diameterMm, d.px, d.py, hit.position.x, hit.position.y, hit.position.z,
                    d.depthMm, dura ? " (stopped at dura)" : "", describeBox(changed).c_str());
    }
    return bbVolume;
}

void run(const RenderOptionsCli& o) {
    const RenderJob job = checkedJob(o);
    const glm::ivec2 size = job.size;
    Volume volume = openForRender(o, size);
    const Camera camera = renderCamera(o, volume, size);

    ThreadPool pool(o.threads);
    auto t0 = std::chrono::steady_clock::now();
    Renderer renderer(volume, &pool);
    std::printf("brick grid: %d x %d x %d bricks in %.1f ms\n", renderer.bricks().dims().x,
                renderer.bricks().dims().y, renderer.bricks().dims().z, msSince(t0));
    const Box3i bbVolume = drillAll(o, job, camera, volume, renderer);

    const bool partial = !o.rect.empty();
    const PixelRect rect =
        partial ? flipRows(job.rectTop, size.y) : PixelRect{0, 0, size.x, size.y};
    t0 = std::chrono::steady_clock::now();
    Dbi image = renderer.renderRect(camera, rect);
    double ms = msSince(t0);
    std::string where = partial ? " (rect " + describe(job.rectTop) + ", top-left origin)" : "";
    std::printf("render %dx%d%s in %.2f ms on %d threads\n", rect.w, rect.h, where.c_str(), ms,
                pool.size());

    if (!job.drills.empty()) {
        PixelRect screen = dirtyScreenRect(camera, volume, bbVolume);
        std::printf("BB_volume %s\n", describeBox(bbVolume).c_str());
        std::printf("BB_screen %s\n", describe(flipRows(screen, size.y)).c_str());
    }
    if (!o.out.empty()) {
        writeDbiExr(o.out, image, rect, size.x, size.y);
        std::printf("wrote %s\n", o.out.c_str());
    }
    if (!o.png.empty()) {
        writeColorPng(o.png, image);
        std::printf("wrote %s\n", o.png.c_str());
    }
}

} // namespace

void addRenderMode(CLI::App& root, int& exitCode) {
    auto o = std::make_shared<RenderOptionsCli>();
    CLI::App* sub = root.add_subcommand("render", "Render one depth-buffered image of a volume");
    sub->add_option("--volume", o->volume,
                    "Volume spec: skull:N, sphere:N, box:N, a file, a folder")
        ->capture_default_str();
    std::string presets;
    for (const std::string& n : cameraPresetNames())
        presets += (presets.empty() ? "" : "|") + n;
    sub->add_option("--camera", o->camera,
                    "View preset: " + presets + " (paper also sets the paper's spacing)")
        ->capture_default_str();
    sub->add_option("--eye", o->eye, "x,y,z: camera position in mm (overrides the preset)");
    sub->add_option("--target", o->target, "x,y,z: point looked at in mm (overrides the preset)");
    sub->add_option("--up", o->up, "x,y,z: up direction (overrides the preset)");
    sub->add_option("--fov", o->fov, "Vertical field of view in degrees (overrides the preset)");
    sub->add_option("--size", o->size, "Window WIDTHxHEIGHT in pixels")->capture_default_str();
    sub->add_option("--out", o->out, "Write the DBI as OpenEXR (R, G, B, A, Z)")
        ->check(outputFile());
    sub->add_option("--png", o->png, "Write the colour as PNG")->check(outputFile());
    sub->add_option("--rect", o->rect,
                    "X,Y,W,H: render only this rectangle (pixels, top-left origin); the EXR's "
                    "data window sits at its place in the full frame");
    sub->add_option("--drill-at", o->drills,
                    "PX,PY,DEPTH_MM,DIAMETER_MM: before rendering, drill a burr hole DEPTH_MM "
                    "deep at the bone under pixel (PX, PY) (top-left origin) along the view ray; "
                    "repeatable. Prints BB_volume and BB_screen")
        ->take_all();
    sub->add_option("--threads", o->threads, "Render threads (0: all cores)")
        ->capture_default_str()
        ->check(CLI::Range(0, 256));
    sub->footer(volumeSpecHelp());
    sub->callback([o, &exitCode] {
        run(*o);
        exitCode = 0;
    });
}

} // namespace trephine::app

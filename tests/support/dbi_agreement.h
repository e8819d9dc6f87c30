// How close a GPU ray caster's DBI is to the CPU Renderer's of the same camera and volume: the
// tolerance VolumeView meets and the server's GPU renderer is held to (docs/rendering.md).
#pragma once

#include "libsim/camera.h"
#include "libsim/dbi.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <sstream>
#include <string>

namespace trephine::testing {

// Depths agree within this fraction of a voxel, measured in eye space (mm along the view axis),
// where a tolerance means something; window depth is far from linear. Both casters find the same
// trilinear iso-surface from the same samples (t = k dt from the eye) with the same regula-falsi
// step and secant. What differs: the GPU sets the ray up in float (the CPU in double: ~1e-6 of
// the eye distance, under 1e-3 mm here), its texture unit may interpolate with fixed-point
// weights (llvmpipe interpolates in float; GPUs commonly keep 8 fractional bits: a sample moves by
// at most 1/512 voxel, and the secant by a few times that where the surface is oblique), and the
// depth divide is float (about one float ulp of window depth, 1e-4 mm in eye space here). All
// are well under a tenth of a voxel (measured on llvmpipe: at most 3e-4 voxel). Pixels beyond
// it can only be grazing rays where a sample just at 128 falls on the other side and the first
// inside sample moves by a whole step: hence 99 %, not all.
inline constexpr double kDepthToleranceVoxels = 0.1;

struct Agreement {
    int64_t bothHit = 0, depthOk = 0, maskMismatch = 0, maskMismatchOffSilhouette = 0;
    int64_t colorOk = 0, cpuHit = 0;
    double maxEyeErrVoxels = 0;
    std::string describe() const {
        std::ostringstream s;
        s << "both hit " << bothHit << ", depth ok " << depthOk << ", colour ok " << colorOk
          << ", mask mismatch " << maskMismatch << " (" << maskMismatchOffSilhouette
          << " off the silhouette), max eye error " << maxEyeErrVoxels << " voxel";
        return s.str();
    }
};

inline Agreement agree(const Dbi& gpu, const Dbi& cpu, const Camera& cam, float voxelMm) {
    Agreement a;
    auto hit = [](const Dbi& d, int x, int y) { return d.depth(x, y) < 1.0f; };
    for (int y = 0; y < cam.height; ++y)
        for (int x = 0; x < cam.width; ++x) {
            bool hg = hit(gpu, x, y), hc = hit(cpu, x, y);
            a.cpuHit += hc;
            if (hg != hc) {
                ++a.maskMismatch;
                // On the silhouette: some 8-neighbour of the CPU image is on the other side.
                bool edge = false;
                for (int dy = -1; dy <= 1; ++dy)
                    for (int dx = -1; dx <= 1; ++dx) {
                        int nx = x + dx, ny = y + dy;
                        if (nx >= 0 && ny >= 0 && nx < cam.width && ny < cam.height)
                            edge = edge || hit(cpu, nx, ny) != hc;
                    }
                a.maskMismatchOffSilhouette += !edge;
                continue;
            }
            if (!hg) {
                EXPECT_EQ(gpu.color(x, y)[0], kBackgroundRgba[0]);
                continue;
            }
            ++a.bothHit;
            double eg = eyeZFromWindowDepth(cam, gpu.depth(x, y));
            double ec = eyeZFromWindowDepth(cam, cpu.depth(x, y));
            double err = std::abs(eg - ec) / voxelMm;
            a.maxEyeErrVoxels = std::max(a.maxEyeErrVoxels, err);
            a.depthOk += err <= kDepthToleranceVoxels;
            int dc = 0;
            for (int i = 0; i < 3; ++i)
                dc = std::max(dc, std::abs(int(gpu.color(x, y)[i]) - int(cpu.color(x, y)[i])));
            a.colorOk += dc <= 4; // 16-bit float gradients and fixed-point filtering: a few levels
        }
    return a;
}

inline void expectAgreement(const Agreement& a) {
    std::printf("  %s\n", a.describe().c_str());
    ASSERT_GT(a.bothHit, 1000) << a.describe();
    EXPECT_GE(double(a.depthOk), 0.99 * double(a.bothHit)) << a.describe();
    EXPECT_GE(double(a.colorOk), 0.98 * double(a.bothHit)) << a.describe();
    // Hit and miss disagree only on the silhouette, and there on a small share of its pixels.
    EXPECT_EQ(a.maskMismatchOffSilhouette, 0) << a.describe();
    EXPECT_LE(double(a.maskMismatch), 0.01 * double(a.cpuHit)) << a.describe();
}

} // namespace trephine::testing

// Critical structures: the procedural skull's sagittal sinus and middle meningeal artery, their
// survival through a save, label maps that bring them to real scans, and the drill's respect for
// them.
#include "libsim/camera.h"
#include "libsim/drill.h"
#include "libsim/error.h"
#include "libsim/renderer.h"
#include "libsim/skull.h"
#include "libsim/tool.h"
#include "libsim/volume_io.h"
#include "test_support.h"

#include <array>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <glm/gtc/quaternion.hpp>
#include <gtest/gtest.h>

using namespace trephine;
using trephine::testing::TempDir;

namespace {

const Volume& skull256() {
    static const Volume v = makeSkull(256);
    return v;
}

bool touchesAir(const Volume& v, glm::ivec3 q) {
    for (glm::ivec3 d : {glm::ivec3(1, 0, 0), glm::ivec3(-1, 0, 0), glm::ivec3(0, 1, 0),
                         glm::ivec3(0, -1, 0), glm::ivec3(0, 0, 1), glm::ivec3(0, 0, -1)})
        if (v.inside(q + d) && v.material(q.x + d.x, q.y + d.y, q.z + d.z) == Material::Air)
            return true;
    return false;
}

std::string errorOf(const std::string& spec) {
    try {
        loadVolume(spec);
    } catch (const Error& e) {
        return e.what();
    }
    return "(loaded)";
}

void writeFile(const std::string& path, const std::string& text) {
    std::ofstream(path, std::ios::binary) << text;
}

// A 3-D uint8 NRRD with the given key/value lines, as 3D Slicer writes a label map.
void writeLabelNrrd(const std::string& path, glm::ivec3 n, const std::vector<uint8_t>& labels,
                    const std::string& keyValues) {
    std::string h = "NRRD0004\ntype: uint8\ndimension: 3\nsizes: " + std::to_string(n.x) + " " +
                    std::to_string(n.y) + " " + std::to_string(n.z) + "\nencoding: raw\n" +
                    keyValues + "\n";
    writeFile(path, h + std::string(labels.begin(), labels.end()));
}

} // namespace

TEST(Skull, TheSinusRunsInTheMidlineUnderTheInnerTable) {
    const Volume& v = skull256();
    const glm::ivec3 n = v.dims();
    int64_t sinus = 0, exposed = 0, offMidline = 0;
    float yLo = 1e9f, yHi = -1e9f;
    for (int z = 0; z < n.z; ++z)
        for (int y = 0; y < n.y; ++y)
            for (int x = 0; x < n.x; ++x)
                if (v.material(x, y, z) == Material::Sinus) {
                    ++sinus;
                    const glm::vec3 p = v.voxelCenter({x, y, z});
                    offMidline += std::fabs(p.x) > 5.0f;
                    // The cut below the vault shows the sinus in section, like the diploe.
                    const bool nearCut = p.z < -45.0f + 0.12f * p.y + 3.0f;
                    exposed += !nearCut && touchesAir(v, {x, y, z});
                    yLo = std::min(yLo, p.y);
                    yHi = std::max(yHi, p.y);
                }
    ASSERT_GT(sinus, 1000);
    EXPECT_EQ(offMidline, 0);
    EXPECT_EQ(exposed, 0);        // always under bone
    EXPECT_GT(yHi - yLo, 150.0f); // front to back along the vault
    // Under the vertex: bone, then the sinus, a few mm wide.
    const int cy = int(v.toVoxel(glm::vec3(0.0f)).y);
    int top = n.z - 1;
    const int cx = n.x / 2;
    while (v.material(cx, cy, top) == Material::Air)
        --top;
    int z = top;
    while (isBone(v.material(cx, cy, z)))
        --z;
    ASSERT_EQ(v.material(cx, cy, z), Material::Sinus);
    int width = 0;
    for (int x = 0; x < n.x; ++x)
        width += v.material(x, cy, z) == Material::Sinus;
    EXPECT_NEAR(width * v.spacing().x, 5.9f, 1.6f);
}

TEST(Skull, TheMeningealArteryBranchesOnBothTemporalWallsInTheInnerTable) {
    const Volume& v = skull256();
    const glm::ivec3 n = v.dims();
    int64_t left = 0, right = 0, exposed = 0, high = 0, besideBone = 0;
    for (int z = 0; z < n.z; ++z)
        for (int y = 0; y < n.y; ++y)
            for (int x = 0; x < n.x; ++x)
                if (v.material(x, y, z) == Material::Artery) {
                    const glm::vec3 p = v.voxelCenter({x, y, z});
                    (p.x > 0 ? left : right)++;
                    exposed += touchesAir(v, {x, y, z});
                    high += p.z > 25.0f;
                    for (int dx : {-1, 1})
                        besideBone += v.inside({x + dx, y, z}) && isBone(v.material(x + dx, y, z));
                }
    EXPECT_GT(left, 300);
    EXPECT_GT(right, 300);
    EXPECT_LT(std::abs(left - right), (left + right) / 10); // mirrored
    EXPECT_EQ(exposed, 0);
    EXPECT_EQ(high, 0);                        // temporal and parietal, well below the vertex
    EXPECT_GT(besideBone, (left + right) / 4); // in a groove of the inner table
}

TEST(Skull, TheStructuresAreThereAtEverySize) {
    for (int n : {32, 64, 128}) {
        SCOPED_TRACE(n);
        const std::vector<int64_t> counts = makeSkull(n).materialCounts();
        EXPECT_GT(counts[int(Material::Sinus)], 0);
        EXPECT_GT(counts[int(Material::Artery)], 0);
    }
}

TEST(Drill, TouchingTheSinusIsAViolationAndLeavesItWhole) {
    Volume v({40, 40, 40}, glm::vec3(0.5f));
    v.fill(Box3i{{0, 0, 0}, {40, 40, 20}}, 190, Material::Sinus);
    v.fill(Box3i{{0, 0, 20}, {40, 40, 24}}, 240, Material::Cortical);
    const Volume before = v;
    Driller burr(ToolShape::burr(3.0f));
    const DrillResult r =
        burr.drill(v, ToolPose::fromAxis(v.voxelCenter({20, 20, 21}), {0, 0, 1}), 1.0f, 1.0f);
    EXPECT_TRUE(r.duraContact);
    EXPECT_GT(r.voxelsRemoved, 0); // the bone around it still erodes
    for (size_t i = 0; i < v.voxelCount(); ++i) {
        if (before.materialData()[i] == uint8_t(Material::Sinus)) {
            ASSERT_EQ(v.densityData()[i], before.densityData()[i]) << "voxel " << i;
        }
    }
}

TEST(VolumeIo, TheStructuresSurviveASaveAndReload) {
    TempDir dir;
    const Volume skull = makeSkull(64);
    const std::string path = dir / "skull.nrrd";
    saveVolume(skull, path);
    const Volume back = loadVolume(path);
    EXPECT_TRUE(back == skull);
    EXPECT_GT(back.materialCounts()[int(Material::Sinus)], 0);
    EXPECT_GT(back.materialCounts()[int(Material::Artery)], 0);
}

TEST(VolumeIo, ASlicerSegmentationNamesTheStructuresOfAScan) {
    TempDir dir;
    const glm::ivec3 n(6, 5, 4);
    Volume scan(n, glm::vec3(0.8f));
    scan.fill(Box3i{{0, 0, 2}, {6, 5, 4}}, 240, Material::Cortical); // bone on top
    saveVolume(scan, dir / "scan.nii"); // density only, as a CT would come
    std::vector<uint8_t> labels(size_t(n.x * n.y * n.z), 0);
    labels[0] = 3;  // segment 0: the sinus
    labels[1] = 7;  // segment 1: an artery
    labels[2] = 9;  // segment 2: a tumour, not a structure Trephine models
    labels[40] = 3; // (x 4, y 1, z 1)
    writeLabelNrrd(dir / "seg.nrrd", n, labels,
                   "Segment0_Name:=Superior sagittal sinus\nSegment0_LabelValue:=3\n"
                   "Segment1_Name:=Middle meningeal artery\nSegment1_LabelValue:=7\n"
                   "Segment2_Name:=Tumor\nSegment2_LabelValue:=9\n");
    const Volume v = loadVolume(dir / "scan.nii?labels=seg.nrrd"); // beside the scan
    EXPECT_EQ(v.material(0, 0, 0), Material::Sinus);
    EXPECT_EQ(v.density(0, 0, 0), kSkullSinusDensity); // visible once exposed
    EXPECT_EQ(v.material(1, 0, 0), Material::Artery);
    EXPECT_EQ(v.material(2, 0, 0), Material::Air); // the tumour keeps what the scan says
    EXPECT_EQ(v.material(4, 1, 1), Material::Sinus);
    EXPECT_EQ(v.material(3, 3, 3), Material::Cortical);
}

TEST(VolumeIo, ANiftiLabelMapTakesItsNamesFromAColourTable) {
    TempDir dir;
    const glm::ivec3 n(4, 4, 4);
    Volume scan(n, glm::vec3(1.0f));
    saveVolume(scan, dir / "scan.nrrd");
    Volume labels(n, glm::vec3(1.0f));
    labels.set(1, 2, 3, 5, Material::Cortical); // density 5 is the label value
    labels.set(2, 2, 2, 6, Material::Cortical);
    saveVolume(labels, dir / "seg.nii.gz");
    writeFile(dir / "names.ctbl", "# Slicer colour table\n0 Background 0 0 0 0\n"
                                  "5 Dura_mater 200 80 80 255\n6 Brain 220 180 170 255\n");
    const Volume v = loadVolume(dir / "scan.nrrd?labels=seg.nii.gz&names=names.ctbl");
    EXPECT_EQ(v.material(1, 2, 3), Material::Dura);
    EXPECT_EQ(v.density(1, 2, 3), kSkullDuraDensity);
    EXPECT_EQ(v.material(2, 2, 2), Material::Brain);
    EXPECT_EQ(v.material(0, 0, 0), Material::Air);
}

TEST(VolumeIo, LabelMapMistakesAreRefusedInOneLine) {
    TempDir dir;
    Volume scan({4, 4, 4}, glm::vec3(1.0f));
    saveVolume(scan, dir / "scan.nrrd");
    writeLabelNrrd(dir / "small.nrrd", {2, 2, 2}, std::vector<uint8_t>(8, 1),
                   "Segment0_Name:=Dura\n");
    writeLabelNrrd(dir / "tumour.nrrd", {4, 4, 4}, std::vector<uint8_t>(64, 1),
                   "Segment0_Name:=Tumor\n");
    writeLabelNrrd(dir / "unnamed.nrrd", {4, 4, 4}, std::vector<uint8_t>(64, 1), "");
    writeFile(dir / "bad.ctbl", "x Dura\n");
    const std::string scanPath = dir / "scan.nrrd";
    const std::pair<std::string, std::string> cases[] = {
        {"?labels=small.nrrd", "the label map is 2x2x2 but the volume is 4x4x4"},
        {"?labels=tumour.nrrd", "no label names a structure Trephine models"},
        {"?labels=unnamed.nrrd", "no label names: give a names table"},
        {"?names=bad.ctbl", "give labels=FILE too"},
        {"?labels=unnamed.nrrd&names=bad.ctbl", "line 1: expected 'VALUE NAME', found 'x'"},
        {"?labels=missing.nrrd", "missing.nrrd"},
    };
    for (const auto& [query, message] : cases) {
        const std::string e = errorOf(scanPath + query);
        EXPECT_NE(e.find(message), std::string::npos) << query << ": " << e;
        EXPECT_EQ(e.find('\n'), std::string::npos) << e;
    }
}

TEST(Skull, SmoothBoneShadesWithoutContourRings) {
    // Terracing shows as a ripple of the shading across the view: second differences of the
    // colour along rows well above the byte rounding of a smooth gradient. Counted over the bone
    // of the working view of skull:256, sutures included.
    const Volume& v = skull256();
    const Camera c = cameraPreset("working", v, {400, 400});
    const Dbi dbi = Renderer(v).render(c);
    int64_t pixels = 0, ripples = 0;
    for (int y = 0; y < dbi.height(); ++y)
        for (int x = 1; x + 1 < dbi.width(); ++x) {
            if (dbi.depth(x - 1, y) >= 1.0f || dbi.depth(x, y) >= 1.0f ||
                dbi.depth(x + 1, y) >= 1.0f)
                continue;
            const int d2 = int(dbi.color(x - 1, y)[0]) - 2 * int(dbi.color(x, y)[0]) +
                           int(dbi.color(x + 1, y)[0]);
            ++pixels;
            ripples += std::abs(d2) >= 3;
        }
    ASSERT_GT(pixels, 100000);
    const double share = double(ripples) / double(pixels);
    std::printf("[ info ] pixels with a shading ripple: %.2f %% (target under 4 %%; 10.5 %% with a "
                "1-voxel ramp)\n",
                100 * share);
    EXPECT_LT(share, 0.04);
}

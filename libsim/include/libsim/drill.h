// Drilling: erode bone under a cutter at a rate set by drilling speed and material hardness, and
// return the tight box of changed voxels (BB_volume). Deterministic: same inputs, same bytes.
#pragma once

#include "libsim/box.h"
#include "libsim/tool.h"
#include "libsim/volume.h"

#include <algorithm>
#include <array>
#include <cstdint>
#include <vector>

namespace trephine {

// Each tool's erosion rate at full speed (speed 1), in density units per second for cortical
// bone, is its catalogue entry's (ToolType::erosionRate): every voxel whose centre lies inside the
// cutter loses that much density. Diploe erodes kDiploeErosionFactor times faster; dura and brain
// never erode. See docs/simulation.md.
inline constexpr int kDiploeErosionFactor = 3;

// Perforator clutch rule. Before each step the perforator looks a margin beyond its cutting
// surface: kPerforatorClutchMarginMm, or one voxel where voxels are larger (perforatorClutch-
// MarginMm). It disengages (cuts nothing) when
//   (a) dura or brain lies within that margin: the tip is through the inner table, or
//   (b) after its tip has been in bone, the tip, at or beyond the deepest point where it had
//       bone ahead, finds no bone ahead of it while bone is still within the margin of the
//       cutter: it broke through into air (a bone block, a cut edge).
// It re-engages once no bone lies within the margin of the cutter: lifted clear of the hole.
inline constexpr float kPerforatorClutchMarginMm = 0.5f;
// The margin for voxels of `spacing`: at least the largest spacing, so that dura face to face
// with a voxel inside the cutter is always within it (tested at voxel centres, 0.5 mm let the
// one-voxel inner table of skull:128, 1.56 mm voxels, be cut through to the dura).
inline float perforatorClutchMarginMm(glm::vec3 spacing) {
    return std::max({kPerforatorClutchMarginMm, spacing.x, spacing.y, spacing.z});
}

// Density units removed from a voxel of material m per unit of cortical erosion (0: never eroded).
int erosionFactor(Material m);
// Cortical erosion rate of a tool at full speed, density units per second (its catalogue's).
double erosionRate(ToolKind kind);

struct DrillResult {
    Box3i changed;             // tight box of voxels whose density or material changed
    int64_t voxelsTouched = 0; // voxels whose centre lay inside the cutter
    int64_t voxelsChanged = 0;
    int64_t densityRemoved = 0;    // sum of density decrements (density units)
    int64_t voxelsRemoved = 0;     // voxels eroded to zero (relabelled air) in this step
    bool duraContact = false;      // the cutter touched dura or brain: a violation (reported at any
    int64_t duraVoxels = 0;        // speed); dura and brain are never removed, bone around still is
    bool clutchDisengaged = false; // perforator only: the clutch was disengaged for this step
                                   // (the tip has broken through), so nothing was cut
    // By material label: voxels eroded to zero (by the label they had), and soft-tissue voxels
    // inside the cutter (which of the structures it touched). The assessment credits them.
    std::array<int64_t, kMaterialCount> removedBy{};
    std::array<int64_t, kMaterialCount> contactBy{};
};

// A tool's motion between two sampled poses, cut into sub-steps so that the cutter sweeps the
// path instead of jumping from pose to pose: equal sub-steps of at most maxStepMm (positions
// lerped, orientations slerped), each ending at the returned pose; the last is `to`. One step (just
// `to`) when the move is within maxStepMm, and also when it is longer than maxSweepMm (a jump, e.g.
// a device re-centred: cutting a trench along it would be wrong) or not finite. At most
// kMaxSweepSteps steps (longer moves take longer sub-steps).
inline constexpr int kMaxSweepSteps = 64;
std::vector<ToolPose> sweepPoses(const ToolPose& from, const ToolPose& to, float maxStepMm,
                                 float maxSweepMm);

// One driller per tool: it keeps the fractional erosion carried between steps and the
// perforator's clutch state, so a stream of small dt steps erodes like one long step.
class Driller {
public:
    explicit Driller(ToolShape shape) : m_shape(shape) {}

    // speed in [0, 1] (fraction of full drill speed; clamped, NaN is 0); dt >= 0 in seconds.
    // Voxels whose centre lies inside the cutter at `pose` lose density; the cutter does not sweep
    // between poses, so callers step small distances (well under a voxel per step). The pose's
    // orientation need not be unit length: it is normalised.
    DrillResult drill(Volume& volume, const ToolPose& pose, float speed, float dt);

    // A pose of the tool while it does not drill (the button up, speed 0): the perforator's
    // clutch re-engages when it is clear of bone, as when drilling. Without it, released, lifted
    // and pressed onto bone elsewhere, the perforator's first drilling step found bone and never
    // re-engaged: it cut nothing at the second hole. A burr ignores it.
    void observe(const Volume& volume, const ToolPose& pose);

    const ToolShape& shape() const { return m_shape; }
    bool clutchDisengaged() const { return m_clutchDisengaged; }
    // The clutch re-engages when the perforator is lifted clear of bone; tests may reset it.
    void resetClutch() {
        m_clutchDisengaged = false;
        m_tipInBone = false;
    }

private:
    ToolShape m_shape;
    double m_carry = 0.0; // fractional cortical density units not yet removed
    bool m_clutchDisengaged = false;
    bool m_tipInBone = false; // perforator: the tip has met bone since the clutch last engaged
    float m_deepestMm = 0.0f; // ... and the deepest apex (along the axis) with bone ahead
};

} // namespace trephine

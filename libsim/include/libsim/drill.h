// Drilling: erode bone under a cutter at a rate set by drilling speed and material hardness, and
// return the tight box of changed voxels (BB_volume). Deterministic: same inputs, same bytes.
#pragma once

#include "libsim/box.h"
#include "libsim/tool.h"
#include "libsim/volume.h"

#include <cstdint>

namespace trephine {

struct DrillResult {
    Box3i changed;             // tight box of voxels whose density or material changed
    int64_t voxelsTouched = 0; // voxels whose centre lay inside the cutter
    int64_t voxelsChanged = 0;
    int64_t densityRemoved = 0; // sum of density decrements (density units)
    int64_t voxelsRemoved = 0;  // voxels eroded to zero (relabelled air) in this step
    bool duraContact = false;   // the cutter touched dura or brain: a violation, nothing removed
    int64_t duraVoxels = 0;
    bool clutchDisengaged = false; // perforator only: the tip has broken through the inner table
};

// One driller per tool: it keeps the fractional erosion carried between steps and the
// perforator's clutch state, so a stream of small dt steps erodes like one long step.
class Driller {
public:
    explicit Driller(ToolShape shape) : m_shape(shape) {}

    // speed in [0, 1] (fraction of full drill speed); dt in seconds.
    DrillResult drill(Volume& volume, const ToolPose& pose, float speed, float dt);

    const ToolShape& shape() const { return m_shape; }
    bool clutchDisengaged() const { return m_clutchDisengaged; }
    // The clutch re-engages when the perforator is lifted clear of bone; tests may reset it.
    void resetClutch() { m_clutchDisengaged = false; }

private:
    ToolShape m_shape;
    double m_carry = 0.0; // fractional density units not yet removed
    bool m_clutchDisengaged = false;
};

} // namespace trephine

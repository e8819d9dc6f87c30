// Haptic contact force between a cutter and the bone density field: a point shell over the cutter
// surface with penetration-based penalty forces, plus the force's 3x3 gradient for the multi-rate
// interface (the server sends f and grad f; the client extrapolates between updates).
#pragma once

#include "libsim/tool.h"
#include "libsim/volume.h"

#include <algorithm>
#include <glm/mat3x3.hpp>
#include <glm/vec3.hpp>
#include <memory>
#include <vector>

namespace trephine {

inline constexpr float kDefaultMaxForceN = 8.5f; // a PHANToM Premium's peak force
inline constexpr float kDefaultStiffnessNPerMm = 6.0f;

struct ForceModelConfig {
    // Penalty stiffness (N/mm) of a cutter whose whole front half is pressed in: each shell point
    // carries stiffness * (its area / the cutter's cross-section area).
    float stiffnessNPerMm = kDefaultStiffnessNPerMm;
    float maxForceN = kDefaultMaxForceN; // the device maximum; |force| is clamped to it
    // Viscous resistance along the shaft while drilling (N per mm/s at full speed), scaled by the
    // fraction of shell points in contact, against feeding into the bone only (an axial motion
    // against the contact force; a withdrawal is free). Not part of the gradient (it depends on
    // velocity).
    float drillDampingNsPerMm = 0.01f;
    // Shell point spacing (mm); 0 picks one from the cutter size (about 450 points per burr, 900
    // for the 14 mm perforator), so the cost does not grow with the burr.
    float pointSpacingMm = 0.0f;
};

// One point of the cutter's surface shell, in the tool-local frame.
struct ShellPoint {
    glm::vec3 position; // on the cutter surface (mm, tool-local)
    glm::vec3 normal;   // outward unit normal (tool-local)
    float weight;       // area / cross-section area: stiffness share of the point
};

struct ForceResult {
    glm::vec3 force{0.0f};    // on the tool (N), clamped to maxForceN
    glm::mat3 gradient{0.0f}; // d force / d position (N/mm), symmetrised: conservative when used
                              // as F(p) = f + gradient (p - p_N). glm is column-major:
                              // gradient[col][row] = d force[row] / d position[col]
    glm::mat3 jacobian{0.0f}; // the exact (unsymmetrised) derivative of the clamped force
    bool contact = false;     // some shell point is inside bone
    int contactPoints = 0;
    bool clamped = false; // |force| reached maxForceN
};

class ForceModel {
public:
    explicit ForceModel(const ToolShape& shape, ForceModelConfig config = {});

    // Force on the tool at `pose` against `volume` (object space, mm). `speed` in [0, 1] and the
    // tool's velocity (mm/s) add the drilling resistance; with speed 0 the force depends on the
    // position only. Cost: one trilinear sample with gradient per shell point.
    ForceResult compute(const Volume& volume, const ToolPose& pose, float speed = 0.0f,
                        glm::vec3 velocityMmPerS = glm::vec3(0.0f)) const;

    const ToolShape& shape() const { return m_shape; }
    const ForceModelConfig& config() const { return m_config; }
    const std::vector<ShellPoint>& shell() const { return m_shell; }

private:
    ToolShape m_shape;
    ForceModelConfig m_config;
    std::vector<ShellPoint> m_shell;
};

// The tool's velocity (mm/s) from its successive positions: the drilling resistance needs one and
// no device or tool state carries it. 0 for the first position, after a gap of over kMaxGapS, and
// for a step faster than kMaxMmPerS (a device re-centred, a tool put elsewhere); a position not
// later than the last (a reordered tool state) gives 0 and is not kept.
class VelocityEstimate {
public:
    static constexpr double kMaxGapS = 0.1;
    static constexpr float kMaxMmPerS = 1000.0f;
    glm::vec3 update(glm::vec3 position, double timeS);

private:
    bool m_have = false;
    glm::vec3 m_last{0.0f};
    double m_lastS = 0.0;
};

// One ForceModel per tool shape, built on first use: the server's network thread answers each
// tool state with `cache.get(shape).compute(...)` without rebuilding shells. At most `capacity`
// shapes, the least recently used dropped first: every diameter in the burr's range is valid, so
// a peer sending a new one with each tool state (or a burr-size slider dragged) grew it without
// bound (20,000 diameters: +250 MB, and a lookup scanned them all). The reference `get` returns
// is valid until the next `get`. Not thread-safe: one cache per thread. Throws Error (from
// ToolShape::validate) for a shape the factories do not make.
class ForceModelCache {
public:
    static constexpr size_t kDefaultCapacity = 16;
    explicit ForceModelCache(ForceModelConfig config = {}, size_t capacity = kDefaultCapacity)
        : m_config(config), m_capacity(std::max<size_t>(capacity, 1)) {}
    const ForceModel& get(const ToolShape& shape);
    size_t size() const { return m_models.size(); }
    size_t capacity() const { return m_capacity; }

private:
    ForceModelConfig m_config;
    size_t m_capacity;
    // Most recently used first; a few shapes: a linear scan is fine.
    std::vector<std::unique_ptr<ForceModel>> m_models;
};

// The shell a ForceModel uses for `shape` at a given point spacing (0: automatic).
std::vector<ShellPoint> makeShell(const ToolShape& shape, float pointSpacingMm = 0.0f);

// Penetration (mm) the force model assigns to a density: 0 at kSurfaceDensity, rising linearly to
// about one voxel (the smallest spacing) at density 255.
inline float penetrationScaleMm(const Volume& v) {
    glm::vec3 s = v.spacing();
    return std::min(s.x, std::min(s.y, s.z)) / float(255 - kSurfaceDensity);
}

} // namespace trephine

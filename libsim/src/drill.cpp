// Drilling: erosion under a cutter, the perforator's clutch, and the tight box of changed voxels.
//
// [SECTION] Frame and rows — voxel centres in tool-local coordinates, one row at a time
// [SECTION] Passes         — the clutch's look-ahead scan and the erosion pass (raw pointers)
// [SECTION] Driller        — rates, carry, clutch state machine
#include "libsim/drill.h"

#include "libsim/tool_catalogue.h"

#include <algorithm>
#include <cassert>
#include <climits>
#include <cmath>
#include <glm/common.hpp>
#include <glm/geometric.hpp>
#include <glm/gtc/quaternion.hpp>
#include <glm/mat3x3.hpp>
#include <optional>

namespace trephine {

int erosionFactor(Material m) {
    switch (m) {
    case Material::Cortical:
        return 1;
    case Material::Diploe:
        return kDiploeErosionFactor;
    default:
        return 0;
    }
}

double erosionRate(ToolKind kind) {
    return toolType(kind).erosionRate;
}

namespace {

// Density units forgiven when flooring the erosion budget; see Driller::drill.
constexpr double kCarryEpsilon = 1e-4;

// [SECTION] Frame and rows
// The local position of voxel (x, y, z)'s centre is origin + x dx + y dy + z dz: one rotation per
// step instead of a quaternion inverse per voxel.
struct Frame {
    glm::vec3 origin, dx, dy, dz;
};

Frame makeFrame(const Volume& vol, const ToolPose& pose) {
    // Same as ToolPose::toLocal; the pose's quaternion is unit (Driller::drill normalises it).
    glm::mat3 toLocal = glm::mat3_cast(glm::conjugate(pose.orientation));
    glm::vec3 s = vol.spacing();
    Frame f;
    f.origin = toLocal * (vol.voxelCenter({0, 0, 0}) - pose.position);
    f.dx = toLocal * glm::vec3(s.x, 0, 0);
    f.dy = toLocal * glm::vec3(0, s.y, 0);
    f.dz = toLocal * glm::vec3(0, 0, s.z);
    return f;
}

// Voxels whose centres may lie in the tool-local box [lo, hi] at this pose.
Box3i voxelBox(const Volume& vol, const ToolPose& pose, glm::vec3 lo, glm::vec3 hi) {
    glm::vec3 mn(INFINITY), mx(-INFINITY);
    for (int k = 0; k < 8; ++k) {
        glm::vec3 c((k & 1) ? hi.x : lo.x, (k & 2) ? hi.y : lo.y, (k & 4) ? hi.z : lo.z);
        glm::vec3 v = vol.toVoxel(pose.toObject(c));
        mn = glm::min(mn, v);
        mx = glm::max(mx, v);
    }
    // A little slack for rounding (the per-voxel test is exact); clamp in float before
    // converting, as a tool far outside the volume gives coordinates no int can hold.
    const glm::vec3 limit = glm::vec3(vol.dims()) + 1.0f;
    glm::ivec3 a(glm::clamp(glm::ceil(mn - 0.01f), glm::vec3(-1.0f), limit));
    glm::ivec3 b(glm::clamp(glm::floor(mx + 0.01f), glm::vec3(-1.0f), limit));
    return Box3i{a, b + 1}.intersect(vol.bounds());
}

// Row clips: the interval [t0, t1] of x (in voxels) where the local line a + x dx may lie in a
// simple solid that holds the cutter. Exactness comes from the per-voxel test; a clip only has
// to be tight and never too small. dx is the same for every row, so its terms are set up once.
struct SphereClip {
    SphereClip(glm::vec3 dx, glm::vec3 centre, float radius)
        : dx(dx), centre(centre), r2(radius * radius), invBb(1.0f / glm::dot(dx, dx)) {}
    glm::vec3 dx, centre;
    float r2, invBb;
    bool operator()(glm::vec3 a, float& t0, float& t1) const {
        glm::vec3 ac = a - centre;
        float ab = glm::dot(ac, dx) * invBb;
        float disc = ab * ab - (glm::dot(ac, ac) - r2) * invBb;
        if (disc < 0.0f)
            return false;
        float sq = std::sqrt(disc);
        t0 = -ab - sq;
        t1 = -ab + sq;
        return true;
    }
};

// The capped cylinder rho <= radius, zLo <= z <= zHi about the local z axis.
struct CylinderClip {
    CylinderClip(glm::vec3 dx, float radius, float zLo, float zHi)
        : dx(dx), r2(radius * radius), zLo(zLo), zHi(zHi) {
        slab = std::fabs(dx.z) > 1e-6f;
        invDz = slab ? 1.0f / dx.z : 0.0f;
        float qa = dx.x * dx.x + dx.y * dx.y;
        radial = qa > 1e-10f;
        invQa = radial ? 1.0f / qa : 0.0f;
    }
    glm::vec3 dx;
    float r2, zLo, zHi, invDz, invQa;
    bool slab, radial;
    bool operator()(glm::vec3 a, float& t0, float& t1) const {
        t0 = -INFINITY;
        t1 = INFINITY;
        if (slab) { // linear in x
            float u0 = (zLo - a.z) * invDz, u1 = (zHi - a.z) * invDz;
            t0 = std::min(u0, u1);
            t1 = std::max(u0, u1);
        } else if (a.z < zLo || a.z > zHi) {
            return false;
        }
        float qc = a.x * a.x + a.y * a.y - r2;
        if (radial) { // quadratic in x
            float qb = (a.x * dx.x + a.y * dx.y) * invQa;
            float disc = qb * qb - qc * invQa;
            if (disc < 0.0f)
                return false;
            float sq = std::sqrt(disc);
            t0 = std::max(t0, -qb - sq);
            t1 = std::min(t1, -qb + sq);
        } else if (qc > 0.0f) {
            return false;
        }
        return t0 <= t1;
    }
};

// Calls visit(y, z, rowLocal, x0, x1) for every row of `box` whose clip interval holds voxels,
// with rowLocal the local position of voxel (0, y, z) and [x0, x1] the voxels to test.
template <typename Clip, typename Visit>
void forEachRow(const Frame& f, const Box3i& box, const Clip& clip, Visit&& visit) {
    if (box.empty())
        return;
    for (int z = box.lo.z; z < box.hi.z; ++z)
        for (int y = box.lo.y; y < box.hi.y; ++y) {
            glm::vec3 a = f.origin + float(y) * f.dy + float(z) * f.dz;
            float t0, t1;
            if (!clip(a, t0, t1))
                continue;
            // Slack of a hundredth of a voxel for rounding; clamp before converting to int.
            float lo = std::max(float(box.lo.x), std::ceil(t0 - 0.01f));
            float hi = std::min(float(box.hi.x - 1), std::floor(t1 + 0.01f));
            if (lo <= hi)
                visit(y, z, a, int(lo), int(hi));
        }
}

struct BurrInside {
    float r2;
    bool operator()(glm::vec3 l) const { return glm::dot(l, l) <= r2; }
};

// Same solid as ToolShape::signedDistance(l) <= 0, without the square root.
struct PerforatorInside {
    float r2, t2, h;
    bool operator()(glm::vec3 l) const {
        float rho2 = l.x * l.x + l.y * l.y;
        return l.z >= 0.0f && l.z <= h && rho2 <= r2 && rho2 * t2 <= l.z * l.z * r2;
    }
};

// Whether l lies within `margin` of the perforator (ToolShape::signedDistance(l) <= margin),
// with cheap rejections first: the exact distance needs a square root and three segment
// distances, and most voxels around the cutter are far from it.
struct PerforatorNear {
    const ToolShape* shape;
    float r, t, h, margin, coneLen;
    bool operator()(glm::vec3 l) const {
        if (l.z < -margin || l.z > h + margin)
            return false;
        float rho2 = l.x * l.x + l.y * l.y;
        float rm = r + margin;
        if (rho2 > rm * rm)
            return false;
        // Beyond the cone face offset by the margin: rho t - z r > margin |(t, -r)|.
        float rhs = l.z * r + margin * coneLen;
        if (rhs < 0.0f || rho2 * t * t > rhs * rhs)
            return false;
        return shape->signedDistance(l) <= margin;
    }
};

// [SECTION] Passes

struct Nearby {
    bool bone = false;
    bool dura = false;
};

// What lies within `margin` of the perforator: live bone, dura or brain.
Nearby scanNearby(const Volume& vol, const Frame& f, const Box3i& box, const ToolShape& shape,
                  float margin) {
    const float r = 0.5f * shape.diameterMm, t = shape.tipLengthMm;
    const PerforatorNear near{
        &shape, r, t, t + shape.cutLengthMm, margin, std::sqrt(r * r + t * t)};
    Nearby found;
    const uint8_t* den = vol.densityData();
    const uint8_t* mat = vol.materialData();
    const glm::ivec3 dims = vol.dims();
    const CylinderClip clip(f.dx, r + margin, -margin, near.h + margin);
    forEachRow(f, box, clip, [&](int y, int z, glm::vec3 a, int x0, int x1) {
        if (found.bone && found.dura)
            return;
        size_t base = size_t(dims.x) * (size_t(y) + size_t(dims.y) * size_t(z));
        const uint8_t* drow = den + base;
        const uint8_t* mrow = mat + base;
        if (found.bone) {
            // Only soft tissue is still of interest: skip rows without any, in one cheap
            // (vectorisable) sweep over the labels.
            bool any = false;
            for (int x = x0; x <= x1; ++x)
                any |= mrow[x] >= uint8_t(Material::Dura);
            if (!any)
                return;
        }
        for (int x = x0; x <= x1; ++x) {
            Material m = Material(mrow[x]);
            bool isDura = isSoftTissue(m);
            bool isLiveBone = isBone(m) && drow[x] > 0;
            if (!(isDura && !found.dura) && !(isLiveBone && !found.bone))
                continue;
            if (near(a + float(x) * f.dx)) {
                found.dura |= isDura;
                found.bone |= isLiveBone;
            }
        }
    });
    return found;
}

// Whether live bone lies on the axis within `length` ahead of the perforator's apex.
bool boneAheadOfTip(const Volume& vol, const ToolPose& pose, float length) {
    glm::vec3 s = vol.spacing();
    float step = 0.5f * std::min({s.x, s.y, s.z});
    glm::vec3 ahead = -pose.axis();
    for (float t = 0.0f; t <= length + 1e-4f; t += step) {
        // Clamp in float before converting (a tool far outside gives coordinates no int holds);
        // -1 and dims are outside, as they should be.
        glm::ivec3 v(glm::clamp(glm::round(vol.toVoxel(pose.position + t * ahead)),
                                glm::vec3(-1.0f), glm::vec3(vol.dims())));
        if (!vol.inside(v))
            continue;
        size_t i = vol.index(v);
        if (isBone(Material(vol.materialData()[i])) && vol.densityData()[i] > 0)
            return true;
    }
    return false;
}

// Visits every voxel centre inside the cutter: counts it, reports dura and brain, and (when
// `decrement` > 0) erodes bone, tracking the tight box of changes.
template <typename Clip, typename Inside>
void erodePass(Volume& vol, const Frame& f, const Box3i& box, const Clip& clip, Inside inside,
               int decrement, DrillResult& res) {
    uint8_t* den = vol.densityData();
    uint8_t* mat = vol.materialData();
    const glm::ivec3 dims = vol.dims();
    glm::ivec3 lo(INT_MAX), hi(INT_MIN);
    int64_t touched = 0, dura = 0, changed = 0, removed = 0, zeroed = 0;
    forEachRow(f, box, clip, [&](int y, int z, glm::vec3 a, int x0, int x1) {
        size_t base = size_t(dims.x) * (size_t(y) + size_t(dims.y) * size_t(z));
        uint8_t* drow = den + base;
        uint8_t* mrow = mat + base;
        // The cutter is convex, so the voxels of a row inside it are one run: trim the clip's
        // interval from both ends with the exact test and walk the run with no test at all.
        while (x0 <= x1 && !inside(a + float(x0) * f.dx))
            ++x0;
        while (x1 >= x0 && !inside(a + float(x1) * f.dx))
            --x1;
        if (x0 > x1)
            return;
        touched += x1 - x0 + 1;
        int rowLo = INT_MAX, rowHi = INT_MIN;
        for (int x = x0; x <= x1; ++x) {
            uint8_t m = mrow[x];
            int dec;
            if (m == uint8_t(Material::Cortical))
                dec = decrement;
            else if (m == uint8_t(Material::Diploe))
                dec = decrement * kDiploeErosionFactor;
            else {
                if (isSoftTissue(Material(m))) {
                    ++dura;
                    ++res.contactBy[m];
                }
                continue;
            }
            if (dec == 0)
                continue;
            int d = drow[x];
            int nd = std::max(0, d - dec);
            drow[x] = uint8_t(nd);
            removed += d - nd;
            if (nd == 0) {
                mrow[x] = uint8_t(Material::Air);
                ++zeroed;
                ++res.removedBy[m];
            }
            ++changed;
            rowLo = std::min(rowLo, x);
            rowHi = std::max(rowHi, x);
        }
        if (rowLo <= rowHi) {
            lo = glm::min(lo, glm::ivec3(rowLo, y, z));
            hi = glm::max(hi, glm::ivec3(rowHi + 1, y + 1, z + 1));
        }
    });
    res.voxelsTouched += touched;
    res.duraVoxels += dura;
    res.duraContact = res.duraVoxels > 0;
    res.voxelsChanged += changed;
    res.densityRemoved += removed;
    res.voxelsRemoved += zeroed;
    if (changed > 0)
        res.changed.merge(Box3i{lo, hi});
}

} // namespace

// [SECTION] Driller

namespace {

// `raw` with a unit rotation, or nullopt for a pose that touches nothing (not finite, a zero
// quaternion: poses come from clients). The unit rotation is used everywhere (frame, voxel boxes,
// the clutch's axis): a quaternion off unit length rotates and scales, which squashed the voxel
// boxes while the frame cut at full size.
std::optional<ToolPose> usablePose(const Volume& volume, const ToolPose& raw) {
    const glm::quat& q = raw.orientation;
    const glm::vec3& p = raw.position;
    const float qq = q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w;
    if (volume.empty() || !std::isfinite(p.x + p.y + p.z) || !std::isfinite(qq) || qq < 1e-12f)
        return std::nullopt;
    return ToolPose{p, glm::normalize(q)};
}

// Bone and dura within the clutch's margin of the perforator at `pose`.
Nearby perforatorNearby(const Volume& volume, const ToolPose& pose, const Frame& frame,
                        const ToolShape& shape) {
    const float margin = perforatorClutchMarginMm(volume.spacing());
    const float r = 0.5f * shape.diameterMm;
    const float top = shape.tipLengthMm + shape.cutLengthMm;
    Box3i near = voxelBox(volume, pose, glm::vec3(-r - margin, -r - margin, -margin),
                          glm::vec3(r + margin, r + margin, top + margin));
    return scanNearby(volume, frame, near, shape, margin);
}

} // namespace

void Driller::observe(const Volume& volume, const ToolPose& rawPose) {
    if (!toolType(m_shape.kind).clutch || !m_clutchDisengaged)
        return;
    if (const std::optional<ToolPose> pose = usablePose(volume, rawPose)) {
        if (!perforatorNearby(volume, *pose, makeFrame(volume, *pose), m_shape).bone)
            m_clutchDisengaged = m_tipInBone = false; // lifted clear of bone
    }
}

DrillResult Driller::drill(Volume& volume, const ToolPose& rawPose, float speed, float dt) {
    assert(dt >= 0.0f && "Driller::drill: dt is a duration in seconds and must not be negative");
    DrillResult res;
    const std::optional<ToolPose> usable = usablePose(volume, rawPose);
    if (!usable)
        return res;
    const ToolPose& pose = *usable;
    speed = speed > 0.0f ? std::min(speed, 1.0f) : 0.0f; // also maps NaN to 0
    const Frame frame = makeFrame(volume, pose);
    const bool clutch = toolType(m_shape.kind).clutch;
    const float r = 0.5f * m_shape.diameterMm;
    const float top = m_shape.tipLengthMm + m_shape.cutLengthMm;

    if (clutch) {
        const float margin = perforatorClutchMarginMm(volume.spacing());
        const Nearby around = perforatorNearby(volume, pose, frame, m_shape);
        if (m_clutchDisengaged && !around.bone)
            m_clutchDisengaged = m_tipInBone = false; // lifted clear of bone
        if (!m_clutchDisengaged) {
            const float minSpacing =
                std::min({volume.spacing().x, volume.spacing().y, volume.spacing().z});
            bool ahead = boneAheadOfTip(volume, pose, margin + minSpacing);
            // How deep the apex is along the tool's axis. Rule (b) holds only at or beyond the
            // deepest point where the tip had bone ahead: lifted back up its own hole (a peck) the
            // tip has air ahead and bone around, and the clutch stopped it ~2 mm short for good.
            const float depth = -glm::dot(pose.position, pose.axis());
            const bool advancing = !m_tipInBone || depth >= m_deepestMm - 0.5f * minSpacing;
            if (around.dura || (m_tipInBone && !ahead && around.bone && advancing))
                m_clutchDisengaged = true;
            else if (ahead) {
                m_deepestMm = m_tipInBone ? std::max(m_deepestMm, depth) : depth;
                m_tipInBone = true;
            }
        }
        res.clutchDisengaged = m_clutchDisengaged;
    }

    // Whole density units this step; the fraction carries over so that many small steps erode
    // like one long one. The epsilon absorbs float rounding of dt and speed (0.01f x 1700 is
    // 16.9999996), so 10 x 1 ms and 1 x 10 ms floor alike.
    int decrement = 0;
    if (speed > 0.0f && dt > 0.0f && !(clutch && m_clutchDisengaged)) {
        double budget = m_carry + erosionRate(m_shape.kind) * double(speed) * double(dt);
        double whole = std::floor(budget + kCarryEpsilon);
        m_carry = std::max(0.0, budget - whole);
        decrement = int(std::min(whole, 255.0)); // 255 clears any voxel in one step
    }

    if (!m_shape.sphere()) {
        Box3i box = voxelBox(volume, pose, glm::vec3(-r, -r, 0.0f), glm::vec3(r, r, top));
        float t = m_shape.tipLengthMm;
        erodePass(volume, frame, box, CylinderClip(frame.dx, r, 0.0f, top),
                  PerforatorInside{r * r, t * t, top}, decrement, res);
    } else {
        Box3i box = voxelBox(volume, pose, glm::vec3(-r), glm::vec3(r));
        erodePass(volume, frame, box, SphereClip(frame.dx, glm::vec3(0.0f), r), BurrInside{r * r},
                  decrement, res);
    }
    return res;
}

std::vector<ToolPose> sweepPoses(const ToolPose& from, const ToolPose& to, float maxStepMm,
                                 float maxSweepMm) {
    const float distance = glm::length(to.position - from.position);
    if (!std::isfinite(distance) || !(maxStepMm > 0.0f) || distance <= maxStepMm ||
        distance > maxSweepMm)
        return {to};
    // Capped in float before converting: a tiny step gives a ratio no int holds.
    const int steps = int(std::min(float(kMaxSweepSteps), std::ceil(distance / maxStepMm)));
    std::vector<ToolPose> poses;
    poses.reserve(size_t(steps));
    for (int i = 1; i < steps; ++i) {
        const float a = float(i) / float(steps);
        poses.push_back({glm::mix(from.position, to.position, a),
                         glm::slerp(from.orientation, to.orientation, a)});
    }
    poses.push_back(to); // exactly the sampled pose
    return poses;
}

} // namespace trephine

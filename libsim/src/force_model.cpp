#include "libsim/force_model.h"

#include <cmath>
#include <glm/gtc/quaternion.hpp>
#include <glm/mat3x3.hpp>
#include <numbers>

namespace trephine {

namespace {

constexpr double kPi = std::numbers::pi;

float autoSpacing(const ToolShape& shape) {
    // About 12 points across a burr's diameter; the perforator is coarser per mm but has more
    // area. Both stay well under a voxel of the 256^3 skull (0.78 mm).
    if (shape.sphere())
        return std::clamp(shape.diameterMm / 12.0f, 0.08f, 0.5f);
    return std::clamp(shape.diameterMm / 16.0f, 0.2f, 1.0f);
}

// Trilinear density and its derivative with respect to the continuous voxel coordinate c. Voxels
// outside the volume read as air. Returns false (and leaves d, g alone) when all eight corners are
// below the surface density: such a point cannot be in contact.
bool sampleDensity(const Volume& v, glm::vec3 c, double& d, glm::dvec3& g) {
    const glm::ivec3 dims = v.dims();
    const glm::vec3 fl = glm::floor(c);
    const int x0 = int(fl.x), y0 = int(fl.y), z0 = int(fl.z);
    const double fx = c.x - fl.x, fy = c.y - fl.y, fz = c.z - fl.z;
    double q[8];
    const uint8_t* data = v.densityData();
    if (x0 >= 0 && y0 >= 0 && z0 >= 0 && x0 + 1 < dims.x && y0 + 1 < dims.y && z0 + 1 < dims.z) {
        const size_t sy = size_t(dims.x), sz = size_t(dims.x) * size_t(dims.y);
        const uint8_t* p = data + size_t(x0) + sy * size_t(y0) + sz * size_t(z0);
        q[0] = p[0], q[1] = p[1], q[2] = p[sy], q[3] = p[sy + 1];
        q[4] = p[sz], q[5] = p[sz + 1], q[6] = p[sz + sy], q[7] = p[sz + sy + 1];
    } else {
        if (x0 + 1 < 0 || y0 + 1 < 0 || z0 + 1 < 0 || x0 >= dims.x || y0 >= dims.y || z0 >= dims.z)
            return false;
        for (int k = 0; k < 8; ++k) {
            glm::ivec3 vi(x0 + (k & 1), y0 + ((k >> 1) & 1), z0 + ((k >> 2) & 1));
            q[k] = v.inside(vi) ? double(v.density(vi.x, vi.y, vi.z)) : 0.0;
        }
    }
    double mx = q[0];
    for (int k = 1; k < 8; ++k)
        mx = std::max(mx, q[k]);
    if (mx <= double(kSurfaceDensity))
        return false;
    // Interpolate along x, then y, then z, keeping the partial derivatives.
    const double a00 = q[0] + fx * (q[1] - q[0]), a10 = q[2] + fx * (q[3] - q[2]);
    const double a01 = q[4] + fx * (q[5] - q[4]), a11 = q[6] + fx * (q[7] - q[6]);
    const double b0 = a00 + fy * (a10 - a00), b1 = a01 + fy * (a11 - a01);
    d = b0 + fz * (b1 - b0);
    const double dx00 = q[1] - q[0], dx10 = q[3] - q[2], dx01 = q[5] - q[4], dx11 = q[7] - q[6];
    const double dx0 = dx00 + fy * (dx10 - dx00), dx1 = dx01 + fy * (dx11 - dx01);
    g.x = dx0 + fz * (dx1 - dx0);
    g.y = (a10 - a00) + fz * ((a11 - a01) - (a10 - a00));
    g.z = b1 - b0;
    return true;
}

void addRing(std::vector<ShellPoint>& out, float rho, float z, glm::vec2 normalRhoZ, float area,
             float spacing, float crossSection) {
    int n = std::max(3, int(std::ceil(2.0 * kPi * rho / spacing)));
    for (int i = 0; i < n; ++i) {
        double a = 2.0 * kPi * (i + 0.5 * (int(z / spacing) & 1)) / n;
        glm::vec3 radial(float(std::cos(a)), float(std::sin(a)), 0.0f);
        ShellPoint p;
        p.position = radial * rho + glm::vec3(0, 0, z);
        p.normal = glm::normalize(radial * normalRhoZ.x + glm::vec3(0, 0, normalRhoZ.y));
        p.weight = area / float(n) / crossSection;
        out.push_back(p);
    }
}

} // namespace

std::vector<ShellPoint> makeShell(const ToolShape& shape, float pointSpacingMm) {
    shape.validate();
    const float h = pointSpacingMm > 0.0f ? pointSpacingMm : autoSpacing(shape);
    const float r = 0.5f * shape.diameterMm;
    const float crossSection = float(kPi) * r * r;
    std::vector<ShellPoint> out;
    if (shape.sphere()) {
        // A Fibonacci sphere: near-uniform points, equal areas.
        const double area = 4.0 * kPi * r * r;
        const int n = std::max(32, int(std::ceil(area / (h * h))));
        const double golden = kPi * (3.0 - std::sqrt(5.0));
        out.reserve(size_t(n));
        for (int i = 0; i < n; ++i) {
            double z = 1.0 - 2.0 * (i + 0.5) / n;
            double rho = std::sqrt(std::max(0.0, 1.0 - z * z));
            double a = golden * i;
            glm::vec3 nrm(float(rho * std::cos(a)), float(rho * std::sin(a)), float(z));
            out.push_back({nrm * r, nrm, float(area / n) / crossSection});
        }
        return out;
    }
    // Perforator: rings over the conical tip (apex at the origin, shoulder at (r, t)) and the
    // cutting cylinder above it. The flat top joins the shaft and never meets bone first.
    const float t = shape.tipLengthMm, top = shape.tipLengthMm + shape.cutLengthMm;
    const float slant = std::sqrt(r * r + t * t);
    const glm::vec2 coneNormal = glm::vec2(t, -r) / slant;
    const int coneRings = std::max(1, int(std::ceil(slant / h)));
    const float ds = slant / float(coneRings);
    for (int j = 0; j < coneRings; ++j) {
        float s = (j + 0.5f) * ds;
        float rho = r * s / slant, z = t * s / slant;
        addRing(out, rho, z, coneNormal, float(2.0 * kPi) * rho * ds, h, crossSection);
    }
    const int cylRings = std::max(1, int(std::ceil((top - t) / h)));
    const float dz = (top - t) / float(cylRings);
    for (int j = 0; j < cylRings; ++j) {
        float z = t + (j + 0.5f) * dz;
        addRing(out, r, z, glm::vec2(1.0f, 0.0f), float(2.0 * kPi) * r * dz, h, crossSection);
    }
    return out;
}

ForceModel::ForceModel(const ToolShape& shape, ForceModelConfig config)
    : m_shape(shape), m_config(config), m_shell(makeShell(shape, config.pointSpacingMm)) {}

ForceResult ForceModel::compute(const Volume& volume, const ToolPose& pose, float speed,
                                glm::vec3 velocityMmPerS) const {
    ForceResult out;
    if (volume.empty())
        return out;
    const glm::mat3 rot = glm::mat3_cast(pose.orientation);
    const glm::vec3 spacing = volume.spacing();
    const glm::vec3 toVoxelScale = 1.0f / spacing;
    const glm::vec3 toVoxelOffset = glm::vec3(volume.dims()) * 0.5f - 0.5f;
    const double scale = penetrationScaleMm(volume);
    const glm::dvec3 gradScale = glm::dvec3(scale) / glm::dvec3(spacing);
    const double k = m_config.stiffnessNPerMm;

    glm::dvec3 f(0.0);
    glm::dmat3 jac(0.0);
    for (const ShellPoint& sp : m_shell) {
        const glm::vec3 p = rot * sp.position + pose.position;
        double d;
        glm::dvec3 g;
        if (!sampleDensity(volume, p * toVoxelScale + toVoxelOffset, d, g))
            continue;
        if (d <= double(kSurfaceDensity))
            continue;
        // Penalty: the point is pushed back along its inward normal by its penetration.
        const double depth = (d - double(kSurfaceDensity)) * scale;
        const glm::dvec3 gradDepth = g * gradScale;
        const glm::dvec3 n = glm::dvec3(rot * sp.normal);
        const double kw = k * double(sp.weight);
        f -= kw * depth * n;
        jac -= glm::outerProduct(kw * n, gradDepth); // jac[b][a] = d f_a / d p_b
        out.contactPoints++;
    }
    out.contact = out.contactPoints > 0;
    if (!out.contact)
        return out;

    // The cutter resists being fed into the bone, not being withdrawn: only an axial motion
    // against the contact force is resisted. Resisting a withdrawal too would pull the tool
    // towards the bone, past the contact force near separation, reversing the direction the
    // client's one-way extrapolation protects (1-2 N inwards on a fast pull-out).
    if (speed > 0.0f && m_config.drillDampingNsPerMm > 0.0f) {
        const glm::dvec3 axis = glm::dvec3(pose.axis());
        const double axial = glm::dot(glm::dvec3(velocityMmPerS), axis);
        if (axial * glm::dot(f, axis) < 0.0) {
            const double frac = double(out.contactPoints) / double(m_shell.size());
            const double c =
                double(m_config.drillDampingNsPerMm) * std::min(1.0, double(speed)) * frac;
            f -= c * axial * axis;
        }
    }

    const double mag = glm::length(f), fmax = m_config.maxForceN;
    if (mag > fmax && mag > 0.0) {
        // d(fmax f/|f|) = fmax/|f| (I - u u^T) df: the clamped field's exact derivative.
        const glm::dvec3 u = f / mag;
        const glm::dmat3 proj = glm::dmat3(1.0) - glm::outerProduct(u, u);
        jac = (fmax / mag) * proj * jac;
        f = u * fmax;
        out.clamped = true;
    }
    out.force = glm::vec3(f);
    out.jacobian = glm::mat3(jac);
    out.gradient = glm::mat3(0.5 * (jac + glm::transpose(jac)));
    return out;
}

glm::vec3 VelocityEstimate::update(glm::vec3 position, double timeS) {
    if (!std::isfinite(position.x + position.y + position.z) || !std::isfinite(timeS))
        return glm::vec3(0.0f);
    if (m_have && !(timeS > m_lastS))
        return glm::vec3(0.0f);
    const bool had = m_have;
    const glm::vec3 last = m_last;
    const double dt = timeS - m_lastS;
    m_have = true;
    m_last = position;
    m_lastS = timeS;
    if (!had || dt > kMaxGapS)
        return glm::vec3(0.0f);
    const glm::vec3 v = (position - last) / float(dt);
    return glm::length(v) <= kMaxMmPerS ? v : glm::vec3(0.0f);
}

const ForceModel& ForceModelCache::get(const ToolShape& shape) {
    for (auto it = m_models.begin(); it != m_models.end(); ++it) {
        const ToolShape& s = (*it)->shape();
        if (s.kind == shape.kind && s.diameterMm == shape.diameterMm &&
            s.tipLengthMm == shape.tipLengthMm && s.cutLengthMm == shape.cutLengthMm) {
            std::rotate(m_models.begin(), it, it + 1); // to the front: most recently used
            return *m_models.front();
        }
    }
    auto model = std::make_unique<ForceModel>(shape, m_config); // validates first
    if (m_models.size() >= m_capacity)
        m_models.pop_back();
    m_models.insert(m_models.begin(), std::move(model));
    return *m_models.front();
}

} // namespace trephine

// The simulated force device: a hand of given mass held by a spring-damper to a scripted intent,
// feeling the forces it is sent, integrated between reads in steps of at most 0.1 ms. The same
// physics as the haptics study's HandModel (study/haptics_study.h). Built as a plugin of the
// device ABI, so tests and demos drive the same path a real device takes.
//
// Args (comma-separated key=value): mass (kg, 0.15), k (N/mm, 1), c (N s/mm, 0.005),
// maxforce (N, 8.5), half (workspace half-width, mm, 150).
#include "libsim_devices/trephine_device_abi.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>

namespace {

struct Vec {
    double x = 0, y = 0, z = 0;
    Vec operator+(Vec o) const { return {x + o.x, y + o.y, z + o.z}; }
    Vec operator-(Vec o) const { return {x - o.x, y - o.y, z - o.z}; }
    Vec operator*(double s) const { return {x * s, y * s, z * s}; }
    double norm() const { return std::sqrt(x * x + y * y + z * z); }
};

constexpr double kMaxStepS = 1e-4;
constexpr double kMaxGapS = 0.05; // a longer gap between reads integrates this much only

} // namespace

struct TrephineDevice {
    double massKg = 0.15, stiffnessNPerMm = 1.0, dampingNsPerMm = 0.005, maxForceN = 8.5;
    double halfMm = 150.0;
    Vec x, v, target, force;
    double orientation[4] = {1, 0, 0, 0};
    bool placed = false; // the first intent places the hand there, at rest
    double lastNow = 0.0;
    bool ticked = false;
    std::string error;
};

namespace {

// Parses "key=value,..." into d; false (with error) on an unknown key or a bad number.
bool parseArgs(TrephineDevice& d, const char* args, char* error, size_t size) {
    std::string s = args ? args : "";
    size_t at = 0;
    while (at < s.size()) {
        size_t end = s.find(',', at);
        if (end == std::string::npos)
            end = s.size();
        const std::string item = s.substr(at, end - at);
        at = end + 1;
        if (item.empty())
            continue;
        const size_t eq = item.find('=');
        const std::string key = item.substr(0, eq);
        const char* text = eq == std::string::npos ? "" : item.c_str() + eq + 1;
        char* rest = nullptr;
        const double value = std::strtod(text, &rest);
        double* slot = key == "mass"       ? &d.massKg
                       : key == "k"        ? &d.stiffnessNPerMm
                       : key == "c"        ? &d.dampingNsPerMm
                       : key == "maxforce" ? &d.maxForceN
                       : key == "half"     ? &d.halfMm
                                           : nullptr;
        if (!slot) {
            std::snprintf(error, size, "unknown argument '%s' (mass, k, c, maxforce, half)",
                          key.c_str());
            return false;
        }
        if (!*text || *rest || !std::isfinite(value) || value < 0.0 ||
            (slot == &d.massKg && value <= 0.0)) {
            std::snprintf(error, size, "argument %s needs a non-negative number, got '%s'",
                          key.c_str(), text);
            return false;
        }
        *slot = value;
    }
    return true;
}

TrephineDevice* simOpen(const char* args, char* error, size_t size) {
    auto* d = new TrephineDevice;
    if (!parseArgs(*d, args, error, size)) {
        delete d;
        return nullptr;
    }
    return d;
}

void simClose(TrephineDevice* d) {
    delete d;
}

int simInfo(TrephineDevice* d, TrephineDeviceInfo* out) {
    std::memset(out, 0, sizeof *out);
    std::snprintf(out->name, sizeof out->name, "simulated hand %.2f kg", d->massKg);
    for (int i = 0; i < 3; ++i) {
        out->workspace_min_mm[i] = -d->halfMm;
        out->workspace_max_mm[i] = d->halfMm;
    }
    out->max_force_n = d->maxForceN;
    return TREPHINE_DEVICE_OK;
}

// Semi-implicit Euler from the last read to now: m a = k (target - x) - c v + F.
void advance(TrephineDevice& d, double now) {
    double gap = d.ticked ? std::clamp(now - d.lastNow, 0.0, kMaxGapS) : 0.0;
    d.lastNow = now;
    d.ticked = true;
    const int steps = int(std::ceil(gap / kMaxStepS));
    const double h = steps ? gap / steps : 0.0;
    for (int i = 0; i < steps; ++i) {
        const Vec fHand = (d.target - d.x) * d.stiffnessNPerMm - d.v * d.dampingNsPerMm;
        const Vec acc = (fHand + d.force) * (1000.0 / d.massKg); // mm/s^2
        d.v = d.v + acc * h;
        d.x = d.x + d.v * h;
    }
}

int simRead(TrephineDevice* d, double now, TrephineDevicePose* out) {
    if (!std::isfinite(now)) {
        d->error = "read at a time that is not finite";
        return 1;
    }
    advance(*d, now);
    out->position_mm[0] = d->x.x;
    out->position_mm[1] = d->x.y;
    out->position_mm[2] = d->x.z;
    std::memcpy(out->orientation, d->orientation, sizeof d->orientation);
    out->buttons = 0;
    return TREPHINE_DEVICE_OK;
}

int simWriteForce(TrephineDevice* d, const double f[3]) {
    Vec force{f[0], f[1], f[2]};
    if (!std::isfinite(force.norm())) {
        d->error = "force is not finite";
        return 2;
    }
    // Like a real device, the motors saturate at the maximum force.
    const double n = force.norm();
    d->force = n > d->maxForceN ? force * (d->maxForceN / n) : force;
    return TREPHINE_DEVICE_OK;
}

int simAppliedForce(TrephineDevice* d, double f[3]) {
    f[0] = d->force.x;
    f[1] = d->force.y;
    f[2] = d->force.z;
    return TREPHINE_DEVICE_OK;
}

int simSetIntent(TrephineDevice* d, const TrephineDevicePose* p) {
    d->target = {p->position_mm[0], p->position_mm[1], p->position_mm[2]};
    std::memcpy(d->orientation, p->orientation, sizeof d->orientation);
    if (!d->placed) {
        d->x = d->target;
        d->v = {};
        d->placed = true;
    }
    return TREPHINE_DEVICE_OK;
}

const char* simLastError(TrephineDevice* d) {
    return d->error.c_str();
}

const TrephineDeviceApi kApi = {
    TREPHINE_DEVICE_ABI_VERSION,
    sizeof(TrephineDeviceApi),
    simOpen,
    simClose,
    simInfo,
    simRead,
    simWriteForce,
    simAppliedForce,
    simSetIntent,
    simLastError,
};

} // namespace

extern "C" TREPHINE_DEVICE_EXPORT const TrephineDeviceApi* trephine_device_api(uint32_t version) {
    return version == TREPHINE_DEVICE_ABI_VERSION ? &kApi : nullptr;
}

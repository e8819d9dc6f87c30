// Force Dimension's dhd (omega, sigma, delta, Novint Falcon through the FD SDK) wrapped in the
// Trephine device ABI. Built only where the SDK is installed (plugins/CMakeLists.txt). dhd calls
// talk to the device directly (USB), so read and write_force call it; dhd works in metres, the ABI
// in millimetres. Args: maxforce=N, used when the SDK reports no force limit (default 12).
#include "libsim_devices/trephine_device_abi.h"

#include <dhdc.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>

struct TrephineDevice {
    char id = -1;
    double maxForce = 12.0;
    std::string error;
};

namespace {

int fail(TrephineDevice* d, const char* what) {
    d->error = std::string(what) + ": " + dhdErrorGetLastStr();
    return 1;
}

TrephineDevice* fdOpen(const char* args, char* error, size_t size) {
    double maxForce = 12.0;
    if (args && *args && std::sscanf(args, "maxforce=%lf", &maxForce) != 1) {
        std::snprintf(error, size, "the dhd plugin takes maxforce=N only, got '%s'", args);
        return nullptr;
    }
    const int id = dhdOpen();
    if (id < 0) {
        std::snprintf(error, size, "dhdOpen: %s", dhdErrorGetLastStr());
        return nullptr;
    }
    auto* d = new TrephineDevice;
    d->id = char(id);
    const double limit = dhdGetMaxForce(d->id);
    d->maxForce = limit > 0.0 ? limit : maxForce;
    if (dhdEnableForce(DHD_ON, d->id) < 0) {
        std::snprintf(error, size, "dhdEnableForce: %s", dhdErrorGetLastStr());
        dhdClose(d->id);
        delete d;
        return nullptr;
    }
    return d;
}

void fdClose(TrephineDevice* d) {
    dhdSetForce(0.0, 0.0, 0.0, d->id);
    dhdEnableForce(DHD_OFF, d->id);
    dhdClose(d->id);
    delete d;
}

int fdInfo(TrephineDevice* d, TrephineDeviceInfo* out) {
    std::memset(out, 0, sizeof *out);
    const char* name = dhdGetSystemName(d->id);
    std::snprintf(out->name, sizeof out->name, "%s", name ? name : "Force Dimension device");
    // dhd does not report a workspace; a delta/omega reaches about +-80 mm around its centre.
    for (int i = 0; i < 3; ++i) {
        out->workspace_min_mm[i] = -80.0;
        out->workspace_max_mm[i] = 80.0;
    }
    out->max_force_n = d->maxForce;
    return TREPHINE_DEVICE_OK;
}

void toQuaternion(const double r[3][3], double q[4]) {
    const double t = r[0][0] + r[1][1] + r[2][2];
    if (t > 0) {
        const double s = 2.0 * std::sqrt(1.0 + t);
        q[0] = s / 4, q[1] = (r[2][1] - r[1][2]) / s, q[2] = (r[0][2] - r[2][0]) / s,
        q[3] = (r[1][0] - r[0][1]) / s;
    } else if (r[0][0] > r[1][1] && r[0][0] > r[2][2]) {
        const double s = 2.0 * std::sqrt(1.0 + r[0][0] - r[1][1] - r[2][2]);
        q[0] = (r[2][1] - r[1][2]) / s, q[1] = s / 4, q[2] = (r[0][1] + r[1][0]) / s,
        q[3] = (r[0][2] + r[2][0]) / s;
    } else if (r[1][1] > r[2][2]) {
        const double s = 2.0 * std::sqrt(1.0 + r[1][1] - r[0][0] - r[2][2]);
        q[0] = (r[0][2] - r[2][0]) / s, q[1] = (r[0][1] + r[1][0]) / s, q[2] = s / 4,
        q[3] = (r[1][2] + r[2][1]) / s;
    } else {
        const double s = 2.0 * std::sqrt(1.0 + r[2][2] - r[0][0] - r[1][1]);
        q[0] = (r[1][0] - r[0][1]) / s, q[1] = (r[0][2] + r[2][0]) / s,
        q[2] = (r[1][2] + r[2][1]) / s, q[3] = s / 4;
    }
}

int fdRead(TrephineDevice* d, double, TrephineDevicePose* out) {
    double x, y, z;
    // A positive status (DHD_TIMEGUARD, DHD_MOTOR_SATURATED) is a warning, not a failure.
    if (dhdGetPosition(&x, &y, &z, d->id) < 0)
        return fail(d, "dhdGetPosition");
    double r[3][3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
    if (dhdHasWrist(d->id) && dhdGetOrientationFrame(r, d->id) < 0)
        return fail(d, "dhdGetOrientationFrame");
    out->position_mm[0] = x * 1000.0;
    out->position_mm[1] = y * 1000.0;
    out->position_mm[2] = z * 1000.0;
    toQuaternion(r, out->orientation);
    out->buttons = uint32_t(dhdGetButtonMask(d->id));
    return TREPHINE_DEVICE_OK;
}

int fdWriteForce(TrephineDevice* d, const double f[3]) {
    if (dhdSetForce(f[0], f[1], f[2], d->id) < 0)
        return fail(d, "dhdSetForce");
    return TREPHINE_DEVICE_OK;
}

int fdAppliedForce(TrephineDevice* d, double f[3]) {
    if (dhdGetForce(&f[0], &f[1], &f[2], d->id) < 0)
        return fail(d, "dhdGetForce");
    return TREPHINE_DEVICE_OK;
}

const char* fdLastError(TrephineDevice* d) {
    return d->error.c_str();
}

const TrephineDeviceApi kApi = {
    TREPHINE_DEVICE_ABI_VERSION,
    sizeof(TrephineDeviceApi),
    fdOpen,
    fdClose,
    fdInfo,
    fdRead,
    fdWriteForce,
    fdAppliedForce,
    nullptr,
    fdLastError,
};

} // namespace

extern "C" TREPHINE_DEVICE_EXPORT const TrephineDeviceApi* trephine_device_api(uint32_t version) {
    return version == TREPHINE_DEVICE_ABI_VERSION ? &kApi : nullptr;
}

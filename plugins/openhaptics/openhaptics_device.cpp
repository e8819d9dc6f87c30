// OpenHaptics' HD API (3D Systems Touch, Phantom Premium) wrapped in the Trephine device ABI.
// Built only where the SDK is installed (plugins/CMakeLists.txt). HD runs its own servo thread:
// an asynchronous callback there copies the device's state out and the newest force in, under a
// mutex, so read and write_force never wait for a servo tick. Poses are in HD's frame (mm, y up,
// z towards the user), as the device reports them. Args: none.
#include "libsim_devices/trephine_device_abi.h"

#include <HD/hd.h>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <mutex>
#include <string>

struct TrephineDevice {
    HHD handle = HD_INVALID_HANDLE;
    HDSchedulerHandle servo = 0;
    std::mutex mutex;
    HDdouble transform[16] = {}; // the servo thread's newest, column-major, mm
    HDint buttons = 0;
    HDdouble force[3] = {0, 0, 0};   // the host's newest
    HDdouble applied[3] = {0, 0, 0}; // what the servo thread last sent
    bool servoError = false;
    HDdouble workspace[6] = {};
    HDdouble maxForce = 0;
    std::string error;
};

namespace {

std::string describe(const HDErrorInfo& e, const char* what) {
    return std::string(what) + ": " + hdGetErrorString(e.errorCode);
}

HDCallbackCode HDCALLBACK servoTick(void* data) {
    TrephineDevice& d = *static_cast<TrephineDevice*>(data);
    hdBeginFrame(d.handle);
    HDdouble transform[16];
    HDint buttons = 0;
    hdGetDoublev(HD_CURRENT_TRANSFORM, transform);
    hdGetIntegerv(HD_CURRENT_BUTTONS, &buttons);
    HDdouble force[3];
    {
        std::lock_guard lock(d.mutex);
        std::memcpy(d.transform, transform, sizeof transform);
        d.buttons = buttons;
        std::memcpy(force, d.force, sizeof force);
    }
    hdSetDoublev(HD_CURRENT_FORCE, force);
    hdEndFrame(d.handle);
    const HDErrorInfo e = hdGetError();
    std::lock_guard lock(d.mutex);
    std::memcpy(d.applied, force, sizeof force);
    if (HD_DEVICE_ERROR(e)) {
        d.servoError = true;
        d.error = describe(e, "servo loop");
        return HD_CALLBACK_DONE; // the host cuts the device off at its next read
    }
    return HD_CALLBACK_CONTINUE;
}

TrephineDevice* hdOpen(const char* args, char* error, size_t size) {
    if (args && *args) {
        std::snprintf(error, size, "the OpenHaptics plugin takes no arguments");
        return nullptr;
    }
    auto* d = new TrephineDevice;
    d->handle = hdInitDevice(HD_DEFAULT_DEVICE);
    HDErrorInfo e = hdGetError();
    if (HD_DEVICE_ERROR(e)) {
        std::snprintf(error, size, "%s", describe(e, "hdInitDevice").c_str());
        delete d;
        return nullptr;
    }
    hdGetDoublev(HD_USABLE_WORKSPACE_DIMENSIONS, d->workspace);
    hdGetDoublev(HD_NOMINAL_MAX_CONTINUOUS_FORCE, &d->maxForce);
    hdEnable(HD_FORCE_OUTPUT);
    d->servo = hdScheduleAsynchronous(servoTick, d, HD_MAX_SCHEDULER_PRIORITY);
    hdStartScheduler();
    e = hdGetError();
    if (HD_DEVICE_ERROR(e)) {
        std::snprintf(error, size, "%s", describe(e, "hdStartScheduler").c_str());
        hdUnschedule(d->servo);
        hdDisableDevice(d->handle);
        delete d;
        return nullptr;
    }
    return d;
}

void hdClose(TrephineDevice* d) {
    {
        std::lock_guard lock(d->mutex);
        d->force[0] = d->force[1] = d->force[2] = 0.0;
    }
    hdStopScheduler();
    hdUnschedule(d->servo);
    hdDisable(HD_FORCE_OUTPUT);
    hdDisableDevice(d->handle);
    delete d;
}

int hdInfo(TrephineDevice* d, TrephineDeviceInfo* out) {
    std::memset(out, 0, sizeof *out);
    std::snprintf(out->name, sizeof out->name, "%s", hdGetString(HD_DEVICE_MODEL_TYPE));
    for (int i = 0; i < 3; ++i) {
        out->workspace_min_mm[i] = d->workspace[i];
        out->workspace_max_mm[i] = d->workspace[3 + i];
    }
    out->max_force_n = d->maxForce;
    return TREPHINE_DEVICE_OK;
}

// Rotation part of a column-major 4x4 to a quaternion (w, x, y, z).
void toQuaternion(const HDdouble m[16], double q[4]) {
    const double r00 = m[0], r10 = m[1], r20 = m[2], r01 = m[4], r11 = m[5], r21 = m[6];
    const double r02 = m[8], r12 = m[9], r22 = m[10];
    const double t = r00 + r11 + r22;
    if (t > 0) {
        const double s = 2.0 * std::sqrt(1.0 + t);
        q[0] = s / 4;
        q[1] = (r21 - r12) / s, q[2] = (r02 - r20) / s, q[3] = (r10 - r01) / s;
    } else if (r00 > r11 && r00 > r22) {
        const double s = 2.0 * std::sqrt(1.0 + r00 - r11 - r22);
        q[0] = (r21 - r12) / s, q[1] = s / 4, q[2] = (r01 + r10) / s, q[3] = (r02 + r20) / s;
    } else if (r11 > r22) {
        const double s = 2.0 * std::sqrt(1.0 + r11 - r00 - r22);
        q[0] = (r02 - r20) / s, q[1] = (r01 + r10) / s, q[2] = s / 4, q[3] = (r12 + r21) / s;
    } else {
        const double s = 2.0 * std::sqrt(1.0 + r22 - r00 - r11);
        q[0] = (r10 - r01) / s, q[1] = (r02 + r20) / s, q[2] = (r12 + r21) / s, q[3] = s / 4;
    }
}

int hdRead(TrephineDevice* d, double, TrephineDevicePose* out) {
    std::lock_guard lock(d->mutex);
    if (d->servoError)
        return 1;
    out->position_mm[0] = d->transform[12];
    out->position_mm[1] = d->transform[13];
    out->position_mm[2] = d->transform[14];
    toQuaternion(d->transform, out->orientation);
    out->buttons = uint32_t(d->buttons);
    return TREPHINE_DEVICE_OK;
}

int hdWriteForce(TrephineDevice* d, const double f[3]) {
    std::lock_guard lock(d->mutex);
    std::memcpy(d->force, f, sizeof d->force);
    return d->servoError ? 1 : TREPHINE_DEVICE_OK;
}

int hdAppliedForce(TrephineDevice* d, double f[3]) {
    std::lock_guard lock(d->mutex);
    std::memcpy(f, d->applied, sizeof d->applied);
    return TREPHINE_DEVICE_OK;
}

const char* hdLastError(TrephineDevice* d) {
    std::lock_guard lock(d->mutex);
    return d->error.c_str();
}

const TrephineDeviceApi kApi = {
    TREPHINE_DEVICE_ABI_VERSION,
    sizeof(TrephineDeviceApi),
    hdOpen,
    hdClose,
    hdInfo,
    hdRead,
    hdWriteForce,
    hdAppliedForce,
    nullptr,
    hdLastError,
};

} // namespace

extern "C" TREPHINE_DEVICE_EXPORT const TrephineDeviceApi* trephine_device_api(uint32_t version) {
    return version == TREPHINE_DEVICE_ABI_VERSION ? &kApi : nullptr;
}

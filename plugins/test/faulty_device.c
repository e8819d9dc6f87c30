/* A device plugin that misbehaves on purpose, for the tests: it sits still at the origin until its
 * Nth read, then fails it (mode=fail), sleeps in it (mode=hang) or sleeps in its next force write
 * (mode=hangwrite) for ms milliseconds. Args: mode=fail|hang|hangwrite,after=N,ms=M. */
#include "libsim_devices/trephine_device_abi.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

enum Mode { kFail, kHang, kHangWrite };

struct TrephineDevice {
    enum Mode mode;
    long after, ms, reads, writes;
};

static void sleepMs(long ms) {
    struct timespec t = {ms / 1000, (ms % 1000) * 1000000L};
    nanosleep(&t, NULL);
}

static TrephineDevice* faultyOpen(const char* args, char* error, size_t size) {
    TrephineDevice d = {kFail, 100, 1000, 0, 0};
    char mode[16] = "fail";
    if (args && *args &&
        sscanf(args, "mode=%15[a-z],after=%ld,ms=%ld", mode, &d.after, &d.ms) < 1) {
        snprintf(error, size, "args must be mode=fail|hang|hangwrite,after=N,ms=M");
        return NULL;
    }
    if (!strcmp(mode, "fail"))
        d.mode = kFail;
    else if (!strcmp(mode, "hang"))
        d.mode = kHang;
    else if (!strcmp(mode, "hangwrite"))
        d.mode = kHangWrite;
    else {
        snprintf(error, size, "unknown mode '%s' (fail, hang, hangwrite)", mode);
        return NULL;
    }
    TrephineDevice* p = malloc(sizeof *p);
    *p = d;
    return p;
}

static void faultyClose(TrephineDevice* d) {
    free(d);
}

static int faultyInfo(TrephineDevice* d, TrephineDeviceInfo* out) {
    (void)d;
    memset(out, 0, sizeof *out);
    snprintf(out->name, sizeof out->name, "faulty");
    for (int i = 0; i < 3; ++i) {
        out->workspace_min_mm[i] = -100.0;
        out->workspace_max_mm[i] = 100.0;
    }
    out->max_force_n = 3.0;
    return TREPHINE_DEVICE_OK;
}

static int faultyRead(TrephineDevice* d, double now, TrephineDevicePose* out) {
    (void)now;
    if (++d->reads >= d->after) {
        if (d->mode == kFail)
            return 7;
        if (d->mode == kHang && d->reads == d->after)
            sleepMs(d->ms);
    }
    memset(out, 0, sizeof *out);
    out->orientation[0] = 1.0;
    return TREPHINE_DEVICE_OK;
}

static int faultyWrite(TrephineDevice* d, const double f[3]) {
    (void)f;
    if (d->mode == kHangWrite && d->reads >= d->after && d->writes++ == 0)
        sleepMs(d->ms);
    return TREPHINE_DEVICE_OK;
}

static const char* faultyLastError(TrephineDevice* d) {
    (void)d;
    return "the test plugin fails on purpose";
}

static const TrephineDeviceApi kApi = {
    TREPHINE_DEVICE_ABI_VERSION,
    sizeof(TrephineDeviceApi),
    faultyOpen,
    faultyClose,
    faultyInfo,
    faultyRead,
    faultyWrite,
    NULL,
    NULL,
    faultyLastError,
};

TREPHINE_DEVICE_EXPORT const TrephineDeviceApi* trephine_device_api(uint32_t version) {
    return version == TREPHINE_DEVICE_ABI_VERSION ? &kApi : NULL;
}

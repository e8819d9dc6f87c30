/* The C ABI a force-feedback plugin implements (docs/devices.md). A plugin is a shared library
 * exporting one function, trephine_device_api(), that returns a table of function pointers. The
 * host passes the ABI version it was built with; a plugin that cannot serve it returns NULL. Plain
 * C so that any vendor SDK (OpenHaptics HD, Force Dimension dhd, ...) can be wrapped in it.
 *
 * Units: millimetres, newtons, seconds. Every call is made from one host thread at a time; read
 * and write_force come once per haptic tick (1 kHz) and must return well within a millisecond: a
 * call that does not return within the host's deadline cuts the device off. */
#ifndef TREPHINE_DEVICE_ABI_H
#define TREPHINE_DEVICE_ABI_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

#define TREPHINE_DEVICE_ABI_VERSION 1u
#define TREPHINE_DEVICE_ENTRY "trephine_device_api"

#if defined(_WIN32)
#define TREPHINE_DEVICE_EXPORT __declspec(dllexport)
#else
#define TREPHINE_DEVICE_EXPORT __attribute__((visibility("default")))
#endif

/* Status codes: 0 is success, anything else a failure the host reports and cuts the device off. */
#define TREPHINE_DEVICE_OK 0

typedef struct TrephineDevice TrephineDevice; /* the plugin's own state, opaque to the host */

typedef struct TrephineDevicePose {
    double position_mm[3];
    double orientation[4]; /* unit quaternion w, x, y, z: the tool's local +z is its shaft */
    uint32_t buttons;      /* bit i set: button i pressed */
} TrephineDevicePose;

typedef struct TrephineDeviceInfo {
    char name[64];              /* NUL-terminated, for messages */
    double workspace_min_mm[3]; /* the box the tool can reach */
    double workspace_max_mm[3];
    double max_force_n; /* the most the device can render continuously */
} TrephineDeviceInfo;

typedef struct TrephineDeviceApi {
    uint32_t abi_version; /* TREPHINE_DEVICE_ABI_VERSION the plugin was built with */
    uint32_t struct_size; /* sizeof(TrephineDeviceApi) as the plugin knows it */

    /* Opens the device. args: the text after '?' in --device plugin:PATH?ARGS ("" if none). On
     * failure returns NULL and writes a one-line reason into error (error_size bytes). */
    TrephineDevice* (*open)(const char* args, char* error, size_t error_size);
    /* Releases the device; it must stop exerting force first. */
    void (*close)(TrephineDevice* device);
    int (*info)(TrephineDevice* device, TrephineDeviceInfo* out);
    /* The pose at host time now_s (seconds on the haptic loop's clock). */
    int (*read)(TrephineDevice* device, double now_s, TrephineDevicePose* out);
    /* The force on the user's hand until the next call (N, the pose's frame). */
    int (*write_force)(TrephineDevice* device, const double force_n[3]);

    /* Optional (NULL when absent). */
    /* The force the device measures it applies (N); hosts fall back to the force written. */
    int (*applied_force)(TrephineDevice* device, double force_n[3]);
    /* A simulated hand's intent: where the user wants the tool this tick. */
    int (*set_intent)(TrephineDevice* device, const TrephineDevicePose* intent);
    /* A one-line description of the last failure, owned by the plugin. */
    const char* (*last_error)(TrephineDevice* device);
} TrephineDeviceApi;

/* The one exported entry point. */
typedef const TrephineDeviceApi* (*TrephineDeviceEntry)(uint32_t host_abi_version);
TREPHINE_DEVICE_EXPORT const TrephineDeviceApi* trephine_device_api(uint32_t host_abi_version);

#ifdef __cplusplus
}
#endif

#endif /* TREPHINE_DEVICE_ABI_H */

/* A device plugin built for an ABI version this host does not know, for the tests. */
#include "libsim_devices/trephine_device_abi.h"

TREPHINE_DEVICE_EXPORT const TrephineDeviceApi* trephine_device_api(uint32_t version) {
    (void)version;
    return NULL;
}

// The SpaceMouse through spacenavd (libspnav): the daemon owns the device and sends motion and
// button events, which become the HID reports SpaceMouseParser reads. Built only where libspnav
// is found (kHaveSpaceNav); elsewhere opening says so in one line.
#pragma once

#include "libsim_devices/spacemouse.h"

#include <memory>
#include <string>

namespace trephine {

extern const bool kHaveSpaceNav; // this build links libspnav

// True when spacenavd answers (its socket accepts us); `why` says why not ("does not answer").
bool spaceNavRunning(std::string* why = nullptr);

// Connects to spacenavd; throws Error (one line) when libspnav is absent from this build or the
// daemon does not answer.
std::unique_ptr<SpaceMouseSource> openSpaceNav();

} // namespace trephine

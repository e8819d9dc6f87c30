// 3Dconnexion SpaceMouse through hidapi: the HID report parser (testable with recorded bytes), the
// integration of its 6-DOF deflection into a tool pose, the device, and HID enumeration.
//
// Report formats (byte 0 is the report ID; axes little-endian int16, about +-350 at full push):
// - Older models (SpaceNavigator, SpaceExplorer, SpacePilot, ...): ID 1 = translation x, y, z
//   (7 bytes), ID 2 = rotation rx, ry, rz (7 bytes), ID 3 = button bitmask (1-4 bytes after the
//   ID).
// - Newer models (SpaceMouse Compact, Wireless, Pro Wireless, ...): ID 1 carries translation and
//   rotation together (13 bytes); buttons still ID 3.
// Anything else (unknown ID, short report) is ignored.
#pragma once

#include "libsim/device.h"

#include <cstdint>
#include <glm/vec3.hpp>
#include <memory>
#include <span>
#include <string>
#include <vector>

namespace trephine {

inline constexpr uint16_t kLogitechVendorId = 0x046d; // 3Dconnexion's older devices
inline constexpr uint16_t k3DconnexionVendorId = 0x256f;
inline constexpr int kSpaceMouseFullScale = 350;

struct SpaceMouseState {
    glm::ivec3 translation{0}; // device axes: x right, y towards the user, z down
    glm::ivec3 rotation{0};
    uint32_t buttons = 0;
    uint64_t reports = 0; // accepted
    uint64_t ignored = 0; // malformed or unknown
};

class SpaceMouseParser {
public:
    // Returns true when the report was understood and applied.
    bool feed(std::span<const uint8_t> report);
    // The device is gone: no deflection, no button held (the counts stay).
    void release();
    const SpaceMouseState& state() const { return m_state; }

private:
    SpaceMouseState m_state;
};

struct SpaceMouseConfig {
    double translationGainMmPerS = 60.0; // at full deflection
    double rotationGainRadPerS = 1.5;
    int deadZone = 12; // raw counts, per axis
};

// Moves `pose` by the deflection held for dt seconds. Device axes map to object space as
// x -> +x, y -> -y (push away: +y), z -> -z (lift: +z); rotations follow the same mapping.
ToolPose integrateSpaceMouse(const ToolPose& pose, const SpaceMouseState& state, double dt,
                             const SpaceMouseConfig& config);

// The longest time one read integrates: after a stall (a descheduled thread, a suspended laptop)
// the tool moves as if the deflection had been held this long, not the whole gap.
inline constexpr double kSpaceMouseMaxStepS = 0.1;

// One read of the device at `now`: `pose` moved by `state`'s deflection held since `lastRead`
// (at most kSpaceMouseMaxStepS of it; nothing on the first read, lastRead < 0), `lastRead` set to
// `now`. A `lost` device reports invalid and leaves the pose where it was.
DeviceState spaceMouseStep(ToolPose& pose, double& lastRead, double now,
                           const SpaceMouseState& state, bool lost, const SpaceMouseConfig& config);

// HID usage of a 6-DOF device's interface: Generic Desktop (page 1), Multi-axis Controller (8).
inline constexpr uint16_t kHidGenericDesktopPage = 0x01, kHidMultiAxisUsage = 0x08;

// True for 3Dconnexion 6-DOF devices (the product IDs spacenavd drives). Under 3Dconnexion's own
// vendor ID the CadMouse and other non-6-DOF products are refused, and a product not listed is
// taken when its interface's usage (hidraw reports it; 0 when unknown) says multi-axis
// controller; there a known usage that is not that refuses any product (a receiver carrying a
// SpaceMouse and a CadMouse shows one interface for each). Logitech's IDs go by product alone.
bool isSpaceMouse(uint16_t vendorId, uint16_t productId, uint16_t usagePage = 0,
                  uint16_t usage = 0);

struct HidDeviceInfo {
    std::string path;
    uint16_t vendorId = 0, productId = 0;
    uint16_t usagePage = 0, usage = 0; // of this interface (0: unknown)
    std::string manufacturer, product;
    bool usable = false; // a SpaceMouse we can drive
};
// All HID devices hidapi sees (empty when none or when hidapi cannot initialise).
std::vector<HidDeviceInfo> enumerateHidDevices();

class SpaceMouseDevice : public Device {
public:
    // Opens the first usable SpaceMouse (or `path`); throws Error when there is none.
    explicit SpaceMouseDevice(SpaceMouseConfig config = {}, const std::string& path = {});
    ~SpaceMouseDevice() override;
    std::string name() const override { return m_name; }
    // Drains pending reports (non-blocking) and integrates the pose since the last read.
    DeviceState read(double now) override;
    void setForce(glm::vec3) override {}
    void setPose(const ToolPose& pose) { m_pose = pose; }
    // hidapi failed to read (the device was unplugged): from then on read() reports invalid.
    bool lost() const { return m_lost; }

private:
    struct Impl;
    std::unique_ptr<Impl> m_impl;
    std::string m_name;
    SpaceMouseConfig m_config;
    SpaceMouseParser m_parser;
    ToolPose m_pose;
    double m_lastRead = -1.0;
    bool m_lost = false;
};

} // namespace trephine

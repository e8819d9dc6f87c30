// 3Dconnexion SpaceMouse: the HID report parser (testable with recorded bytes), the integration of
// its 6-DOF deflection into a tool pose, the device over its two backends (hidapi, and spacenavd
// through libspnav in spacenav.h), and HID enumeration.
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

#include <array>
#include <cstdint>
#include <glm/gtc/quaternion.hpp>
#include <glm/vec3.hpp>
#include <memory>
#include <mutex>
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

// Moves `pose` by the deflection held for dt seconds. Device axes map to the table frame as
// x -> +x, y -> -y (push away: +y), z -> -z (lift: +z); rotations follow the same mapping.
// `frame` turns the table frame into object space (identity: the object's own axes), so a window
// can make "push away" mean "into the screen" (spaceMouseViewFrame).
ToolPose integrateSpaceMouse(const ToolPose& pose, const SpaceMouseState& state, double dt,
                             const SpaceMouseConfig& config,
                             glm::quat frame = glm::quat(1, 0, 0, 0));

// The frame for a viewer whose right, up and backward (towards the viewer) directions are given
// (object space, orthonormal): pushing the cap away moves the tool into the view, lifting it
// moves the tool up the screen.
glm::quat spaceMouseViewFrame(glm::vec3 right, glm::vec3 up, glm::vec3 back);

// The longest time one read integrates: after a stall (a descheduled thread, a suspended laptop)
// the tool moves as if the deflection had been held this long, not the whole gap.
inline constexpr double kSpaceMouseMaxStepS = 0.1;

// One read of the device at `now`: `pose` moved by `state`'s deflection held since `lastRead`
// (at most kSpaceMouseMaxStepS of it; nothing on the first read, lastRead < 0), `lastRead` set to
// `now`. A `lost` device reports invalid and leaves the pose where it was.
DeviceState spaceMouseStep(ToolPose& pose, double& lastRead, double now,
                           const SpaceMouseState& state, bool lost, const SpaceMouseConfig& config,
                           glm::quat frame = glm::quat(1, 0, 0, 0));

// spacenavd's events as the HID reports a SpaceNavigator sends (IDs 1, 2, 3), so both backends
// share one parser. spacenavd's default axes (x right, y up, z away from the user, its
// `swap-yz` and inversions) are turned back into the device's (x right, y towards the user,
// z down); a spacenavd.conf that remaps axes remaps them here too.
std::array<uint8_t, 7> spnavTranslationReport(int x, int y, int z);
std::array<uint8_t, 7> spnavRotationReport(int rx, int ry, int rz);
std::array<uint8_t, 5> spaceMouseButtonReport(uint32_t buttons);

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

// Where a SpaceMouse's reports come from: hidapi (the device's own HID reports) or spacenavd
// (libspnav's events, turned into the same reports). Tests give their own.
class SpaceMouseSource {
public:
    virtual ~SpaceMouseSource() = default;
    virtual std::string name() const = 0;
    // Feeds what arrived since the last call to `parser` without blocking (a bounded number of
    // reports: never starve the haptic tick); false once the device is gone (unplugged, the
    // daemon stopped).
    virtual bool poll(SpaceMouseParser& parser) = 0;
};

// The first usable SpaceMouse through hidapi (or the one at `path`); throws Error when there is
// none or it cannot be opened.
std::unique_ptr<SpaceMouseSource> openHidSpaceMouse(const std::string& path = {});

// A SpaceMouse as a relative device: its deflection moves and turns a pose that starts at the
// origin (an AnchoredDevice places it), integrated on every read.
class SpaceMouseDevice : public Device {
public:
    explicit SpaceMouseDevice(std::unique_ptr<SpaceMouseSource> source,
                              SpaceMouseConfig config = {});
    // Opens the first usable SpaceMouse through hidapi (or `path`); throws Error when there is
    // none.
    explicit SpaceMouseDevice(SpaceMouseConfig config = {}, const std::string& path = {});
    ~SpaceMouseDevice() override;
    std::string name() const override { return m_name; }
    // Drains pending reports (non-blocking) and integrates the pose since the last read.
    DeviceState read(double now) override;
    void setForce(glm::vec3) override {}
    // Any thread: the frame later motion is taken in (spaceMouseViewFrame); what has moved stays.
    void setFrame(glm::quat frame);
    const SpaceMouseConfig& config() const { return m_config; }
    // The source stopped answering (the device was unplugged): from then on read() reports
    // invalid.
    bool lost() const { return m_lost; }

private:
    std::unique_ptr<SpaceMouseSource> m_source;
    std::string m_name;
    SpaceMouseConfig m_config;
    SpaceMouseParser m_parser;
    ToolPose m_pose;
    double m_lastRead = -1.0;
    bool m_lost = false;
    mutable std::mutex m_frameMutex;
    glm::quat m_frame{1, 0, 0, 0};
};

} // namespace trephine

#include "libsim_devices/spacemouse.h"

#include "libsim/error.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <glm/gtc/quaternion.hpp>
#include <hidapi.h>
#include <span>

namespace trephine {

namespace {

int16_t readI16(const uint8_t* p) {
    return int16_t(uint16_t(p[0]) | uint16_t(p[1]) << 8);
}

glm::ivec3 readAxes(const uint8_t* p) {
    return {readI16(p), readI16(p + 2), readI16(p + 4)};
}

double shaped(int raw, int deadZone) {
    // Dead zone, then linear from its edge so there is no jump when leaving it.
    const int mag = std::abs(raw);
    if (mag <= deadZone)
        return 0.0;
    const double span = std::max(1, kSpaceMouseFullScale - deadZone);
    return std::copysign(std::min(1.0, double(mag - deadZone) / span), double(raw));
}

// Device axes to object space (see integrateSpaceMouse).
glm::dvec3 toObject(glm::dvec3 d) {
    return {d.x, -d.y, -d.z};
}

} // namespace

bool SpaceMouseParser::feed(std::span<const uint8_t> r) {
    if (r.empty()) {
        m_state.ignored++;
        return false;
    }
    switch (r[0]) {
    case 1:
        if (r.size() >= 13) { // newer models: translation and rotation in one report
            m_state.translation = readAxes(&r[1]);
            m_state.rotation = readAxes(&r[7]);
        } else if (r.size() >= 7) {
            m_state.translation = readAxes(&r[1]);
        } else {
            break;
        }
        m_state.reports++;
        return true;
    case 2:
        if (r.size() < 7)
            break;
        m_state.rotation = readAxes(&r[1]);
        m_state.reports++;
        return true;
    case 3: {
        if (r.size() < 2)
            break;
        uint32_t bits = 0;
        const size_t n = std::min<size_t>(r.size() - 1, 4);
        for (size_t i = 0; i < n; ++i)
            bits |= uint32_t(r[1 + i]) << (8 * i);
        m_state.buttons = bits;
        m_state.reports++;
        return true;
    }
    default:
        break;
    }
    m_state.ignored++;
    return false;
}

void SpaceMouseParser::release() {
    m_state.translation = glm::ivec3(0);
    m_state.rotation = glm::ivec3(0);
    m_state.buttons = 0;
}

DeviceState spaceMouseStep(ToolPose& pose, double& lastRead, double now,
                           const SpaceMouseState& state, bool lost, const SpaceMouseConfig& config,
                           glm::quat frame) {
    DeviceState s;
    if (!lost && lastRead >= 0.0)
        pose = integrateSpaceMouse(pose, state, std::min(now - lastRead, kSpaceMouseMaxStepS),
                                   config, frame);
    lastRead = now;
    s.pose = pose;
    s.buttons = lost ? 0u : state.buttons;
    s.valid = !lost;
    return s;
}

ToolPose integrateSpaceMouse(const ToolPose& pose, const SpaceMouseState& s, double dt,
                             const SpaceMouseConfig& c, glm::quat frame) {
    ToolPose out = pose;
    if (!(dt > 0.0))
        return out;
    const glm::dvec3 t(shaped(s.translation.x, c.deadZone), shaped(s.translation.y, c.deadZone),
                       shaped(s.translation.z, c.deadZone));
    const glm::dvec3 r(shaped(s.rotation.x, c.deadZone), shaped(s.rotation.y, c.deadZone),
                       shaped(s.rotation.z, c.deadZone));
    const glm::dquat f(frame);
    out.position += glm::vec3(f * toObject(t) * (c.translationGainMmPerS * dt));
    const glm::dvec3 w = f * toObject(r) * (c.rotationGainRadPerS * dt); // rotation vector
    const double angle = glm::length(w);
    if (angle > 0.0) {
        const glm::quat dq = glm::angleAxis(float(angle), glm::vec3(w / angle));
        out.orientation = glm::normalize(dq * pose.orientation); // about object axes
    }
    return out;
}

glm::quat spaceMouseViewFrame(glm::vec3 right, glm::vec3 up, glm::vec3 back) {
    // Table frame x (right), y (away from the user), z (up) onto the view's right, -back, up.
    return glm::normalize(glm::quat_cast(glm::mat3(right, -back, up)));
}

namespace {

void putI16(uint8_t* p, int v) {
    const auto c = uint16_t(int16_t(std::clamp(v, -32768, 32767)));
    p[0] = uint8_t(c & 0xff);
    p[1] = uint8_t(c >> 8);
}

std::array<uint8_t, 7> axesReport(uint8_t id, int x, int y, int z) {
    std::array<uint8_t, 7> r{id};
    putI16(&r[1], x);
    putI16(&r[3], y);
    putI16(&r[5], z);
    return r;
}

} // namespace

// spacenavd's default maps device axes (x, y, z) to (x, -z, -y); this is its inverse.
std::array<uint8_t, 7> spnavTranslationReport(int x, int y, int z) {
    return axesReport(1, x, -z, -y);
}

std::array<uint8_t, 7> spnavRotationReport(int rx, int ry, int rz) {
    return axesReport(2, rx, -rz, -ry);
}

std::array<uint8_t, 5> spaceMouseButtonReport(uint32_t buttons) {
    return {3, uint8_t(buttons), uint8_t(buttons >> 8), uint8_t(buttons >> 16),
            uint8_t(buttons >> 24)};
}

bool isSpaceMouse(uint16_t vendorId, uint16_t productId, uint16_t usagePage, uint16_t usage) {
    auto listed = [productId](std::span<const uint16_t> products) {
        return std::find(products.begin(), products.end(), productId) != products.end();
    };
    if (vendorId == kLogitechVendorId) {
        // 3Dconnexion products sold under Logitech's vendor ID (SpaceNavigator and kin).
        static constexpr uint16_t kProducts[] = {0xc603, 0xc605, 0xc606, 0xc621, 0xc623, 0xc625,
                                                 0xc626, 0xc627, 0xc628, 0xc629, 0xc62b, 0xc640};
        return listed(kProducts);
    }
    if (vendorId != k3DconnexionVendorId)
        return false;
    // The same vendor ID covers mice, keyboards and receivers carrying several of them, so here an
    // interface whose usage is known must be the multi-axis controller.
    const bool usageKnown = usagePage != 0 || usage != 0;
    const bool multiAxis = usagePage == kHidGenericDesktopPage && usage == kHidMultiAxisUsage;
    if (usageKnown && !multiAxis)
        return false;
    // SpaceMouse Wireless (cable, receiver), Pro Wireless (cable, receiver), Enterprise, Compact,
    // Module, and the Universal Receiver.
    static constexpr uint16_t kProducts[] = {0xc62e, 0xc62f, 0xc631, 0xc632,
                                             0xc633, 0xc635, 0xc636, 0xc652};
    // Not 6-DOF: CadMouse, CadMouse Wireless, and two spacenavd refuses (c62c, c641).
    static constexpr uint16_t kNot6Dof[] = {0xc650, 0xc651, 0xc62c, 0xc641};
    if (listed(kNot6Dof))
        return false;
    return listed(kProducts) || multiAxis;
}

namespace {

std::string narrow(const wchar_t* w) {
    std::string out;
    for (; w && *w; ++w)
        out.push_back(*w < 128 ? char(*w) : '?');
    return out;
}

} // namespace

std::vector<HidDeviceInfo> enumerateHidDevices() {
    std::vector<HidDeviceInfo> out;
    if (hid_init() != 0)
        return out;
    hid_device_info* list = hid_enumerate(0, 0);
    for (hid_device_info* d = list; d; d = d->next) {
        HidDeviceInfo info;
        info.path = d->path ? d->path : "";
        info.vendorId = d->vendor_id;
        info.productId = d->product_id;
        info.manufacturer = narrow(d->manufacturer_string);
        info.product = narrow(d->product_string);
        info.usagePage = d->usage_page;
        info.usage = d->usage;
        info.usable = isSpaceMouse(d->vendor_id, d->product_id, d->usage_page, d->usage);
        out.push_back(std::move(info));
    }
    hid_free_enumeration(list);
    return out;
}

namespace {

class HidSource : public SpaceMouseSource {
public:
    HidSource(hid_device* handle, std::string name) : m_handle(handle), m_name(std::move(name)) {}
    ~HidSource() override { hid_close(m_handle); }
    std::string name() const override { return m_name; }
    bool poll(SpaceMouseParser& parser) override {
        uint8_t buf[64];
        for (int i = 0; i < 64; ++i) {
            const int n = hid_read(m_handle, buf, sizeof buf);
            if (n < 0)
                return false;
            if (n == 0)
                break;
            parser.feed(std::span<const uint8_t>(buf, size_t(n)));
        }
        return true;
    }

private:
    hid_device* m_handle;
    std::string m_name;
};

} // namespace

std::unique_ptr<SpaceMouseSource> openHidSpaceMouse(const std::string& path) {
    std::string chosen = path, name;
    if (chosen.empty()) {
        for (const HidDeviceInfo& d : enumerateHidDevices())
            if (d.usable) {
                chosen = d.path;
                name = d.product.empty() ? "SpaceMouse" : d.product;
                break;
            }
        if (chosen.empty())
            throw Error("no SpaceMouse found through hidapi: attach one (and check "
                        "/dev/hidraw* permissions), or choose another --device");
    }
    hid_device* handle = nullptr;
    if (hid_init() != 0 || !(handle = hid_open_path(chosen.c_str())))
        throw Error("cannot open HID device " + chosen + ": check its permissions");
    hid_set_nonblocking(handle, 1);
    return std::make_unique<HidSource>(handle, name.empty() ? "SpaceMouse" : name);
}

SpaceMouseDevice::SpaceMouseDevice(std::unique_ptr<SpaceMouseSource> source,
                                   SpaceMouseConfig config)
    : m_source(std::move(source)), m_name(m_source->name()), m_config(config) {}

SpaceMouseDevice::SpaceMouseDevice(SpaceMouseConfig config, const std::string& path)
    : SpaceMouseDevice(openHidSpaceMouse(path), config) {}

SpaceMouseDevice::~SpaceMouseDevice() = default;

void SpaceMouseDevice::setFrame(glm::quat frame) {
    std::lock_guard lock(m_frameMutex);
    m_frame = frame;
}

DeviceState SpaceMouseDevice::read(double now) {
    if (!m_lost && !m_source->poll(m_parser)) {
        // Unplugged: the last deflection would otherwise keep moving the tool (up to the
        // full-scale gain) for as long as the loop runs.
        m_lost = true;
        m_parser.release();
        std::fprintf(stderr,
                     "trephine: %s stopped answering (unplugged?); the tool stays where it was\n",
                     m_name.c_str());
    }
    glm::quat frame;
    {
        std::lock_guard lock(m_frameMutex);
        frame = m_frame;
    }
    return spaceMouseStep(m_pose, m_lastRead, now, m_parser.state(), m_lost, m_config, frame);
}

} // namespace trephine

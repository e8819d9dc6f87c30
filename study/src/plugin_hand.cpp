// The haptics study's hand as the simulated force device, loaded through the device plugin ABI.
#include "study/haptics_study.h"

#include "libsim/error.h"
#include "libsim_devices/plugin_device.h"

#include <fmt/format.h>

#include <filesystem>
#include <system_error>

namespace trephine::study {

struct PluginHand::Loaded {
    LoadedPlugin plugin;
    ~Loaded() { unloadPlugin(plugin); }
};

namespace {

TrephineDevicePose poseAt(glm::dvec3 p) {
    TrephineDevicePose pose{};
    pose.position_mm[0] = p.x;
    pose.position_mm[1] = p.y;
    pose.position_mm[2] = p.z;
    pose.orientation[0] = 1.0;
    return pose;
}

} // namespace

PluginHand::PluginHand(const std::string& path, const HandModel& model, const HandFrame& frame,
                       glm::dvec3 start)
    : m_plugin(std::make_unique<Loaded>()), m_model(model), m_frame(frame), m_x(start) {
    // No saturation the spring-damper hand does not have: the display's clamp is the study's.
    const std::string args = fmt::format("mass={},k={},c={},maxforce=1000,half=100000",
                                         model.massKg, model.stiffnessNPerMm, model.dampingNsPerMm);
    std::string error;
    if (!loadPlugin(path, args, m_plugin->plugin, error))
        throw Error("study haptics: the hand: " + error);
    const TrephineDeviceApi& api = m_plugin->plugin.api;
    if (!api.set_intent)
        throw Error("study haptics: the hand: " + path +
                    " takes no intent: it is not a simulated device");
    const TrephineDevicePose at = poseAt(start); // the first intent places the hand, at rest
    api.set_intent(m_plugin->plugin.device, &at);
}

PluginHand::~PluginHand() = default;

void PluginHand::advance(glm::dvec3 forceN, double t, double dt) {
    const TrephineDeviceApi& api = m_plugin->plugin.api;
    TrephineDevice* device = m_plugin->plugin.device;
    TrephineDevicePose pose{};
    if (!m_started) { // its clock starts at the run's
        api.read(device, t, &pose);
        m_started = true;
    }
    const double force[3] = {forceN.x, forceN.y, forceN.z};
    const TrephineDevicePose intent = poseAt(handTarget(m_model, m_frame, t + 0.5 * dt));
    if (api.write_force(device, force) != TREPHINE_DEVICE_OK ||
        api.set_intent(device, &intent) != TREPHINE_DEVICE_OK ||
        api.read(device, t + dt, &pose) != TREPHINE_DEVICE_OK)
        throw Error("study haptics: the simulated device refused a tick at " +
                    fmt::format("{:.3f} s", t));
    m_x = {pose.position_mm[0], pose.position_mm[1], pose.position_mm[2]};
}

std::string builtSimDevicePath() {
    std::error_code ec;
    const std::filesystem::path self = std::filesystem::read_symlink("/proc/self/exe", ec);
    if (ec)
        return {};
    const std::filesystem::path plugin =
        self.parent_path().parent_path() / "plugins" / "trephine_sim_device.so";
    return std::filesystem::is_regular_file(plugin, ec) ? plugin.string() : std::string();
}

} // namespace trephine::study

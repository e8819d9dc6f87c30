#include "libsim_devices/plugin_device.h"

#include "libsim_devices/trephine_device_abi.h"

#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstdio>
#include <cstring>
#include <deque>
#include <dlfcn.h>
#include <fmt/format.h>
#include <glm/geometric.hpp>
#include <glm/gtc/quaternion.hpp>
#include <mutex>
#include <optional>
#include <thread>
#include <utility>

namespace trephine {

// [SECTION] the worker's state

using Clock = std::chrono::steady_clock;

// Shared by the device and its worker thread: every plugin call runs on the worker, so a call that
// hangs holds the worker, never the haptic loop. A worker stuck in a call at close keeps this alive
// (and the library loaded) after the device is gone.
struct PluginDevice::Impl {
    std::string path;
    PluginOptions options;
    void* library = nullptr;
    TrephineDeviceApi table{}; // the plugin's table, padded with nulls to this ABI's size
    const TrephineDeviceApi* api = nullptr;
    TrephineDevice* device = nullptr;
    TrephineDeviceInfo info{};

    mutable std::mutex mutex;
    std::condition_variable wake; // the worker waits on it for work
    std::condition_variable done; // the host waits on it for a result
    std::thread worker;

    // Requests (newest wins) and results, under mutex.
    bool writePending = false;
    glm::dvec3 force{0.0};
    bool readPending = false;
    double readNow = 0.0;
    std::optional<TrephineDevicePose> intent;
    uint64_t posted = 0, completed = 0; // read requests
    bool inCall = false;                // the worker is inside a plugin call
    const char* callName = "";
    Clock::time_point callStart;
    int rc = TREPHINE_DEVICE_OK;
    const char* failedCall = "";
    TrephineDevicePose pose{};
    glm::dvec3 applied{0.0};
    bool stop = false, closed = false;

    bool cut = false; // no call but close from now on
    std::string fault;
    uint64_t calls = 0, missed = 0;
    glm::dvec3 lastWritten{0.0};
    std::deque<PluginSample> history;

    void run();
    // Calls fn with the lock released, stamped so the host can tell how long it has been inside.
    template <typename Fn>
    int call(std::unique_lock<std::mutex>& lock, const char* name, Fn fn);
    // Under the lock: stops calling the plugin and says why, once.
    void cutOff(const std::string& why);
    std::string pluginError() const;
    void say(const std::string& line) const; // to options.report, else stderr
};

template <typename Fn>
int PluginDevice::Impl::call(std::unique_lock<std::mutex>& lock, const char* name, Fn fn) {
    inCall = true;
    callName = name;
    callStart = Clock::now();
    calls++;
    lock.unlock();
    const int r = fn();
    lock.lock();
    inCall = false;
    return r;
}

std::string PluginDevice::Impl::pluginError() const {
    const char* e = api && api->last_error && device ? api->last_error(device) : nullptr;
    return e && *e ? fmt::format(": {}", e) : std::string();
}

void PluginDevice::Impl::say(const std::string& line) const {
    if (options.report)
        options.report(line);
    else
        std::fprintf(stderr, "trephine: %s\n", line.c_str());
}

void PluginDevice::Impl::cutOff(const std::string& why) {
    if (cut)
        return;
    cut = true;
    fault = fmt::format("device plugin {}: {}; force output cut off", path, why);
    say(fault);
    wake.notify_all(); // the worker writes zero force if it can
}

void PluginDevice::Impl::run() {
    pthread_setname_np(pthread_self(), "device-plugin");
    std::unique_lock lock(mutex);
    bool zeroed = false;
    while (true) {
        wake.wait(lock, [&] { return stop || (cut && !zeroed) || writePending || readPending; });
        if (cut && !zeroed) {
            // Cut off: one last zero, and nothing else until close.
            zeroed = true;
            writePending = readPending = false;
            const double zero[3] = {0.0, 0.0, 0.0};
            call(lock, "write_force", [&] { return api->write_force(device, zero); });
            done.notify_all();
            continue;
        }
        if (stop)
            break;
        if (writePending) {
            writePending = false;
            const glm::dvec3 f = force;
            const int r = call(lock, "write_force", [&] {
                const double v[3] = {f.x, f.y, f.z};
                return api->write_force(device, v);
            });
            if (r != TREPHINE_DEVICE_OK)
                cutOff(fmt::format("write_force failed ({}){}", r, pluginError()));
        }
        if (readPending && !cut) {
            readPending = false;
            const double now = readNow;
            const std::optional<TrephineDevicePose> goal = std::exchange(intent, std::nullopt);
            TrephineDevicePose p{};
            glm::dvec3 a = force;
            int r = TREPHINE_DEVICE_OK;
            const char* failed = "";
            if (goal && api->set_intent &&
                (r = call(lock, "set_intent", [&] { return api->set_intent(device, &*goal); })))
                failed = "set_intent";
            if (!r && (r = call(lock, "read", [&] { return api->read(device, now, &p); })))
                failed = "read";
            double v[3] = {a.x, a.y, a.z};
            if (!r && api->applied_force &&
                (r = call(lock, "applied_force", [&] { return api->applied_force(device, v); })))
                failed = "applied_force";
            pose = p;
            applied = glm::dvec3(v[0], v[1], v[2]);
            rc = r;
            failedCall = failed;
            completed++;
            done.notify_all();
        }
    }
    const double zero[3] = {0.0, 0.0, 0.0};
    call(lock, "write_force", [&] { return api->write_force(device, zero); });
    call(lock, "close", [&] {
        api->close(device);
        return 0;
    });
    closed = true;
    done.notify_all();
}

// [SECTION] the device

PluginDevice::PluginDevice(std::shared_ptr<Impl> impl) : m_impl(std::move(impl)) {}

PluginDevice::~PluginDevice() {
    Impl& d = *m_impl;
    std::unique_lock lock(d.mutex);
    d.stop = true;
    d.wake.notify_all();
    // A worker stuck in the plugin cannot be joined: it is left with the library loaded.
    if (d.done.wait_for(lock, std::chrono::milliseconds(200), [&] { return d.closed; })) {
        lock.unlock();
        d.worker.join();
        dlclose(d.library);
    } else {
        d.cut = true;
        d.say(fmt::format("device plugin {}: {} still running at close; left loaded", d.path,
                          d.callName));
        lock.unlock();
        d.worker.detach();
    }
}

std::string PluginDevice::name() const {
    return fmt::format("plugin:{}", m_impl->info.name);
}

float PluginDevice::maxForceN() const {
    return float(m_impl->info.max_force_n);
}

DeviceWorkspace PluginDevice::workspace() const {
    const TrephineDeviceInfo& i = m_impl->info;
    return {glm::vec3(i.workspace_min_mm[0], i.workspace_min_mm[1], i.workspace_min_mm[2]),
            glm::vec3(i.workspace_max_mm[0], i.workspace_max_mm[1], i.workspace_max_mm[2])};
}

bool PluginDevice::acceptsIntent() const {
    return m_impl->api->set_intent != nullptr;
}

void PluginDevice::setIntent(const ToolPose& p) {
    TrephineDevicePose goal{};
    for (int i = 0; i < 3; ++i)
        goal.position_mm[i] = p.position[i];
    goal.orientation[0] = p.orientation.w;
    goal.orientation[1] = p.orientation.x;
    goal.orientation[2] = p.orientation.y;
    goal.orientation[3] = p.orientation.z;
    std::lock_guard lock(m_impl->mutex);
    m_impl->intent = goal;
}

std::string PluginDevice::fault() const {
    std::lock_guard lock(m_impl->mutex);
    return m_impl->fault;
}

std::vector<PluginSample> PluginDevice::history() const {
    std::lock_guard lock(m_impl->mutex);
    return {m_impl->history.begin(), m_impl->history.end()};
}

uint64_t PluginDevice::calls() const {
    std::lock_guard lock(m_impl->mutex);
    return m_impl->calls;
}

uint64_t PluginDevice::missedTicks() const {
    std::lock_guard lock(m_impl->mutex);
    return m_impl->missed;
}

DeviceState PluginDevice::read(double now) {
    Impl& d = *m_impl;
    std::unique_lock lock(d.mutex);
    const auto deadline = std::chrono::duration_cast<Clock::duration>(
        std::chrono::duration<double>(d.options.deadlineS));
    const auto hang = std::chrono::duration_cast<Clock::duration>(
        std::chrono::duration<double>(std::max(d.options.hangS, d.options.deadlineS)));
    // A call out longer than hangS cuts the device off. Counted from when the worker went into
    // the plugin: a worker not yet scheduled is the machine's lateness, not the plugin's.
    if (!d.cut && d.inCall && Clock::now() - d.callStart >= hang)
        d.cutOff(fmt::format("{} did not return within {:.1f} ms", d.callName,
                             std::max(d.options.hangS, d.options.deadlineS) * 1e3));
    if (d.cut) {
        d.missed++;
        return {};
    }
    // A read the worker has not started yet (it was late waking) is moved to this tick's time
    // rather than queued behind.
    if (d.posted == d.completed) {
        d.readPending = true;
        ++d.posted;
    }
    d.readNow = now;
    const uint64_t serial = d.posted;
    d.wake.notify_one();
    if (!d.done.wait_until(lock, Clock::now() + deadline, [&] { return d.completed >= serial; })) {
        d.missed++; // zero force this tick; the next read decides whether it hangs
        return {};
    }
    if (d.rc != TREPHINE_DEVICE_OK) {
        d.cutOff(fmt::format("{} failed ({}){}", d.failedCall, d.rc, d.pluginError()));
        d.missed++;
        return {};
    }
    const TrephineDevicePose& p = d.pose;
    DeviceState s;
    s.pose.position = glm::vec3(p.position_mm[0], p.position_mm[1], p.position_mm[2]);
    s.pose.orientation =
        glm::normalize(glm::quat(float(p.orientation[0]), float(p.orientation[1]),
                                 float(p.orientation[2]), float(p.orientation[3])));
    s.buttons = p.buttons;
    s.valid = std::isfinite(s.pose.position.x) && std::isfinite(s.pose.position.y) &&
              std::isfinite(s.pose.position.z) && std::isfinite(s.pose.orientation.w);
    if (!s.valid) {
        d.cutOff("read returned a pose that is not finite");
        return {};
    }
    d.history.push_back({now, s.pose.position, glm::vec3(d.applied)});
    if (d.history.size() > 8192)
        d.history.pop_front();
    return s;
}

void PluginDevice::setForce(glm::vec3 f) {
    Impl& d = *m_impl;
    std::lock_guard lock(d.mutex);
    if (d.cut)
        return;
    d.force = glm::dvec3(f);
    d.lastWritten = d.force;
    d.writePending = true;
    d.wake.notify_one();
}

// [SECTION] loading

namespace {

// "PATH?ARGS" -> PATH, ARGS.
std::pair<std::string, std::string> splitSpec(const std::string& spec) {
    const size_t q = spec.find('?');
    if (q == std::string::npos)
        return {spec, {}};
    return {spec.substr(0, q), spec.substr(q + 1)};
}

} // namespace

bool loadPlugin(const std::string& path, const std::string& args, LoadedPlugin& out,
                std::string& error) {
    if (path.empty()) {
        error = "device plugin: no file given (plugin:PATH.so)";
        return false;
    }
    // A path without a slash would be searched for along the library path, not in the directory
    // the user means.
    const std::string file = path.find('/') == std::string::npos ? "./" + path : path;
    void* library = dlopen(file.c_str(), RTLD_NOW | RTLD_LOCAL);
    if (!library) {
        error = fmt::format("device plugin {}: cannot load it: {}", path, dlerror());
        return false;
    }
    auto fail = [&](const std::string& why) {
        error = fmt::format("device plugin {}: {}", path, why);
        dlclose(library);
        return false;
    };
    auto entry = reinterpret_cast<TrephineDeviceEntry>(dlsym(library, TREPHINE_DEVICE_ENTRY));
    if (!entry)
        return fail(fmt::format("no {} entry point (is it a Trephine device plugin?)",
                                TREPHINE_DEVICE_ENTRY));
    const TrephineDeviceApi* api = entry(TREPHINE_DEVICE_ABI_VERSION);
    if (!api)
        return fail(
            fmt::format("it does not serve device ABI version {}", TREPHINE_DEVICE_ABI_VERSION));
    if (api->abi_version != TREPHINE_DEVICE_ABI_VERSION ||
        api->struct_size < offsetof(TrephineDeviceApi, applied_force))
        return fail(fmt::format("it was built for device ABI version {}, this is version {}",
                                api->abi_version, TREPHINE_DEVICE_ABI_VERSION));
    if (!api->open || !api->close || !api->info || !api->read || !api->write_force)
        return fail("its function table lacks open, close, info, read or write_force");
    // Optional entries past the plugin's own table are absent.
    LoadedPlugin p;
    p.library = library;
    std::memcpy(&p.api, api, std::min<size_t>(api->struct_size, sizeof p.api));
    char why[256] = "";
    p.device = p.api.open(args.c_str(), why, sizeof why);
    if (!p.device) {
        why[sizeof why - 1] = 0;
        return fail(fmt::format("open failed: {}", why[0] ? why : "no reason given"));
    }
    auto lastError = [&] {
        const char* e = p.api.last_error ? p.api.last_error(p.device) : nullptr;
        return e && *e ? std::string(": ") + e : std::string();
    };
    if (const int r = p.api.info(p.device, &p.info); r != TREPHINE_DEVICE_OK) {
        const std::string why = fmt::format("info failed ({}){}", r, lastError());
        p.api.close(p.device);
        return fail(why);
    }
    p.info.name[sizeof p.info.name - 1] = 0;
    if (!(p.info.max_force_n > 0.0)) {
        p.api.close(p.device);
        return fail("it reports no maximum force");
    }
    out = p;
    return true;
}

void unloadPlugin(LoadedPlugin& p) {
    if (p.device)
        p.api.close(p.device);
    if (p.library)
        dlclose(p.library);
    p = {};
}

std::unique_ptr<PluginDevice> openPlugin(const std::string& spec, const PluginOptions& options,
                                         std::string& error) {
    auto [path, args] = splitSpec(spec);
    auto d = std::make_shared<PluginDevice::Impl>();
    d->path = path;
    d->options = options;
    if (d->options.args.empty())
        d->options.args = args;
    LoadedPlugin p;
    if (!loadPlugin(path, d->options.args, p, error))
        return nullptr;
    d->library = p.library;
    d->table = p.api;
    d->api = &d->table;
    d->device = p.device;
    d->info = p.info;
    d->worker = std::thread([d] { d->run(); });
    return std::unique_ptr<PluginDevice>(new PluginDevice(d));
}

std::unique_ptr<Device> openPluginDevice(const std::string& path, std::string& error) {
    return openPlugin(path, {}, error);
}

} // namespace trephine

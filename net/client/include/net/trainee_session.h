// A trainee's session from join to the end, for the shells that run one without a window (the
// headless trainee, the demo): join, the scene, a preset and the view, the picture, a script, the
// lift and the drain. Each step waits for what the server sends and throws trephine::Error, one
// line naming the server and what did not come. The client half only: no server header.
#pragma once

#include "libsim/camera.h"
#include "libsim/device.h"
#include "net/scene.h"
#include "net/session_client.h"
#include "net/trainee_core.h"

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

namespace trephine::net {

struct TraineeSessionConfig {
    std::string address = "127.0.0.1:7777"; // HOST:PORT, named in every failure
    // Name, code, role, codecs and design; its view is the hello's (a 1x1 placeholder until the
    // scene gives a preset, unless the shell knows its camera already, as the demo does).
    ClientConfig client;
    int size = 500;            // the picture's side, pixels (square)
    double toolRateHz = 100.0; // tool states a second from the haptic loop
    double connectTimeoutS = 10.0;
    std::string who = "trainee"; // each failure's line starts "WHO: "
};

// How a session ended: the script ran out, the caller's go() stopped it (the headless trainee's:
// a signal), the server closed it or went silent. elapsedS runs from the script's start to the
// end of the drain.
struct SessionEnd {
    enum class How { ScriptDone, Stopped, Closed, Lost };
    How how = How::ScriptDone;
    double elapsedS = 0;
    std::string reason; // Closed: why the server closed it
};

class TraineeSession {
public:
    // Silence after which the server counts as lost: it answers the client thread's pings within
    // milliseconds, and a server killed or cut off sends no goodbye (ENet notices after 5-30 s).
    static constexpr uint64_t kServerSilenceUs = 3'000'000;

    explicit TraineeSession(TraineeSessionConfig config);
    ~TraineeSession();
    TraineeSession(const TraineeSession&) = delete;
    TraineeSession& operator=(const TraineeSession&) = delete;

    // [Steps, in order] join() connects (once) and waits for the welcome; awaitScene() for the
    // scene that follows it; openPreset() asks for the scene's preset view at the session's size
    // and waits for its whole picture (openView: a camera of the caller's).
    const Welcome& join(double timeoutS = 15.0);
    const ReceivedScene& awaitScene(double timeoutS = 10.0);
    Camera openPreset(const std::string& preset, double timeoutS = 30.0);
    void openView(const Camera& camera, double timeoutS = 30.0);
    // `--script burrhole` at the scene's default burr site, for `durationS` (net/scripts.h).
    std::vector<ScriptSample> burrhole(double durationS) const;
    // Starts the haptic loop on `script`, played by `device` (a device following the rows' poses,
    // e.g. a ScriptedDevice), drilling until `endS`. Once.
    void play(std::vector<ScriptSample> script, double endS, std::unique_ptr<Device> device);
    // Takes the client's news until the script's end, the link's close, the server's silence or
    // `go(t)` (t: s since the script started) answers false: the caller's stop.
    void drill(const std::function<bool(double)>& go = {});
    // Stops the loop, lifts the tool (the last row, drilling off) and drains: waits until the
    // server has answered the lift (the force model for it has come back) and then `quietS` has
    // passed without an update, `maxS` at most (others drilling on would keep it waiting).
    void liftAndDrain(double quietS = 0.5, double maxS = 2.0);
    // Stops the core (the figures stay readable) and says how the session ended.
    SessionEnd finish();
    // A stop asked for after the script (during the drain) ends the session as Stopped too.
    void noteStopped() { m_stopped = true; }
    // The line a shell prints for an end that is not ScriptDone ("" for one that is).
    std::string endText(const SessionEnd& end) const;

    // [Parts] For a shell's own waits and figures.
    void connect(); // starts the client thread (join() calls it)
    bool waitFor(double seconds, const std::function<bool()>& pred) {
        return m_view.waitFor(m_core.client(), seconds, pred);
    }
    void take() { m_view.take(m_core.client(), m_core.hapticStats().ticks); }
    TraineeCore& core() { return m_core; }
    const TraineeCore& core() const { return m_core; }
    const HeadlessView& view() const { return m_view; }
    const ClientModel& model() const { return m_view.model; }
    const ClientSnapshot& snap() const { return *m_view.snap(); }
    const TraineeSessionConfig& config() const { return m_config; }
    bool closed() const { return !m_view.connected(); }
    // Connected, yet nothing heard for kServerSilenceUs (counted from the script's start at the
    // earliest).
    bool serverLost() const;

private:
    [[noreturn]] void fail(const std::string& what) const;

    TraineeSessionConfig m_config;
    // The script's tools outlive the core, whose haptic loop reads them.
    std::unique_ptr<Device> m_device;
    std::unique_ptr<ScriptToolSource> m_tools;
    std::vector<ScriptSample> m_script;
    TraineeCore m_core;
    HeadlessView m_view;
    bool m_connected = false;
    bool m_stopped = false; // go() said stop
    uint64_t m_startUs = 0; // the script's start (0: not yet)
    uint64_t m_endUs = 0;   // the script's end
};

} // namespace trephine::net

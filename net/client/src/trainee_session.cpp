#include "net/trainee_session.h"

#include "libsim/error.h"
#include "net/codec.h"
#include "net/net_stats.h"
#include "net/scripts.h"
#include "net/view.h"

#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <thread>

namespace trephine::net {

namespace {

TraineeCoreConfig coreConfigOf(const TraineeSessionConfig& c) {
    TraineeCoreConfig core;
    core.client.client = c.client;
    core.client.address = c.address;
    core.client.connectTimeoutS = c.connectTimeoutS;
    core.client.retryS = 3600.0; // one connection: a lost link ends the session
    core.haptics.sendRateHz = c.toolRateHz;
    return core;
}

} // namespace

TraineeSession::TraineeSession(TraineeSessionConfig config)
    : m_config(std::move(config)), m_core(coreConfigOf(m_config)), m_view(m_config.size) {}

TraineeSession::~TraineeSession() {
    m_core.stop();
}

void TraineeSession::fail(const std::string& what) const {
    throw Error(m_config.who + ": " + what);
}

void TraineeSession::connect() {
    if (!m_connected)
        m_core.connect();
    m_connected = true;
}

bool TraineeSession::serverLost() const {
    return m_view.connected() &&
           steadyNowUs() - std::max(snap().lastHeardUs, m_startUs) > kServerSilenceUs;
}

// [SECTION] steps

const Welcome& TraineeSession::join(double timeoutS) {
    connect();
    const std::string& server = m_config.address;
    if (!waitFor(timeoutS, [&] { return m_view.connected(); })) {
        // The client ended it over a malformed message of the server's: its reason names the
        // server and the message ("HOST sent a malformed scene (...)").
        const std::string& reason = snap().closeReason;
        if (reason.empty())
            fail("no answer from " + server + " (is `trephine server` running?)");
        if (snap().fault || reason.rfind("no answer", 0) == 0)
            fail(reason);
        fail(server + " refused us: " + reason);
    }
    return *snap().welcome;
}

const ReceivedScene& TraineeSession::awaitScene(double timeoutS) {
    // The scene follows the welcome on the same reliable channel: presets and the burr site come
    // from the server, so a trainee needs its address only (it never opens a volume).
    if (!waitFor(timeoutS, [&] { return snap().scene != nullptr; })) {
        const std::string& reason = snap().closeReason;
        if (snap().fault)
            fail(reason);
        fail(m_config.address + " sent no scene after its welcome" +
             (reason.empty() ? std::string() : ": " + reason));
    }
    return *snap().scene;
}

Camera TraineeSession::openPreset(const std::string& preset, double timeoutS) {
    const int size = m_config.size;
    const std::optional<Camera> camera = presetCamera(awaitScene(0.0).scene, preset, {size, size});
    if (!camera)
        fail("the server's scene has no camera preset '" + preset + "'");
    openView(*camera, timeoutS);
    return *camera;
}

// A view the server does not serve (too large, or the session's views full) fails at once, in the
// window's words: it would otherwise run on and report the 1x1 placeholder as its picture.
void TraineeSession::openView(const Camera& camera, double timeoutS) {
    m_core.client().requestView(toViewSpec(camera));
    std::string notServed;
    const bool done = waitFor(timeoutS, [&] {
        notServed = viewNotServedText(snap(), camera.width, camera.height, "--size");
        return m_view.hasPicture() || !notServed.empty();
    });
    if (!notServed.empty())
        fail(notServed);
    if (done)
        return;
    const ClientSnapshot& s = snap();
    const std::string from = "no image from " + m_config.address;
    if (s.fault)
        fail(s.closeReason);
    if (!s.closeReason.empty())
        fail(from + ": " + s.closeReason);
    if (s.malformedImages > 0)
        fail(from + ": the server's images were malformed (" + std::to_string(s.malformedImages) +
             " dropped)");
    fail(from + " in " + fmt::format("{:g}", timeoutS) + " s");
}

std::vector<ScriptSample> TraineeSession::burrhole(double durationS) const {
    const std::shared_ptr<const ReceivedScene>& scene = snap().scene;
    const SceneSite* site = scene ? findSite(scene->scene, kDefaultSiteName) : nullptr;
    if (!site)
        fail("the server's scene has no burr site for the burrhole script");
    return burrholeScript({site->position, site->normal}, durationS);
}

void TraineeSession::play(std::vector<ScriptSample> script, double endS,
                          std::unique_ptr<Device> device) {
    if (script.empty())
        throw Error(m_config.who + ": an empty script: nothing to drill");
    m_script = std::move(script);
    m_device = std::move(device);
    m_tools = std::make_unique<ScriptToolSource>(*m_device, m_script, endS);
    m_core.startHaptics(*m_tools);
    m_startUs = steadyNowUs();
    m_endUs = m_startUs + uint64_t(endS * 1e6);
}

void TraineeSession::drill(const std::function<bool(double)>& go) {
    while (steadyNowUs() < m_endUs && !closed() && !serverLost()) {
        take();
        if (go && !go(double(steadyNowUs() - m_startUs) * 1e-6)) {
            m_stopped = true;
            break;
        }
        std::this_thread::sleep_for(std::chrono::milliseconds(2));
    }
}

void TraineeSession::liftAndDrain(double quietS, double maxS) {
    m_core.stopHaptics();
    if (closed() || serverLost() || m_script.empty())
        return;
    ToolState lift = m_script.back().tool; // drilling off, where the script ends
    lift.speed = 0.0f;
    lift.drilling = false;
    lift.clientTimeUs = steadyNowUs(); // its force model echoes it: the server has the lift
    m_core.client().sendToolState(lift);
    const uint64_t until = steadyNowUs() + uint64_t(maxS * 1e6);
    uint64_t count = snap().updatesApplied, quietSince = steadyNowUs();
    bool answered = false;
    while (!closed() && !serverLost() && steadyNowUs() < until) {
        std::this_thread::sleep_for(std::chrono::milliseconds(5));
        take();
        const ClientSnapshot& s = snap();
        answered = answered || (s.hapticModel && s.hapticModel->clientTimeUs >= lift.clientTimeUs);
        if (s.updatesApplied != count) {
            count = s.updatesApplied;
            quietSince = steadyNowUs();
        }
        // Every tool state before the lift is in the server's queue once the lift is answered:
        // the updates they cause follow within a quiet spell.
        if (answered && steadyNowUs() - quietSince >= uint64_t(quietS * 1e6))
            break;
    }
}

SessionEnd TraineeSession::finish() {
    SessionEnd end;
    end.elapsedS = m_startUs ? double(steadyNowUs() - m_startUs) * 1e-6 : 0.0;
    if (closed()) {
        end.how = SessionEnd::How::Closed;
        end.reason = snap().closeReason;
    } else if (serverLost()) {
        end.how = SessionEnd::How::Lost;
    } else if (m_stopped) {
        end.how = SessionEnd::How::Stopped;
    }
    m_core.stop();
    return end;
}

std::string TraineeSession::endText(const SessionEnd& end) const {
    const std::string& who = m_config.who;
    switch (end.how) {
    case SessionEnd::How::ScriptDone:
        return {};
    case SessionEnd::How::Closed:
        return who + ": the server closed the session: " + end.reason;
    case SessionEnd::How::Lost:
        return fmt::format("{}: lost the server {}: nothing heard for {:.0f} s (killed, crashed or "
                           "cut off), {:.1f} s into the script",
                           who, m_config.address, double(kServerSilenceUs) * 1e-6, end.elapsedS);
    case SessionEnd::How::Stopped:
        return fmt::format("{}: stopped by a signal {:.1f} s into the script", who, end.elapsedS);
    }
    return {};
}

} // namespace trephine::net

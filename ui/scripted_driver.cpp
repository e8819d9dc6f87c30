#include "ui/scripted_driver.h"

#include "libsim/error.h"
#include "ui/panel_data.h"
#include "ui/trainer_app.h"
#include "ui/window.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>

namespace trephine::ui {

net::Annotate parseMark(const std::string& text) {
    const std::string where = "--mark '" + text + "'";
    const size_t colon = text.find(':');
    const std::string coords = text.substr(0, colon);
    net::Annotate a;
    a.op = net::Annotate::Op::Add;
    a.label = colon == std::string::npos ? std::string() : text.substr(colon + 1);
    if (a.label.size() > net::kMaxNameLength)
        throw Error(where + ": the label is longer than " + std::to_string(net::kMaxNameLength) +
                    " bytes");
    float v[3];
    const char* p = coords.c_str();
    for (int i = 0; i < 3; ++i) {
        char* end = nullptr;
        v[i] = std::strtof(p, &end);
        const char want = i < 2 ? ',' : '\0';
        if (end == p || *end != want || !std::isfinite(v[i]) ||
            std::abs(v[i]) > net::kMaxAnnotationDistanceMm)
            throw Error(where + ": expected X,Y,Z[:LABEL] with X, Y, Z in mm");
        p = end + (i < 2 ? 1 : 0);
    }
    a.position = {v[0], v[1], v[2]};
    return a;
}

ScriptedDriver::ScriptedDriver(const TrainerOptions& o)
    : m_address(o.address), m_screenshot(o.screenshot), m_takeOverName(o.takeOver),
      m_viewAsName(o.viewAs), m_frames(o.frames), m_timeoutS(o.timeoutS),
      m_burrhole(o.script == "burrhole"), m_scriptDone(o.script.empty()),
      m_switchAtS(o.switchSyncAtS), m_takeOver{o.takeOver} {
    if (!o.marks.empty() && !o.instructor)
        throw Error("window: --mark: only an instructor places marks");
    for (const std::string& m : o.marks)
        m_marks.push_back(parseMark(m));
    m_marksSent = m_marks.empty();
    if (!o.takeOver.empty() && !o.instructor)
        throw Error("window: --take-over: only an instructor takes over a trainee");
}

bool ScriptedDriver::ignoresPointer() const {
    return !m_screenshot.empty() && m_burrhole;
}

net::ScriptPose ScriptedDriver::tool(const SurfaceSite& site, double now) {
    if (m_scriptStart < 0)
        m_scriptStart = now;
    const net::ScriptPose p = net::burrholePose(site, now - m_scriptStart);
    if (p.done && !m_scriptDone) {
        m_scriptDone = true;
        m_justDone = true;
    }
    return p;
}

bool ScriptedDriver::toolJustDone() {
    const bool done = m_justDone;
    m_justDone = false;
    return done;
}

std::optional<net::SyncDesign> ScriptedDriver::switchDue(double now, double firstPictureAt,
                                                         bool switching, net::SyncDesign wanted) {
    if (m_nextSwitch >= m_switchAtS.size() || firstPictureAt < 0 || switching ||
        now - firstPictureAt < m_switchAtS[m_nextSwitch])
        return std::nullopt;
    ++m_nextSwitch;
    return wanted == net::SyncDesign::Dbi ? net::SyncDesign::Volume : net::SyncDesign::Dbi;
}

void ScriptedDriver::sendDue(const net::ClientSnapshot& snap, net::ClientThread& client) {
    if (!snap.welcome || snap.state != net::LinkState::Connected)
        return;
    if (!m_marksSent) {
        for (const net::Annotate& a : m_marks)
            client.annotate(a);
        m_marksSent = true;
    }
    // Once per connection: the server hands a trainee back when its instructor leaves.
    if (const auto id = m_takeOver.due(snap.attempts, snap.participants))
        client.takeOver(*id);
}

bool ScriptedDriver::settled(const Frame& f) const {
    // Connected too: a picture kept from before a lost link is not the session's now.
    return f.snap->state == net::LinkState::Connected && f.havePicture && f.viewMatches &&
           f.haveScene && m_scriptDone && !f.pointerBusy && !f.switching &&
           m_nextSwitch == m_switchAtS.size() && !f.snap->waitingForView &&
           f.sinceLastUpdateS > 0.5 && m_marksSent && (m_takeOverName.empty() || f.holding != 0) &&
           (m_viewAsName.empty() || f.snap->viewingAs != 0) &&
           f.snap->annotations.size() >= m_marks.size();
}

bool ScriptedDriver::abortsBeforeEnd(const Frame& f) {
    ++m_frameCount;
    if (f.viewNotServed.empty() || !scripted())
        return false;
    std::fprintf(stderr, "trephine: %s\n", f.viewNotServed.c_str());
    m_exitCode = 1;
    m_ended = true;
    return true;
}

bool ScriptedDriver::wantsCapture(const Frame& f, double now) {
    m_settledFrames = settled(f) ? m_settledFrames + 1 : 0;
    m_shoot = !m_screenshot.empty() && m_settledFrames >= std::max(m_frames, 1);
    m_timedOut = !m_screenshot.empty() && now > m_timeoutS;
    return m_shoot || m_timedOut;
}

bool ScriptedDriver::afterFrame(const Frame& f, double now, const Dbi& capture) {
    const net::ClientSnapshot& snap = *f.snap;
    if (m_shoot || m_timedOut) {
        writeScreenshot(m_screenshot, capture);
        if (m_timedOut) {
            // What the view was still waiting for, where the script asked for something.
            std::string waiting = net::linkStateName(snap.state);
            if (!m_takeOverName.empty() && f.holding == 0)
                waiting += "; --take-over: no trainee '" + m_takeOverName + "' taken over";
            if (!m_marksSent || snap.annotations.size() < m_marks.size())
                waiting += "; --mark: the marks not listed yet";
            std::fprintf(stderr,
                         "trephine: screenshot %s taken after %.0f s without a settled view "
                         "(%s)\n",
                         m_screenshot.c_str(), now, waiting.c_str());
            m_exitCode = 1;
        } else {
            std::printf("screenshot %s (%dx%d) after %d frames\n", m_screenshot.c_str(),
                        capture.width(), capture.height(), m_frameCount);
        }
        m_ended = true;
        return true;
    }
    // --frames without a screenshot: that many frames showing the picture while connected, or,
    // with none by --timeout (or none for --timeout after the last), a failure in one line.
    if (!m_screenshot.empty() || m_frames <= 0)
        return false;
    if (snap.state == net::LinkState::Connected && f.havePicture && f.viewMatches) {
        ++m_pictureFrames;
        m_lastPictureFrameAt = now;
    }
    if (m_pictureFrames >= m_frames) {
        m_ended = true;
        return true;
    }
    if (m_pictureFrames == 0 && now > m_timeoutS) {
        std::fprintf(stderr, "trephine: no picture from %s after %.0f s (%s)\n", m_address.c_str(),
                     now, net::linkStateName(snap.state));
        m_exitCode = 1;
        m_ended = true;
        return true;
    }
    if (m_pictureFrames > 0 && now - m_lastPictureFrameAt > m_timeoutS) {
        std::fprintf(stderr,
                     "trephine: no picture from %s for %.0f s after %d of %d frames (%s: %s)\n",
                     m_address.c_str(), now - m_lastPictureFrameAt, m_pictureFrames, m_frames,
                     net::linkStateName(snap.state),
                     snap.closeReason.empty() ? "no reason given" : snap.closeReason.c_str());
        m_exitCode = 1;
        m_ended = true;
        return true;
    }
    return false;
}

void ScriptedDriver::closed() {
    // A script must not read exit 0 as done: the PNG it waits for is not there.
    if (m_ended || !scripted())
        return;
    std::fprintf(stderr, "trephine: the window was closed before %s\n",
                 m_screenshot.empty() ? "its --frames were drawn"
                                      : ("the screenshot " + m_screenshot).c_str());
    m_exitCode = 1;
}

} // namespace trephine::ui

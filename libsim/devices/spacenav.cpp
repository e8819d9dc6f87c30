#include "libsim_devices/spacenav.h"

#include "libsim/error.h"

#ifdef TREPHINE_HAVE_SPNAV
#include <spnav.h>
#endif

namespace trephine {

#ifdef TREPHINE_HAVE_SPNAV

const bool kHaveSpaceNav = true;

namespace {

// libspnav keeps one connection per process.
class SpaceNavSource : public SpaceMouseSource {
public:
    SpaceNavSource() {
        char buf[128] = {};
        if (spnav_dev_name(buf, sizeof buf) > 0)
            m_name = std::string(buf) + " (spacenavd)";
    }
    ~SpaceNavSource() override { spnav_close(); }
    std::string name() const override { return m_name; }
    bool poll(SpaceMouseParser& parser) override {
        spnav_event ev;
        for (int i = 0; i < 64; ++i) { // bounded, as the HID source
            const int type = spnav_poll_event(&ev);
            if (type == 0)
                break;
            if (type == SPNAV_EVENT_MOTION) {
                const auto t = spnavTranslationReport(ev.motion.x, ev.motion.y, ev.motion.z);
                const auto r = spnavRotationReport(ev.motion.rx, ev.motion.ry, ev.motion.rz);
                parser.feed(t);
                parser.feed(r);
            } else if (type == SPNAV_EVENT_BUTTON && ev.button.bnum >= 0 && ev.button.bnum < 32) {
                const uint32_t bit = 1u << ev.button.bnum;
                m_buttons = ev.button.press ? (m_buttons | bit) : (m_buttons & ~bit);
                parser.feed(spaceMouseButtonReport(m_buttons));
            }
        }
        // A daemon that went away closes the socket; libspnav then has no descriptor.
        return spnav_fd() >= 0;
    }

private:
    std::string m_name = "SpaceMouse (spacenavd)";
    uint32_t m_buttons = 0;
};

} // namespace

bool spaceNavRunning(std::string* why) {
    if (spnav_open() == -1) {
        if (why)
            *why = "does not answer (is it running?)";
        return false;
    }
    spnav_close();
    return true;
}

std::unique_ptr<SpaceMouseSource> openSpaceNav() {
    if (spnav_open() == -1)
        throw Error("spacenavd does not answer: start it (systemctl start spacenavd), or use "
                    "spacemouse:hid");
    return std::make_unique<SpaceNavSource>();
}

#else

const bool kHaveSpaceNav = false;

bool spaceNavRunning(std::string* why) {
    if (why)
        *why = "this trephine was built without libspnav (install libspnav-dev and rebuild)";
    return false;
}

std::unique_ptr<SpaceMouseSource> openSpaceNav() {
    throw Error("this trephine was built without libspnav (install libspnav-dev and rebuild), "
                "or use spacemouse:hid");
}

#endif

} // namespace trephine

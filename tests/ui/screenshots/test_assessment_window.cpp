// `trephine instructor` windowed against an in-process server while an in-process trainee holds
// its burr on the dura: the server warns the instructor (a violation), the instructor's banner
// takes the zone's colour across the top of the view and its Assessment panel shows the
// trainee's zone beside the figures. Needs a display (xvfb-run).
#include "gl_window_test.h"
#include "ui/panels.h"
#include "ui/window.h"

#include "libsim/skull.h"
#include "net/session_client.h"
#include "net/session_server.h"

#include "loopback.h"
#include "screenshot.h"
#include "test_support.h"

#include <gtest/gtest.h>

#include <atomic>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <thread>

using namespace trephine;

using trephine::testing::Image;
using trephine::testing::readPng;
using trephine::testing::shellQuote;

namespace {

// The first soft-tissue voxel down the middle column: under the vault.
glm::vec3 underTheVault(const Volume& v) {
    const glm::ivec3 d = v.dims();
    for (int z = d.z - 1; z >= 0; --z)
        if (isSoftTissue(v.material(d.x / 2, d.y / 2, z)))
            return v.voxelCenter({d.x / 2, d.y / 2, z});
    return glm::vec3(0.0f);
}

} // namespace

TEST(AssessmentWindow, TheInstructorSeesTheViolationInTheBannerAndThePanel) {
    TREPHINE_NEED_DISPLAY("the instructor window");
    Volume skull = makeSkull(64);
    const glm::vec3 onDura = underTheVault(skull);
    net::ServerConfig sc;
    sc.port = 0;
    sc.volumeName = "skull:64";
    sc.renderThreads = 1;
    net::SessionServer server(skull, sc);
    server.start(); // its own threads: the violation must reach the window within its 90 frames,
                    // however loaded the machine
    const std::string address = "127.0.0.1:" + std::to_string(server.port());

    net::ClientConfig tc;
    tc.name = "Ada";
    tc.view.width = tc.view.height = 32;
    net::SessionClient ada(tc);
    ada.connect(net::parseAddress(address));
    std::atomic<bool> stop{false};
    std::atomic<bool> warned{false};
    std::thread trainee([&] {
        while (!stop) {
            ada.poll(5);
            if (!ada.welcomed())
                continue;
            net::ToolState t;
            t.diameterMm = 4.0f;
            t.position = onDura;
            ada.sendToolState(t);
            auto w = ada.warnings().find(ada.welcome().clientId);
            if (w != ada.warnings().end() && w->second.zone == net::Zone::Violation)
                warned = true;
        }
        ada.disconnect();
    });

    const std::string out =
        (std::filesystem::temp_directory_path() / "trephine_assessment.png").string();
    std::filesystem::remove(out);
    const std::string cmd = shellQuote(TREPHINE_BIN) + " instructor --connect " + address +
                            " --name Cho --window-size 500 --screenshot " + shellQuote(out) +
                            " --frames 90 --timeout 80 > " + shellQuote(out + ".log") + " 2>&1";
    const int rc = std::system(cmd.c_str());
    stop = true;
    trainee.join();
    server.stop();
    ASSERT_EQ(rc, 0) << cmd;
    EXPECT_TRUE(warned.load()) << "the trainee heard of its own violation";

    // The violation's colour, exactly: the banner's fill in the view, the Assessment panel's
    // swatch in the right-hand column, the Session panel's zone line in the middle one.
    const glm::vec4 c = ui::zoneColor(net::Zone::Violation);
    const int r = int(c.r * 255.0f + 0.5f), g = int(c.g * 255.0f + 0.5f),
              b = int(c.b * 255.0f + 0.5f);
    Image img = readPng(out);
    int banner = 0, panel = 0, badge = 0, elsewhere = 0;
    for (int y = 0; y < img.h; ++y)
        for (int x = 0; x < img.w; ++x) {
            const uint8_t* p = img.at(x, y);
            if (p[0] != r || p[1] != g || p[2] != b)
                continue;
            if (x < 500 && y < 60)
                ++banner;
            else if (x >= 500 + 380)
                ++panel;
            else if (x >= 500 && y < 280)
                ++badge;
            else
                ++elsewhere;
        }
    EXPECT_GT(banner, 5000) << "the banner across the top of the view";
    EXPECT_GT(panel, 50) << "the Assessment panel's zone swatch";
    EXPECT_GT(badge, 20) << "the Session panel's zone line under Ada's row";
    EXPECT_LT(elsewhere, 200) << "nowhere much else";
}

// `trephine trainee` windowed against an in-process server while an in-process instructor takes
// it over: the trainee's screenshot says so on the solid band at the foot of its view. Needs a
// display (xvfb-run).
#include "gl_window_test.h"
#include "ui/window.h"

#include "libsim/skull.h"
#include "net/session_client.h"
#include "net/session_server.h"

#include "loopback.h"
#include "screenshot.h"
#include "test_support.h"

#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <thread>

using namespace trephine;

using trephine::testing::Image;
using trephine::testing::readPng;
using trephine::testing::shellQuote;

TEST(TakeOverWindow, TheTraineeIsToldItsDrillIsPaused) {
    TREPHINE_NEED_DISPLAY("the trainee window");
    Volume skull = makeSkull(64);
    net::ServerConfig sc;
    sc.port = 0;
    sc.volumeName = "skull:64";
    sc.renderThreads = 1;
    net::SessionServer server(skull, sc);
    server.start(); // its own threads: the take-over must reach the window within its 20 frames,
                    // however loaded the machine
    const std::string address = "127.0.0.1:" + std::to_string(server.port());

    // The instructor takes over the trainee called Ada as soon as the roster lists her.
    net::ClientConfig ic;
    ic.name = "Dr Cho";
    ic.role = net::Role::Instructor;
    ic.view.width = ic.view.height = 32;
    net::SessionClient cho(ic);
    cho.connect(net::parseAddress(address));
    std::atomic<bool> stop{false};
    std::atomic<uint16_t> held{0}; // whom the roster says Dr Cho holds
    std::thread instructor([&] {
        bool asked = false;
        while (!stop) {
            cho.poll(1);
            if (!cho.welcomed())
                continue;
            for (const auto& [id, p] : cho.participants()) {
                if (p.role == net::Role::Trainee && p.name == "Ada" && !asked) {
                    cho.takeOver(id);
                    asked = true;
                }
                if (p.takenOverBy == cho.welcome().clientId)
                    held = id;
            }
        }
        cho.disconnect();
    });

    const std::string out =
        (std::filesystem::temp_directory_path() / "trephine_taken_over.png").string();
    std::filesystem::remove(out);
    const std::string cmd = shellQuote(TREPHINE_BIN) + " trainee --connect " + address +
                            " --name Ada --size 500 --screenshot " + shellQuote(out) +
                            " --frames 20 --timeout 80 > " + shellQuote(out + ".log") + " 2>&1";
    const int rc = std::system(cmd.c_str());
    stop = true;
    instructor.join();
    server.stop();
    ASSERT_EQ(rc, 0) << cmd;
    EXPECT_NE(held.load(), 0) << "the server listed the take-over";

    // The band (opaque, IM_COL32(112, 40, 150)) near the foot of the 500 x 500 view.
    Image img = readPng(out);
    int band = 0, bandHigh = 0;
    for (int y = 0; y < 500; ++y)
        for (int x = 0; x < 500; ++x) {
            const uint8_t* p = img.at(x, y);
            if (p[0] == 112 && p[1] == 40 && p[2] == 150)
                (y >= 420 ? band : bandHigh) += 1;
        }
    EXPECT_GT(band, 3000) << "the taken-over band at the foot of the view";
    EXPECT_EQ(bandHigh, 0) << "and nowhere else";
}

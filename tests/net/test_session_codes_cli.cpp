// `trephine server` as a user runs it: a new code an instructor issues is printed on stdout in
// one line, like the start banner, naming who issued it (docs/security.md, "New codes").
#include "net/session_client.h"
#include "net/session_codes.h"

#include "libsim/skull.h"

#include "child_process.h"
#include "loopback.h"

#include <gtest/gtest.h>

#include <chrono>
#include <csignal>

using namespace trephine;
using namespace trephine::net;

TEST(SessionCodesCli, TheServerPrintsANewCodeInOneLineNamingWhoIssuedIt) {
    trephine::testing::Child server({"server", "--port", "0", "--volume", "sphere:32",
                                     "--render-threads", "1", "--trainee-code", "QX7M-4KTD",
                                     "--instructor-code", "HW2R-9PZE"});
    const int port = server.port();
    ASSERT_GT(port, 0);
    ClientConfig c =
        trephine::testing::namedClientConfig(makeSphere(32), "Dr. Cho", Role::Instructor, 32);
    c.code = "HW2R-9PZE";
    SessionClient cho(c);
    cho.connect(trephine::testing::loopback(uint16_t(port)));
    auto pollUntil = [&](auto done) {
        const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(60);
        while (!done() && !cho.closed() && std::chrono::steady_clock::now() < deadline)
            cho.poll(1);
        return done();
    };
    ASSERT_TRUE(pollUntil([&] { return cho.codes().has_value(); })) << cho.closeReason();
    EXPECT_EQ(cho.codes()->trainee, "QX7M-4KTD");
    cho.newCode(Role::Trainee);
    ASSERT_TRUE(pollUntil([&] { return cho.codes()->trainee != "QX7M-4KTD"; }));
    const std::string line = server.waitFor("new trainee code");
    EXPECT_EQ(line, "trephine server: " +
                        codeIssuedLine(Role::Trainee, cho.codes()->trainee, "Dr. Cho") + "\n");
    EXPECT_EQ(server.end(SIGTERM), 0);
}

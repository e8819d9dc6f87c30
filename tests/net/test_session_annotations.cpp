// Instructors' marks on the skull (Annotate, Annotations) over loopback: an instructor adds,
// removes and clears marks and every participant, a late joiner included, holds the same list;
// a trainee's edits and adds beyond the limit are refused (counted, not applied); malformed
// messages are dropped and counted. Deadlines only guard against hangs.
#include "net/session_client.h"
#include "net/session_server.h"

#include "libsim/skull.h"

#include "loopback.h"

#include <gtest/gtest.h>

using namespace trephine;
using namespace trephine::net;

using trephine::testing::loopback;
using trephine::testing::loopbackServerConfig;
using trephine::testing::namedClientConfig;
using trephine::testing::pumpUntil;

namespace {

Annotate add(glm::vec3 p, const std::string& label) {
    Annotate a;
    a.op = Annotate::Op::Add;
    a.position = p;
    a.label = label;
    return a;
}

} // namespace

TEST(Annotations, MessagesRoundTripAndRejectBadFields) {
    Annotate a = add({1.5f, -2.0f, 30.0f}, "burr hole here");
    Annotate back;
    ASSERT_TRUE(decodeMessage(encodeMessage(a), back));
    EXPECT_EQ(back.position, a.position);
    EXPECT_EQ(back.label, a.label);
    Annotate far = add({2.0e5f, 0, 0}, "far");
    EXPECT_FALSE(decodeMessage(encodeMessage(far), back)) << "beyond any volume";
    std::vector<uint8_t> bytes = encodeMessage(a);
    bytes[1] = 3; // no fourth operation
    EXPECT_FALSE(decodeMessage(bytes, back));

    Annotations list;
    list.list = {{1, 2, {0, 0, 1}, "one"}, {5, 2, {1, 0, 0}, "two"}};
    Annotations listBack;
    ASSERT_TRUE(decodeMessage(encodeMessage(list), listBack));
    EXPECT_EQ(listBack.list, list.list);
    Annotations unordered = list;
    std::swap(unordered.list[0], unordered.list[1]);
    EXPECT_FALSE(decodeMessage(encodeMessage(unordered), listBack));
    Annotations zero = list;
    zero.list[0].id = 0;
    EXPECT_FALSE(decodeMessage(encodeMessage(zero), listBack));
    std::vector<uint8_t> lb = encodeMessage(list);
    for (size_t n = 1; n < lb.size(); ++n)
        EXPECT_FALSE(decodeMessage(std::span(lb.data(), n), listBack)) << n;
}

TEST(Annotations, InstructorsMarksReachEveryoneAndTraineesAreRefused) {
    Volume sphere = makeSphere(32);
    SessionServer server(sphere, loopbackServerConfig("sphere:32"));
    server.start();
    SessionClient cho(namedClientConfig(sphere, "Dr. Cho", Role::Instructor, 32));
    SessionClient ada(namedClientConfig(sphere, "Ada", Role::Trainee, 32));
    std::vector<SessionClient*> all = {&cho, &ada};
    for (SessionClient* c : all)
        c->connect(loopback(server.port()));
    ASSERT_TRUE(pumpUntil(all, [&] { return cho.welcomed() && ada.welcomed(); }));

    cho.annotate(add({0, 0, 10}, "entry"));
    cho.annotate(add({5, 0, 9}, "avoid: sinus"));
    ASSERT_TRUE(pumpUntil(
        all, [&] { return ada.annotations().size() == 2 && cho.annotations().size() == 2; }));
    EXPECT_EQ(ada.annotations()[0].label, "entry");
    EXPECT_EQ(ada.annotations()[1].position, glm::vec3(5, 0, 9));
    EXPECT_EQ(ada.annotations()[1].author, cho.welcome().clientId);
    EXPECT_EQ(cho.annotations(), ada.annotations());

    // A trainee's edits are refused: counted, nothing changes.
    ada.annotate(add({1, 1, 1}, "mine"));
    Annotate clear;
    clear.op = Annotate::Op::Clear;
    ada.annotate(clear);
    ASSERT_TRUE(pumpUntil(all, [&] { return server.annotationsRefused() == 2; }));
    EXPECT_EQ(ada.annotations().size(), 2u);

    // A late joiner gets the list after its welcome.
    SessionClient ben(namedClientConfig(sphere, "Ben", Role::Trainee, 32));
    ben.connect(loopback(server.port()));
    all.push_back(&ben);
    ASSERT_TRUE(pumpUntil(all, [&] { return ben.annotations().size() == 2; }));

    // Remove one, then clear: everyone follows.
    Annotate remove;
    remove.op = Annotate::Op::Remove;
    remove.id = ada.annotations()[0].id;
    cho.annotate(remove);
    ASSERT_TRUE(pumpUntil(
        all, [&] { return ada.annotations().size() == 1 && ben.annotations().size() == 1; }));
    EXPECT_EQ(ben.annotations()[0].label, "avoid: sinus");
    cho.annotate(clear);
    ASSERT_TRUE(pumpUntil(all, [&] {
        return ada.annotations().empty() && ben.annotations().empty() && cho.annotations().empty();
    }));

    // At most kMaxAnnotations marks; more adds are refused.
    for (int i = 0; i < kMaxAnnotations + 3; ++i)
        cho.annotate(add({float(i) * 0.01f, 0, 0}, std::to_string(i)));
    ASSERT_TRUE(pumpUntil(all, [&] { return server.annotationsRefused() == 2 + 3; }));
    ASSERT_TRUE(pumpUntil(all, [&] { return ada.annotations().size() == kMaxAnnotations; }));
    for (SessionClient* c : all)
        EXPECT_EQ(c->stats().malformed(), 0u);
    server.stop();
}

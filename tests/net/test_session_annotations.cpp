// Instructors' marks on the skull (Annotate, Annotations) over loopback: an instructor adds,
// removes and clears marks and every participant, a late joiner included, holds the same list;
// a trainee's edits and adds beyond the limit are refused (counted, not applied); malformed
// messages are dropped and counted. Deadlines only guard against hangs.
#include "net/marks_file.h"
#include "net/session_client.h"
#include "net/session_server.h"

#include "libsim/error.h"
#include "libsim/skull.h"
#include "libsim/volume_io.h"

#include "loopback.h"
#include "test_support.h"

#include <filesystem>
#include <fstream>
#include <gtest/gtest.h>
#include <unistd.h>

using namespace trephine;
using namespace trephine::net;

using trephine::testing::loopback;
using trephine::testing::loopbackServerConfig;
using trephine::testing::namedClientConfig;
using trephine::testing::Pumped;
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
    Pumped pumped(server);
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

// A label longer than the wire carries is cut at a character boundary: 63 bytes and a two-byte
// "é" were cut after the é's first byte.
TEST(Annotations, ALongLabelIsCutAtACharacterBoundary) {
    Volume sphere = makeSphere(32);
    SessionServer server(sphere, loopbackServerConfig("sphere:32"));
    Pumped pumped(server);
    SessionClient cho(namedClientConfig(sphere, "Dr. Cho", Role::Instructor, 32));
    cho.connect(loopback(server.port()));
    ASSERT_TRUE(pumpUntil({&cho}, [&] { return cho.welcomed(); }));
    cho.annotate(add({0, 0, 10}, std::string(63, 'a') + "\xc3\xa9 and more"));
    cho.annotate(add({0, 0, 11}, std::string(70, 'b')));
    ASSERT_TRUE(pumpUntil({&cho}, [&] { return cho.annotations().size() == 2; }));
    EXPECT_EQ(cho.annotations()[0].label, std::string(63, 'a'));
    EXPECT_EQ(cho.annotations()[1].label, std::string(kMaxNameLength, 'b'));
    server.stop();
}

// The marks outlive the server: --save-on-exit writes them beside the volume, and a server
// started from that session holds them again, for a newcomer as for anyone.
TEST(Annotations, MarksSavedOnExitComeBackInTheNextSession) {
    Volume sphere = makeSphere(32);
    trephine::testing::TempDir dir;
    const std::string saved = dir / "session.nrrd";
    ServerConfig config = loopbackServerConfig("sphere:32");
    config.saveOnExit = saved;
    {
        SessionServer server(sphere, config);
        Pumped pumped(server);
        SessionClient cho(namedClientConfig(sphere, "Dr. Cho", Role::Instructor, 32));
        cho.connect(loopback(server.port()));
        ASSERT_TRUE(pumpUntil({&cho}, [&] { return cho.welcomed(); }));
        cho.annotate(add({0.25f, -1.5f, 10.125f}, "entry \"A\"\n2nd line\\"));
        cho.annotate(add({5, 0, 9}, "gone"));
        cho.annotate(add({-3, 4, 1e4f}, ""));
        ASSERT_TRUE(pumpUntil({&cho}, [&] { return cho.annotations().size() == 3; }));
        Annotate remove;
        remove.op = Annotate::Op::Remove;
        remove.id = cho.annotations()[1].id;
        cho.annotate(remove);
        ASSERT_TRUE(pumpUntil({&cho}, [&] { return cho.annotations().size() == 2; }));
        server.stop();
        ASSERT_TRUE(server.saveError().empty()) << server.saveError();
    }
    const std::vector<AnnotationInfo> marks = readMarksFile(marksPathFor(saved));
    ASSERT_EQ(marks.size(), 2u);
    EXPECT_EQ(marks[0].position, glm::vec3(0.25f, -1.5f, 10.125f));
    EXPECT_EQ(marks[0].label, "entry \"A\"\n2nd line\\");
    EXPECT_EQ(marks[1].position, glm::vec3(-3, 4, 1e4f));
    EXPECT_EQ(marks[1].label, "");

    ServerConfig next = loopbackServerConfig("session.nrrd");
    next.marks = marks;
    SessionServer server(loadVolume(saved), next);
    Pumped pumped(server);
    SessionClient ben(namedClientConfig(sphere, "Ben", Role::Trainee, 32));
    ben.connect(loopback(server.port()));
    ASSERT_TRUE(pumpUntil({&ben}, [&] { return ben.annotations().size() == 2; }));
    EXPECT_EQ(ben.annotations()[0].label, marks[0].label);
    EXPECT_EQ(ben.annotations()[1].position, marks[1].position);
    EXPECT_EQ(ben.annotations()[0].author, 0u) << "from the file, not from a participant";
    // A session whose marks were all removed saves an empty list: no old mark comes back.
    server.stop();
}

TEST(MarksFile, MalformedFilesAreRefusedInOneLineNamingTheLine) {
    trephine::testing::TempDir dir;
    const std::string path = dir / "m.marks";
    auto refusal = [&](const std::string& text) -> std::string {
        std::ofstream(path, std::ios::binary) << text;
        try {
            readMarksFile(path);
        } catch (const Error& e) {
            return e.what();
        }
        return "";
    };
    const std::string h = "trephine-marks 1\n";
    EXPECT_NE(refusal("").find("not a marks file"), std::string::npos);
    EXPECT_NE(refusal("mark 1 2 3 \"x\"\n").find(":1: not a marks file"), std::string::npos);
    EXPECT_NE(refusal(h + "mark 1 2 \"x\"\n").find(":2: coordinate"), std::string::npos);
    EXPECT_NE(refusal(h + "mark 1 2 nan \"x\"\n").find("coordinate `nan`"), std::string::npos);
    EXPECT_NE(refusal(h + "mark 1 2 1e6 \"x\"\n").find("within 1e5 mm"), std::string::npos);
    EXPECT_NE(refusal(h + "# c\n\nmark 1 2 3 x\n").find(":4: the label must be in double quotes"),
              std::string::npos);
    EXPECT_NE(refusal(h + "mark 1 2 3 \"x\n").find("closing quote is missing"), std::string::npos);
    EXPECT_NE(refusal(h + "mark 1 2 3 \"x\" y\n").find("after the label"), std::string::npos);
    EXPECT_NE(refusal(h + "mark 1 2 3 \"\\q\"\n").find("unknown escape"), std::string::npos);
    EXPECT_NE(refusal(h + "mark 1 2 3 \"\\x4\"\n").find("two hex digits"), std::string::npos);
    EXPECT_NE(refusal(h + "mark 1 2 3 \"" + std::string(kMaxNameLength + 1, 'a') + "\"\n")
                  .find("longer than"),
              std::string::npos);
    std::string many = h;
    for (int i = 0; i <= kMaxAnnotations; ++i)
        many += "mark 0 0 0 \"\"\n";
    EXPECT_NE(refusal(many).find("more than 256 marks"), std::string::npos);
    for (const std::string& text : {std::string(""), h + "mark 1 2 nan \"x\"\n"})
        EXPECT_EQ(refusal(text).find('\n'), std::string::npos);
    // Comments, blank lines, CRLF and escapes read back.
    std::ofstream(path, std::ios::binary)
        << "trephine-marks 1\r\n# a comment\r\n\r\nmark 1.5 -2 3 \"a\\tb\\x01\"\r\n";
    const std::vector<AnnotationInfo> m = readMarksFile(path);
    ASSERT_EQ(m.size(), 1u);
    EXPECT_EQ(m[0].id, 1u);
    EXPECT_EQ(m[0].position, glm::vec3(1.5f, -2, 3));
    EXPECT_EQ(m[0].label, "a\tb\x01");
}

// Writing goes through a temporary file: a write that fails leaves the earlier file whole.
// The volume is written but its marks cannot be (a folder in the way of their temporary file): an
// older marks file must not stay beside the new volume, where `--volume` would read it back.
TEST(Annotations, AFailedMarksWriteLeavesNoOlderMarksBesideTheNewVolume) {
    Volume sphere = makeSphere(32);
    trephine::testing::TempDir dir;
    const std::string saved = dir / "session.nrrd";
    AnnotationInfo old;
    old.position = {1, 2, 3};
    old.label = "removed in this session";
    writeMarksFile(marksPathFor(saved), {old});
    ServerConfig config = loopbackServerConfig("sphere:32");
    config.saveOnExit = saved;
    std::string copy;
    {
        SessionServer server(sphere, config);
        Pumped pumped(server);
        std::filesystem::create_directories(marksPathFor(saved) + ".trephine-" +
                                            std::to_string(::getpid()) + ".tmp");
        std::filesystem::create_directories(dir / "tmp");
        const trephine::testing::ScopedEnv tmp("TMPDIR",
                                               dir / "tmp"); // the emergency copy goes there
        server.stop();
        EXPECT_FALSE(server.saveError().empty());
        copy = server.savedTo();
    }
    ASSERT_TRUE(std::filesystem::is_regular_file(saved)) << "the volume itself was written";
    EXPECT_FALSE(std::filesystem::exists(marksPathFor(saved)))
        << "the older marks would come back with the new volume";
    ASSERT_FALSE(copy.empty());
    EXPECT_TRUE(readMarksFile(marksPathFor(copy)).empty()) << "the emergency copy has them";
}

TEST(MarksFile, AFailedWriteLeavesTheEarlierFileWhole) {
    trephine::testing::TempDir dir;
    const std::string path = dir / "m.marks";
    AnnotationInfo a;
    a.position = {1, 2, 3};
    a.label = "keep";
    writeMarksFile(path, {a});
    EXPECT_THROW(writeMarksFile(dir / "no-such-folder/m.marks", {a}), Error);
    // Never renamed over a device (as root, /dev/full itself would be replaced) or a folder.
    EXPECT_THROW(writeMarksFile("/dev/full", {a}), Error);
    EXPECT_TRUE(std::filesystem::is_character_file("/dev/full"));
    EXPECT_THROW(writeMarksFile(dir.path.string(), {a}), Error);
    // The temporary file cannot be made (a folder in its way): the earlier file stays.
    std::filesystem::create_directories(path + ".trephine-" + std::to_string(::getpid()) + ".tmp");
    AnnotationInfo other = a;
    other.label = "lost?";
    EXPECT_THROW(writeMarksFile(path, {other, other}), Error);
    ASSERT_EQ(readMarksFile(path).size(), 1u);
    AnnotationInfo far = a;
    far.position.x = 2e5f;
    EXPECT_THROW(writeMarksFile(path, {far}), Error);
    EXPECT_EQ(readMarksFile(path)[0].label, "keep");
}

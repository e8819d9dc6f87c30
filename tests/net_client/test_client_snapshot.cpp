// ClientSnapshot as a value: equal when every field is, and its drawn part, what wakes a window.
#include "net/client_thread.h"

#include <gtest/gtest.h>

#include <memory>

using namespace trephine;
using namespace trephine::net;

namespace {

ClientSnapshot populated() {
    ClientSnapshot s;
    s.state = LinkState::Connected;
    s.welcome = Welcome{};
    s.welcome->clientId = 3;
    s.scene = std::make_shared<ReceivedScene>();
    s.others[2].position = {1, 2, 3};
    s.others[2].drilling = true;
    s.participants[3] = ParticipantInfo{};
    s.warnings[3].clientId = 3;
    s.hapticModel = HapticModel{};
    s.hapticModel->force = {0, 0, 1};
    s.replay = ReplayState{};
    s.replay->durationUs = 10'000'000;
    s.rateHistory.push_back({});
    s.modes[0].updatesApplied = 4;
    s.fault = ServerFault{MessageType::Scene, "37 bytes that do not decode"};
    return s;
}

} // namespace

TEST(ClientSnapshot, EqualWhenEveryFieldIsAndTheSceneIsTheSameObject) {
    const ClientSnapshot a = populated();
    ClientSnapshot b = a;
    EXPECT_EQ(a, b);
    EXPECT_EQ(ClientSnapshot{}, ClientSnapshot{});
    // An equal scene in another object is another arrival.
    b.scene = std::make_shared<ReceivedScene>(*a.scene);
    EXPECT_NE(a, b);
}

TEST(ClientSnapshot, AnyOneFieldDifferingMakesItDiffer) {
    const ClientSnapshot a = populated();
    auto differs = [&](auto change) {
        ClientSnapshot b = a;
        change(b);
        return !(a == b);
    };
    EXPECT_TRUE(differs([](ClientSnapshot& s) { s.welcome->clientId = 4; }));
    EXPECT_TRUE(differs([](ClientSnapshot& s) { s.others[2].sequence = 9; }));
    EXPECT_TRUE(differs([](ClientSnapshot& s) { s.warnings[3].distanceMm = 1.5f; }));
    EXPECT_TRUE(differs([](ClientSnapshot& s) { s.hapticModel->contact = true; }));
    EXPECT_TRUE(differs([](ClientSnapshot& s) { s.replay->positionUs = 5; }));
    EXPECT_TRUE(differs([](ClientSnapshot& s) { s.rateHistory[0][0].bytesInPerS = 1; }));
    EXPECT_TRUE(differs([](ClientSnapshot& s) { s.rates[1].messagesOutPerS = 1; }));
    EXPECT_TRUE(differs([](ClientSnapshot& s) { s.modes[1].latencyP50Us = 3; }));
    EXPECT_TRUE(differs([](ClientSnapshot& s) { s.fault->detail = "other"; }));
    EXPECT_TRUE(differs([](ClientSnapshot& s) { s.rttUs = 12; }));
    EXPECT_TRUE(differs([](ClientSnapshot& s) { s.publishedUs = 1; }));
    EXPECT_TRUE(differs([](ClientSnapshot& s) { s.assessment.serverTimeUs = 1; }));
}

// Statistics, a tool's sequence and time, and a playing replay's moving cursor redraw nothing; a
// tool that moved, a link state, a roster or a paused cursor does.
TEST(ClientSnapshot, TheDrawnPartLeavesOutWhatAWindowDoesNotDraw) {
    const ClientSnapshot a = populated();
    auto redraws = [&](auto change) {
        ClientSnapshot b = a;
        change(b);
        return drawnPart(a) != drawnPart(b);
    };
    EXPECT_FALSE(redraws([](ClientSnapshot& s) { s.rttUs = 12; }));
    EXPECT_FALSE(redraws([](ClientSnapshot& s) { s.updatesApplied = 7; }));
    EXPECT_FALSE(redraws([](ClientSnapshot& s) { s.others[2].sequence = 9; }));
    EXPECT_FALSE(redraws([](ClientSnapshot& s) { s.others[2].speed = 0.5f; }));
    EXPECT_FALSE(redraws([](ClientSnapshot& s) { s.welcome->serverTimeUs = 5; }));
    ClientSnapshot playing = a;
    playing.replay->playing = true;
    ClientSnapshot later = playing;
    later.replay->positionUs = 5;
    EXPECT_TRUE(drawnPart(playing) == drawnPart(later));
    EXPECT_TRUE(redraws([](ClientSnapshot& s) { s.replay->positionUs = 5; }));
    EXPECT_TRUE(redraws([](ClientSnapshot& s) { s.others[2].position.x = 4; }));
    EXPECT_TRUE(redraws([](ClientSnapshot& s) { s.others.erase(2); }));
    EXPECT_TRUE(redraws([](ClientSnapshot& s) { s.state = LinkState::Retrying; }));
    EXPECT_TRUE(redraws([](ClientSnapshot& s) { s.participants[3].name.push_back('b'); }));
    EXPECT_TRUE(redraws([](ClientSnapshot& s) { s.welcome.reset(); }));
    EXPECT_TRUE(redraws([](ClientSnapshot& s) { s.scene = std::make_shared<ReceivedScene>(); }));
}

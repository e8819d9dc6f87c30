// The panels' data and the generated meshes, without GL.
#include "ui/mesh.h"
#include "ui/panel_data.h"
#include "ui/panels.h"

#include "libsim/skull.h"
#include "libsim/tool.h"
#include "libsim/volume.h"

#include <glm/geometric.hpp>
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <map>

using namespace trephine;
using namespace trephine::ui;

TEST(NetworkHistory, RateCompressionAndHistogram) {
    NetworkHistory h;
    h.windowS = 10.0;
    for (int i = 0; i < 20; ++i)
        h.addUpdate({0.1 * i, 1000.0 * (i % 4), 100, 400, false});
    EXPECT_DOUBLE_EQ(h.compressionRatio(), 4.0);
    EXPECT_EQ(h.updateRate(1.95), 10.0); // t in (0.95, 1.95]
    auto hist = h.latencyHistogram(4, 4000.0);
    ASSERT_EQ(hist.size(), 4u);
    EXPECT_EQ(hist[0], 5.0f);
    EXPECT_EQ(hist[3], 5.0f);
    h.expire(10.55); // keeps t >= 0.55
    EXPECT_EQ(h.updates.size(), 14u);
    EXPECT_GE(h.latencyPercentile(50), 0.0);
}

// Before any latency is measured the caption says so ("-"), not "-0.0 ms" from the -1 that
// latencyPercentile returns for none.
TEST(NetworkHistory, TheLatencyCaptionShowsADashBeforeAnyLatency) {
    NetworkHistory h;
    EXPECT_EQ(h.latencyCaption(20000.0), "delivery p50 - p99 - (0-20 ms)");
    h.addUpdate({0.1, -1.0, 100, 400, true}); // a full image: no latency
    EXPECT_EQ(h.latencyCaption(20000.0), "delivery p50 - p99 - (0-20 ms)");
    h.addUpdate({0.2, 2500.0, 100, 400, false});
    EXPECT_EQ(h.latencyCaption(20000.0), "delivery p50 2.5 ms p99 2.5 ms (0-20 ms)");
}

TEST(NetworkHistory, SeriesAreCapped) {
    NetworkHistory h;
    h.seriesLength = 3;
    for (int i = 0; i < 5; ++i)
        h.addSecond(1000.0 * i, 0, 0, i, 500.0);
    ASSERT_EQ(h.imageKbitPerS.size(), 3u);
    EXPECT_FLOAT_EQ(h.imageKbitPerS.back(), 32.0f); // 4000 B/s = 32 kbit/s
    EXPECT_FLOAT_EQ(h.rttMs.back(), 0.5f);
}

TEST(ForceHistory, WindowRateAndSeries) {
    ForceHistory f;
    f.windowS = 1.0;
    for (int i = 0; i <= 100; ++i)
        f.addServer(0.01 * i, {3.0f, 4.0f, 0.0f});
    EXPECT_NEAR(f.serverRate(), 100.0, 1.0);
    auto mag = ForceHistory::series(f.server, 3);
    EXPECT_FLOAT_EQ(mag.back(), 5.0f);
    f.addExtrapolated(2.5, {0, 0, 1});
    EXPECT_TRUE(f.server.empty()); // all older than 1.5 s
    EXPECT_EQ(ForceHistory::series(f.extrapolated, 2).back(), 1.0f);
}

// The server's f (tens a second) and the loop's F (1 kHz) on one time axis: resampled over the
// same window, the same moment lands on the same point whatever the rate (by sample index, a
// step 1 s before the end drew ~20 % from the right in f and ~25 % in F).
TEST(ForceHistory, ResampledSeriesShareOneTimeAxisAndOneScale) {
    ForceHistory h;
    for (int i = 0; i <= 50; ++i) { // 10 per second for 5 s: a step to 1.5 N at t = 4
        const double t = double(i) / 10.0;
        h.addServer(t, glm::vec3(0, 0, t >= 3.975 ? 1.5f : 0.2f));
    }
    for (int i = 0; i <= 4000; ++i) { // 1 kHz over the last 4 s: the same step, to 1.9 N
        const double t = 1.0 + double(i) / 1000.0;
        h.extrapolated.push_back({t, glm::vec3(0, 0, t >= 3.975 ? 1.9f : 0.3f)});
    }
    const auto f = ForceHistory::resample(h.server, 3, 1.0, 5.0, 81);
    const auto F = ForceHistory::resample(h.extrapolated, 2, 1.0, 5.0, 81);
    ASSERT_EQ(f.size(), 81u);
    ASSERT_EQ(F.size(), 81u);
    for (int i = 0; i < 81; ++i) { // point i is t = 1 + 0.05 i: the step at i = 60 in both
        EXPECT_EQ(f[i] > 1.0f, i >= 60) << i;
        EXPECT_EQ(F[i] > 1.0f, i >= 60) << i;
    }
    // Before a series' first sample: its first value, not a false zero.
    EXPECT_FLOAT_EQ(ForceHistory::resample(h.extrapolated, 2, 0.0, 1.0, 3).front(), 0.3f);
    EXPECT_TRUE(ForceHistory::resample({}, 3, 0.0, 1.0, 3).empty());
    // One scale for both, the largest force rounded up: 1.9 N -> 2 N.
    EXPECT_EQ(h.scaleN(), 2.0f);
    h.addServer(5.1, glm::vec3(7.3f, 0, 0));
    EXPECT_EQ(h.scaleN(), 10.0f);
    EXPECT_EQ(ForceHistory().scaleN(), 0.5f) << "no force: the smallest scale";
}

TEST(DirtyBoxHistory, FadesAndKeepsTheNewest) {
    DirtyBoxHistory d;
    d.fadeS = 1.0;
    d.keep = 3;
    for (int i = 0; i < 5; ++i)
        d.add({double(i), {i, i, 10, 10}, uint32_t(i), 100, 1000.0, false});
    ASSERT_EQ(d.boxes.size(), 3u);
    EXPECT_EQ(d.boxes.front().sequence, 2u);
    EXPECT_FLOAT_EQ(d.alpha(d.boxes.back(), 4.0), 1.0f);
    EXPECT_FLOAT_EQ(d.alpha(d.boxes.back(), 4.5), 0.5f);
    EXPECT_EQ(d.visible(4.5).size(), 1u);
    EXPECT_TRUE(d.visible(6.0).empty());
}

// A full update (a new view's picture) forgets the rectangles of the picture it replaces: they were
// drawn over the new view for another 1.5 s.
// Drilling adds dozens of boxes a second at one place: the overlay draws the newest few, never a
// full update's (the whole picture), so the site is not buried under stacked fills.
TEST(DirtyBoxHistory, TheOverlayDrawsOnlyTheNewestFewRectangles) {
    DirtyBoxHistory h;
    h.add({0.0, PixelRect(0, 0, 500, 500), 1, 100, -1, true});
    for (uint32_t i = 0; i < 60; ++i)
        h.add({0.01 * i, PixelRect(200, 200, 50, 50), 2 + i, 100, -1, false});
    const auto shown = h.overlay(0.6, 8);
    ASSERT_EQ(shown.size(), 8u);
    EXPECT_EQ(shown.back().sequence, 61u) << "newest last";
    EXPECT_EQ(shown.front().sequence, 54u);
    for (const auto& b : shown)
        EXPECT_FALSE(b.full);
    EXPECT_TRUE(h.overlay(10.0).empty()) << "all faded";
}

TEST(DirtyBoxHistory, AFullUpdateForgetsTheBoxesOfThePictureItReplaces) {
    DirtyBoxHistory d;
    d.add({0.0, {10, 10, 20, 20}, 1, 100, 1000.0, false});
    d.add({0.1, {40, 40, 20, 20}, 2, 100, 1000.0, false});
    d.add({0.2, {0, 0, 500, 500}, 3, 9000, -1.0, true});
    ASSERT_EQ(d.visible(0.3).size(), 1u);
    EXPECT_EQ(d.visible(0.3).front().sequence, 3u);
    d.add({0.4, {5, 5, 8, 8}, 4, 100, 1000.0, false});
    EXPECT_EQ(d.visible(0.5).size(), 2u);
}

// "mark N" never repeats a label on the skull: after "mark 1" of two is removed, the next is not
// a second "mark 2".
TEST(MarkLabels, ADefaultLabelIsNeverOneAlreadyOnTheSkull) {
    std::vector<net::AnnotationInfo> marks;
    EXPECT_EQ(defaultMarkLabel(marks), "mark 1");
    marks.push_back({2, 1, {}, "mark 2"}); // "mark 1" was removed
    EXPECT_EQ(defaultMarkLabel(marks), "mark 3");
    marks.push_back({3, 1, {}, "entry point"});
    EXPECT_EQ(defaultMarkLabel(marks), "mark 3");
}

// --take-over asks once per connection, once the trainee is listed; after a reconnect (the server
// hands a trainee back when its instructor leaves) it asks again.
TEST(ScriptedTakeOver, AsksOncePerConnectionOnceTheTraineeIsListed) {
    ScriptedTakeOver t{"Ada"};
    std::map<uint16_t, net::ParticipantInfo> roster;
    roster[1] = {1, net::Role::Instructor, net::Sync::Dbi, "Ada", 0}; // an instructor named Ada
    EXPECT_FALSE(t.due(1, roster));
    roster[3] = {3, net::Role::Trainee, net::Sync::Dbi, "Ada", 0};
    EXPECT_EQ(t.due(1, roster), std::optional<uint16_t>(3));
    EXPECT_FALSE(t.due(1, roster)) << "once per connection";
    roster.erase(3);
    roster[2] = {2, net::Role::Trainee, net::Sync::Dbi, "Ada", 0};
    EXPECT_EQ(t.due(2, roster), std::optional<uint16_t>(2)) << "the next connection asks again";
    ScriptedTakeOver byId{"2"};
    EXPECT_EQ(byId.due(1, roster), std::optional<uint16_t>(2));
    EXPECT_FALSE(ScriptedTakeOver{}.due(1, roster)) << "none asked for";
}

TEST(Meshes, BurrToolHasItsSphereAtTheOrigin) {
    MeshData m = makeToolMesh(ToolShape::burr(5.0f));
    ASSERT_GT(m.triangleCount(), 100u);
    float minZ = 1e9f;
    for (const auto& v : m.vertices) {
        minZ = std::min(minZ, v.position.z);
        EXPECT_NEAR(glm::length(v.normal), 1.0f, 1e-3f);
    }
    EXPECT_NEAR(minZ, -2.5f, 1e-4f); // the burr's bottom: radius below the origin
    for (uint32_t i : m.indices)
        ASSERT_LT(i, m.vertices.size());
}

TEST(Meshes, PerforatorTipIsTheApex) {
    ToolShape s = ToolShape::perforator();
    MeshData m = makeToolMesh(s);
    float minZ = 1e9f, maxR = 0;
    for (const auto& v : m.vertices) {
        minZ = std::min(minZ, v.position.z);
        if (v.position.z < s.tipLengthMm + s.cutLengthMm)
            maxR = std::max(maxR, glm::length(glm::vec2(v.position)));
    }
    EXPECT_NEAR(minZ, 0.0f, 1e-5f);
    EXPECT_NEAR(maxR, s.diameterMm * 0.5f, 1e-3f);
}

TEST(Meshes, SurgicalFieldSitsAboveTheBoneAndLeavesTheSiteOpen) {
    Volume skull = makeSkull(64);
    SurfaceSite site = defaultBurrSite(skull);
    MeshData m = makeSurgicalField(skull, site, 20.0f, 35.0f, 3.0f);
    ASSERT_GT(m.triangleCount(), 500u);
    float nearest = 1e9f;
    for (const auto& v : m.vertices)
        nearest = std::min(nearest, glm::length(v.position - site.position));
    EXPECT_GT(nearest, 15.0f); // the craniotomy opening stays clear
    for (uint32_t i : m.indices)
        ASSERT_LT(i, m.vertices.size());
}

TEST(ParticipantForces, OneHistoryPerParticipantFromNewModelsOnly) {
    ParticipantForces p;
    p.windowS = 1.0;
    std::map<uint16_t, net::HapticModel> models;
    models[2].toolSequence = 1;
    models[2].force = {3.0f, 4.0f, 0.0f};
    models[5].toolSequence = 9;
    models[5].force = {0.0f, 0.0f, -1.0f};
    EXPECT_EQ(p.update(0.0, models), 2);
    EXPECT_EQ(p.update(0.1, models), 0) << "the same models again add nothing";
    models[2].toolSequence = 2;
    models[2].force = {0.0f, 6.0f, 8.0f};
    EXPECT_EQ(p.update(0.2, models), 1);
    ASSERT_EQ(p.byClient.size(), 2u);
    auto mag = ForceHistory::series(p.byClient.at(2).server, 3);
    ASSERT_EQ(mag.size(), 2u);
    EXPECT_FLOAT_EQ(mag[0], 5.0f);
    EXPECT_FLOAT_EQ(mag[1], 10.0f);
    EXPECT_EQ(ForceHistory::series(p.byClient.at(5).server, 2).back(), -1.0f);
    // Participant 5 sends nothing new: gone after the window; its old model does not return it.
    models[2].toolSequence = 3;
    EXPECT_EQ(p.update(1.5, models), 1);
    EXPECT_EQ(p.byClient.count(5), 0u);
    EXPECT_EQ(p.byClient.at(2).server.size(), 1u);
    EXPECT_EQ(p.update(1.6, models), 0);
    EXPECT_EQ(p.byClient.count(5), 0u);
}

// The client drops a participant's relayed model when the roster no longer lists it: its plot
// goes at once (it was kept, as "client N", until its samples aged out), and an id the server
// gives to someone new later starts with no old sequence to beat.
TEST(ParticipantForces, AParticipantWhoLeftIsDroppedAtOnce) {
    ParticipantForces p;
    p.windowS = 5.0;
    std::map<uint16_t, net::HapticModel> models;
    models[2].toolSequence = 100;
    models[5].toolSequence = 7;
    EXPECT_EQ(p.update(0.0, models), 2);
    models.erase(5); // participant 5 left
    p.update(0.1, models);
    EXPECT_EQ(p.byClient.count(5), 0u) << "no plot for a participant who left";
    EXPECT_EQ(p.byClient.count(2), 1u);
    // Someone new is given id 2 (its tool sequence starts again): a new model, a new sample.
    models.erase(2);
    p.update(0.2, models);
    models[2].toolSequence = 1;
    EXPECT_EQ(p.update(0.3, models), 1);
    EXPECT_EQ(p.byClient.at(2).server.size(), 1u);
}

TEST(Panels, ParticipantsAreNamedFromTheRosterOrByTheirId) {
    std::map<uint16_t, net::ParticipantInfo> roster;
    roster[3] = {3, net::Role::Instructor, net::Sync::Dbi, "Dr. Cho"};
    roster[4] = {4, net::Role::Trainee, net::Sync::Volume, ""};
    EXPECT_EQ(ui::participantName(roster, 3), "Dr. Cho");
    EXPECT_EQ(ui::participantName(roster, 4), "client 4") << "no name given";
    EXPECT_EQ(ui::participantName(roster, 9), "client 9") << "not listed yet";
}

// Every participant's tool and name are told apart from the marks (a yellow participant read as
// an instructor's mark) and from each other: the server's palette, drawn as the roster says.
TEST(Panels, NoParticipantColourIsTheMarksYellow) {
    const glm::vec3 mark(markColor());
    const auto palette = net::participantPalette();
    for (size_t i = 0; i < palette.size(); ++i) {
        const glm::vec3 c(toColour(palette[i]));
        EXPECT_GT(glm::distance(c, mark), 0.35f) << "participant colour " << i;
        for (size_t j = 0; j < i; ++j)
            EXPECT_GT(glm::distance(c, glm::vec3(toColour(palette[j]))), 0.2f) << i << " " << j;
    }
    std::map<uint16_t, net::ParticipantInfo> roster;
    roster[3] = {3, net::Role::Trainee, net::Sync::Dbi, "Alex", 0, palette[2]};
    EXPECT_EQ(participantColor(roster, 3), toColour(palette[2])) << "the server's colour";
    EXPECT_GT(glm::distance(glm::vec3(participantColor(roster, 9)), mark), 0.35f)
        << "not listed yet: neutral";
}

// Arrow keys and the wheel move the push depth in steps and never past the slider's range (held
// down, Down's key repeat drove the burr through the inner table).
TEST(ToolControls, PushStepsStayInTheSlidersRange) {
    float push = 0.0f;
    push = steppedPush(push, 1.0f);
    EXPECT_FLOAT_EQ(push, kPushStepMm);
    for (int i = 0; i < 1000; ++i)
        push = steppedPush(push, 1.0f);
    EXPECT_EQ(push, kPushMaxMm);
    for (int i = 0; i < 1000; ++i)
        push = steppedPush(push, -1.0f);
    EXPECT_EQ(push, kPushMinMm);
    EXPECT_EQ(steppedPush(0.0f, 3.0f), 3.0f * kPushStepMm) << "three wheel notches";
}

// Values typed into the Session panel's sliders (Ctrl+click is not clamped in ImGui 1.86 without
// AlwaysClamp) are brought back into range before the tool uses them: a typed 9 mm burr made
// every tool state malformed and the server kicked the window.
TEST(ToolControls, TypedValuesAreKeptWithinTheSlidersRanges) {
    ToolControls c;
    c.diameter(ToolKind::Burr) = 9.0f;
    c.speed = 4.0f;
    c.pushMm = 50.0f;
    ToolControls k = withinRanges(c);
    EXPECT_EQ(k.diameter(ToolKind::Burr), toolType(ToolKind::Burr).maxDiameterMm);
    EXPECT_EQ(k.speed, 1.0f);
    EXPECT_EQ(k.pushMm, kPushMaxMm);
    EXPECT_NO_THROW(ToolShape::burr(k.diameter(ToolKind::Burr)).validate())
        << "what the server checks";
    c.diameter(ToolKind::Burr) = std::nanf("");
    c.speed = -1.0f;
    c.pushMm = -std::numeric_limits<float>::infinity();
    k = withinRanges(c);
    EXPECT_EQ(k.diameter(ToolKind::Burr), toolType(ToolKind::Burr).minDiameterMm);
    EXPECT_EQ(k.speed, 0.0f);
    EXPECT_EQ(k.pushMm, kPushMinMm);
    c = ToolControls{};
    c.diameter(ToolKind::Burr) = 4.5f;
    c.speed = 0.5f;
    c.pushMm = 2.0f;
    k = withinRanges(c);
    EXPECT_EQ(k.diameter(ToolKind::Burr), 4.5f);
    EXPECT_EQ(k.speed, 0.5f);
    EXPECT_EQ(k.pushMm, 2.0f);
}

// *reset* goes back to the view the window opened with (--orbit, --tilt, its camera's distance),
// not to orbit and tilt 0 at whatever distance the slider was left.
TEST(ViewControls, ResetGoesBackToTheOpeningView) {
    ViewControls v;
    v.yawDeg = 15.0f;
    v.pitchDeg = 30.0f;
    v.distanceMm = 170.0f;
    v.setHome();
    v.yawDeg = -60.0f;
    v.pitchDeg = 5.0f;
    v.distanceMm = 420.0f;
    v.dirty = false;
    v.reset();
    EXPECT_EQ(v.yawDeg, 15.0f);
    EXPECT_EQ(v.pitchDeg, 30.0f);
    EXPECT_EQ(v.distanceMm, 170.0f);
    EXPECT_TRUE(v.dirty) << "a new view to ask for";
}

// An instructor's *remove* or *clear marks* can be undone: the marks come back as Adds with
// their places and labels; the newest removal is the one remembered, and an undo forgets it.
TEST(MarkUndo, PutsBackWhatTheLastRemovalTook) {
    std::vector<net::AnnotationInfo> shown;
    for (uint32_t i = 1; i <= 3; ++i) {
        net::AnnotationInfo m;
        m.id = i;
        m.author = 7;
        m.position = glm::vec3(float(i), 2.0f, 3.0f);
        m.label = std::string(1, char('0' + i)) + " mark";
        shown.push_back(m);
    }
    MarkUndo undo;
    EXPECT_EQ(undo.pending(), 0u);
    EXPECT_TRUE(undo.undo().empty());
    undo.removing(shown, 99); // not listed (already gone): nothing to remember
    EXPECT_EQ(undo.pending(), 0u);
    undo.removing(shown, 2);
    ASSERT_EQ(undo.pending(), 1u);
    undo.clearing(shown);
    ASSERT_EQ(undo.pending(), 3u);
    const std::vector<net::Annotate> adds = undo.undo();
    ASSERT_EQ(adds.size(), 3u);
    for (size_t i = 0; i < 3; ++i) {
        EXPECT_EQ(adds[i].op, net::Annotate::Op::Add);
        EXPECT_EQ(adds[i].position, shown[i].position);
        EXPECT_EQ(adds[i].label, shown[i].label);
    }
    EXPECT_EQ(undo.pending(), 0u);
    undo.clearing({}); // clearing nothing keeps nothing
    EXPECT_EQ(undo.pending(), 0u);
}

// The window sends what the mark controls ask for only while the link is up: the client drops an
// Annotate otherwise. An undo asked while reconnecting stays pending (it was forgotten, and the
// marks with it), and a removal asked then is not remembered (undoing it re-added marks that
// were never taken off).
TEST(MarkUndo, WaitsForTheLinkToSendAnUndo) {
    net::ClientSnapshot snap;
    snap.state = net::LinkState::Connected;
    snap.welcome = net::Welcome{};
    for (uint32_t i = 1; i <= 2; ++i) {
        net::AnnotationInfo m;
        m.id = i;
        m.position = glm::vec3(float(i), 0.0f, 0.0f);
        m.label = i == 1 ? "a" : "b";
        snap.annotations.push_back(m);
    }
    MarkControls controls;
    MarkUndo undo;
    controls.clearAll = true;
    std::vector<net::Annotate> sent = markRequests(controls, undo, snap, std::nullopt);
    ASSERT_EQ(sent.size(), 1u);
    EXPECT_EQ(sent[0].op, net::Annotate::Op::Clear);
    EXPECT_FALSE(controls.clearAll);
    EXPECT_EQ(controls.undoable, 2u);

    net::ClientSnapshot down = snap; // the link dropped; the list as last shown
    down.state = net::LinkState::Connecting;
    down.welcome.reset();
    controls.undo = true;
    EXPECT_TRUE(markRequests(controls, undo, down, std::nullopt).empty());
    EXPECT_FALSE(controls.undo);
    EXPECT_EQ(controls.undoable, 2u) << "kept for when the link is back";
    controls.removeId = 1;
    EXPECT_TRUE(markRequests(controls, undo, down, std::nullopt).empty());
    EXPECT_EQ(controls.undoable, 2u) << "a removal that was not sent is not remembered";

    snap.annotations.clear();
    controls.undo = true;
    sent = markRequests(controls, undo, snap, std::nullopt);
    ASSERT_EQ(sent.size(), 2u);
    EXPECT_EQ(sent[0].op, net::Annotate::Op::Add);
    EXPECT_EQ(sent[0].label, "a");
    EXPECT_EQ(sent[1].label, "b");
    EXPECT_EQ(controls.undoable, 0u);

    controls.addAtPointer = true; // the default label: the next number no mark has
    sent = markRequests(controls, undo, snap, glm::vec3(1.0f, 2.0f, 3.0f));
    ASSERT_EQ(sent.size(), 1u);
    EXPECT_EQ(sent[0].position, glm::vec3(1.0f, 2.0f, 3.0f));
    EXPECT_EQ(sent[0].label, defaultMarkLabel(snap.annotations));
}

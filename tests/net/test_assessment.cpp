// The assessment on its own and inside the simulation step: no ENet, no threads, no sleeps. Tools
// are scripted toward a hand-built sinus under bone; the test reads the warnings the assessment
// posts for the network thread and the metrics it keeps for the report.
#include "net/assessment.h"

#include "libsim/error.h"
#include "libsim/skull.h"
#include "net/debrief.h"
#include "net/session_client.h"
#include "net/session_server.h"
#include "net/sim_step.h"
#include "net/view.h"

#include "loopback.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>

#include <unistd.h>

using namespace trephine;
using namespace trephine::net;

namespace {

constexpr float kSpacing = 0.5f; // a voxel of 1/8 mm^3: sums of voxel volumes are exact

// 64^3 voxels of 0.5 mm: brain below, dura, a sinus slab, then bone (cortical, diploe, cortical)
// up to z = +4 mm, air above. The sinus's top voxel centres lie at z = -4.25 mm.
Volume sinusUnderBone() {
    Volume v({64, 64, 64}, glm::vec3(kSpacing));
    v.fill({{0, 0, 0}, {64, 64, 14}}, 255, Material::Brain);
    v.fill({{0, 0, 14}, {64, 64, 18}}, 255, Material::Dura);
    v.fill({{0, 0, 18}, {64, 64, 24}}, 255, Material::Sinus);
    v.fill({{0, 0, 24}, {64, 64, 28}}, 255, Material::Cortical);
    v.fill({{0, 0, 28}, {64, 64, 36}}, 200, Material::Diploe);
    v.fill({{0, 0, 36}, {64, 64, 40}}, 255, Material::Cortical);
    return v;
}

struct Rig {
    ReportBook book;
    Outbox outbox{1 << 30, book, steadyNowUs};
    SimulationStep step;
    uint64_t now = 1'000'000;
    std::map<uint16_t, uint32_t> sequence;
    std::map<uint16_t, uint64_t> clientUs;

    explicit Rig(Volume v, AssessmentConfig a = {})
        : step(std::move(v), StepConfig{0.05f, 10.0f, 1, a}, outbox, book, steadyNowUs) {}

    void join(uint16_t id, const std::string& name, Role role) {
        // A volume client: nothing to render.
        const LogRecord ev{0,
                           JoinEvent{id, toViewSpec(cameraPreset("top", step.volume(), {32, 32})),
                                     Codec::Raw, Sync::Volume, Codec::Lz4, role, name,
                                     std::make_shared<std::atomic<int64_t>>(0)}};
        step.step({&ev, 1}, now);
    }
    LogRecord tool(uint16_t id, glm::vec3 pos, bool drilling, float forceN = 1.0f,
                   float diameter = 3.0f) {
        ToolEvent ev{id, {}, forceN};
        ev.tool.sequence = ++sequence[id];
        clientUs[id] += 1000; // 1 kHz
        ev.tool.clientTimeUs = clientUs[id];
        ev.tool.toolKind = uint8_t(ToolKind::Burr);
        ev.tool.diameterMm = diameter;
        ev.tool.position = pos;
        ev.tool.speed = drilling ? 1.0f : 0.0f;
        ev.tool.drilling = drilling;
        return {now, ev};
    }
    void run(std::vector<LogRecord> batch) {
        now += 1000 * batch.size();
        step.step(batch, now);
    }
    // The warnings posted since the last call, with whom each went to.
    std::vector<std::pair<SafetyWarning, std::vector<uint16_t>>> warnings() {
        std::vector<std::pair<SafetyWarning, std::vector<uint16_t>>> out;
        for (Assessment::Notice& n : step.assessment().takeNotices()) {
            SafetyWarning w;
            if (decodeMessage(n.bytes, w))
                out.push_back({w, n.to});
        }
        return out;
    }
    ParticipantMetrics metrics(uint16_t id) { return step.assessment().metrics(now).at(id); }
};

} // namespace

TEST(Assessment, DangerWarningPrecedesTheFirstContactAtDrillingSpeed) {
    Rig rig(sinusUnderBone());
    rig.join(1, "ada", Role::Trainee);
    // Down the z axis at 4 mm/s, drilling at full speed, 1 kHz tool states in 10 ms batches.
    uint32_t firstDanger = 0, firstViolation = 0;
    int contactBatch = -1, violationBatch = -1;
    float z = 6.0f;
    for (int batch = 0; batch < 300 && contactBatch < 0; ++batch) {
        std::vector<LogRecord> events;
        for (int i = 0; i < 10; ++i, z -= 0.004f)
            events.push_back(rig.tool(1, {0.2f, -0.3f, z}, true));
        rig.run(events);
        for (auto& [w, to] : rig.warnings()) {
            if (w.zone == Zone::Danger && !firstDanger)
                firstDanger = w.toolSequence;
            if (w.zone == Zone::Violation && !firstViolation) {
                firstViolation = w.toolSequence;
                violationBatch = batch;
            }
        }
        if (rig.metrics(1).structures.at("sinus").contacts > 0)
            contactBatch = batch;
    }
    ASSERT_GE(contactBatch, 0) << "the burr never reached the sinus";
    ASSERT_NE(firstDanger, 0u) << "no danger warning";
    EXPECT_LT(firstDanger, firstViolation);
    EXPECT_EQ(violationBatch, contactBatch) << "the contact's batch warns of it";
    // 1 mm of the 4 mm/s descent lies between them (0.25 s of states), less a voxel's error.
    EXPECT_GT(firstViolation - firstDanger, 150u);
    const ParticipantMetrics m = rig.metrics(1);
    EXPECT_LE(m.structures.at("sinus").closestMm, 0.0);
    EXPECT_EQ(m.structures.at("sinus").contacts, 1u);
    EXPECT_GE(m.warnings, 3u); // caution, danger, violation
    EXPECT_GT(m.zoneS[size_t(Zone::Danger)], 0.0);
}

TEST(Assessment, AToolOutsideTheCautionZoneGetsNoWarning) {
    Rig rig(sinusUnderBone());
    rig.join(1, "ada", Role::Trainee);
    rig.join(2, "iris", Role::Instructor);
    // Drilling the outer table and sweeping over it: the burr's bottom stays above z = -0.5 mm,
    // more than 3 mm from the sinus (top centres at -4.25 mm).
    for (int batch = 0; batch < 60; ++batch) {
        std::vector<LogRecord> events;
        for (int i = 0; i < 10; ++i) {
            const float t = float(batch * 10 + i) * 0.01f;
            events.push_back(rig.tool(1, {5.0f * std::sin(t), 4.0f * std::cos(t), 1.0f}, true));
        }
        rig.run(events);
        EXPECT_TRUE(rig.warnings().empty()) << batch;
    }
    const ParticipantMetrics m = rig.metrics(1);
    EXPECT_EQ(m.warnings, 0u);
    EXPECT_GT(m.structures.at("sinus").closestMm, 3.0);
    EXPECT_EQ(m.structures.at("sinus").contacts, 0u);
    EXPECT_GT(m.removedMm3.at("diploe"), 0.0);
    EXPECT_NEAR(m.zoneS[size_t(Zone::Clear)], m.drillingS, 1e-9);
}

TEST(Assessment, WarningsReachTheOwnerAndInstructorsAndNoOtherTrainee) {
    Rig rig(sinusUnderBone());
    rig.join(1, "ada", Role::Trainee);
    rig.join(2, "ben", Role::Trainee);
    rig.join(3, "iris", Role::Instructor);
    rig.join(4, "ivan", Role::Instructor);
    std::vector<std::pair<SafetyWarning, std::vector<uint16_t>>> seen;
    // Ben stays clear; Ada goes (not drilling) straight down into the sinus.
    for (int batch = 0; batch < 40; ++batch) {
        std::vector<LogRecord> events;
        events.push_back(rig.tool(2, {8.0f, 8.0f, 8.0f}, false));
        events.push_back(rig.tool(1, {0.0f, 0.0f, 6.0f - 0.3f * float(batch)}, false));
        rig.run(events);
        for (auto& w : rig.warnings())
            seen.push_back(w);
    }
    ASSERT_FALSE(seen.empty());
    std::set<Zone> zones;
    for (const auto& [w, to] : seen) {
        EXPECT_EQ(w.clientId, 1);
        EXPECT_EQ(w.structure, w.zone == Zone::Clear ? w.structure : std::string("sinus"));
        EXPECT_EQ(to, (std::vector<uint16_t>{1, 3, 4}));
        zones.insert(w.zone);
    }
    EXPECT_EQ(zones, (std::set<Zone>{Zone::Caution, Zone::Danger, Zone::Violation}));
    // Snapshots: a trainee gets only its own figures, an instructor everyone's.
    rig.now += 1'000'000;
    rig.step.assessment().tick(rig.now);
    int snapshots = 0;
    for (Assessment::Notice& n : rig.step.assessment().takeNotices()) {
        AssessmentSnapshot s;
        ASSERT_TRUE(decodeMessage(n.bytes, s));
        for (uint16_t id : n.to) {
            ++snapshots;
            if (id <= 2) {
                ASSERT_EQ(s.list.size(), 1u);
                EXPECT_EQ(s.list[0].clientId, id);
            } else {
                EXPECT_EQ(s.list.size(), 4u);
            }
        }
    }
    EXPECT_EQ(snapshots, 4);
}

TEST(Assessment, BoneRemovedPerMaterialIsTheVolumesDifferenceAndEachIsCreditedOwnCuts) {
    const Volume start = sinusUnderBone();
    Rig rig(start);
    rig.join(1, "ada", Role::Trainee);
    rig.join(2, "ben", Role::Trainee);
    rig.join(3, "cy", Role::Trainee);
    // Ada drills on the left, Ben on the right, then Cy deepens Ada's hole: their burrs never
    // reach across the midline (x = 0).
    auto drill = [&](uint16_t id, float x, float fromZ, float toZ, float diameter, int dwell) {
        for (float z = fromZ; z > toZ; z -= 0.05f) {
            std::vector<LogRecord> events;
            for (int i = 0; i < dwell; ++i)
                events.push_back(rig.tool(id, {x, 0.0f, z}, true, 2.0f, diameter));
            rig.run(events);
        }
    };
    drill(1, -6.0f, 5.0f, 1.5f, 4.0f, 5);
    drill(2, 6.0f, 5.0f, -0.5f, 5.0f, 5);
    drill(3, -6.0f, 1.5f, -2.2f, 3.0f, 10); // into the lower table

    const Volume& end = rig.step.volume();
    auto countHalf = [](const Volume& v, bool left, Material m) {
        int64_t n = 0;
        for (int z = 0; z < v.dims().z; ++z)
            for (int y = 0; y < v.dims().y; ++y)
                for (int x = left ? 0 : 32; x < (left ? 32 : 64); ++x)
                    n += v.material(x, y, z) == m;
        return n;
    };
    const auto all = rig.step.assessment().metrics(rig.now);
    const double voxel = double(kSpacing) * kSpacing * kSpacing;
    for (Material m : {Material::Cortical, Material::Diploe}) {
        const std::string name(materialName(m));
        auto removed = [&](uint16_t id) {
            const auto& r = all.at(id).removedVoxels;
            return r.count(name) ? r.at(name) : int64_t(0);
        };
        const int64_t left = countHalf(start, true, m) - countHalf(end, true, m);
        const int64_t right = countHalf(start, false, m) - countHalf(end, false, m);
        EXPECT_GT(left, 0) << name;
        EXPECT_GT(right, 0) << name;
        EXPECT_EQ(removed(1) + removed(3), left) << name;
        EXPECT_EQ(removed(2), right) << name;
        EXPECT_GT(removed(3), 0) << name;
        const int64_t whole = start.materialCounts()[size_t(m)] - end.materialCounts()[size_t(m)];
        double mm3 = 0;
        for (uint16_t id : {1, 2, 3}) {
            const auto& r = all.at(id).removedMm3;
            const double own = r.count(name) ? r.at(name) : 0.0;
            EXPECT_EQ(own, double(removed(id)) * voxel) << name;
            mm3 += own;
        }
        EXPECT_EQ(mm3, double(whole) * voxel) << name; // exact: eighths of a mm^3
    }
    // Drilling time, path and force figures come from the applied states.
    const ParticipantMetrics& a = all.at(1);
    EXPECT_NEAR(a.drillingS, 0.001 * 5 * 70, 0.0051);
    EXPECT_NEAR(a.pathLengthMm, 3.5, 0.06);
    EXPECT_NEAR(a.meanSpeedMmS, a.pathLengthMm / a.drillingS, 1e-9);
    EXPECT_DOUBLE_EQ(a.maxForceN, 2.0);
    EXPECT_DOUBLE_EQ(a.meanForceN, 2.0);
    EXPECT_EQ(a.strokes, 1u);
    EXPECT_EQ(a.toolS.count("burr 4 mm"), 1u);
}

TEST(Assessment, ZonesAreConfigurable) {
    AssessmentConfig wide;
    wide.cautionMm = 8.0f;
    wide.dangerMm = 5.0f;
    Rig rig(sinusUnderBone(), wide);
    rig.join(1, "ada", Role::Trainee);
    // The burr's closest approach: 7.25 - 1.5 = 5.75 mm, caution under these zones.
    rig.run({rig.tool(1, {0.0f, 0.0f, 3.0f}, false)});
    auto w = rig.warnings();
    ASSERT_EQ(w.size(), 1u);
    EXPECT_EQ(w[0].first.zone, Zone::Caution);
    EXPECT_NEAR(w[0].first.distanceMm, 5.75f, 0.05f);
    AssessmentConfig bad;
    bad.dangerMm = 4.0f;
    EXPECT_THROW(bad.validate(), Error);
}

TEST(Assessment, StrokesAreCutAtSharpTurns) {
    StrokeCounter straight;
    straight.start({0, 0, 0});
    for (int i = 1; i <= 100; ++i)
        straight.add({0.1f * float(i), 0, 0});
    EXPECT_EQ(straight.strokes(), 1u);
    // Back and forth three times along x: three strokes.
    StrokeCounter zigzag;
    zigzag.start({0, 0, 0});
    float x = 0;
    for (int leg = 0; leg < 3; ++leg)
        for (int i = 0; i < 100; ++i) {
            x += leg % 2 ? -0.1f : 0.1f;
            zigzag.add({x, 0.02f * float(leg), 0});
        }
    EXPECT_EQ(zigzag.strokes(), 3u);
    // A gentle arc is one stroke.
    StrokeCounter arc;
    arc.start({10, 0, 0});
    for (int i = 1; i <= 200; ++i) {
        const float t = float(i) * 0.01f;
        arc.add({10 * std::cos(t), 10 * std::sin(t), 0});
    }
    EXPECT_EQ(arc.strokes(), 1u);
}

TEST(Assessment, ReportAndDebriefHoldEveryParticipant) {
    Rig rig(sinusUnderBone());
    rig.join(1, "ada <lee>", Role::Trainee);
    rig.join(2, "iris", Role::Instructor);
    for (int batch = 0; batch < 40; ++batch) {
        std::vector<LogRecord> dwell; // 40 ms at each depth: the cortical table erodes through
        for (int i = 0; i < 40; ++i)
            dwell.push_back(rig.tool(1, {0.0f, 0.0f, 6.0f - 0.25f * float(batch)}, true, 0.5f));
        rig.run(dwell);
    }
    rig.step.assessment().finish(rig.now);
    const nlohmann::ordered_json j =
        rig.book.read([](const ServerReport& r) { return toJson(r.participants); });
    ASSERT_EQ(j.size(), 2u);
    EXPECT_EQ(j[0]["name"], "ada <lee>");
    EXPECT_EQ(j[0]["role"], "trainee");
    const auto& m = j[0]["metrics"];
    for (const char* key : {"drilling_time_s", "bone_removed_mm3", "contacts", "closest_mm",
                            "warnings", "max_force_n", "path_length_mm"})
        EXPECT_TRUE(m.contains(key)) << key;
    EXPECT_GT(m["bone_removed_mm3"]["cortical"].get<double>(), 0.0);
    EXPECT_EQ(m["contacts"]["sinus"], 1);
    EXPECT_EQ(m["contacts"]["dura"], 0);
    EXPECT_GE(m["warnings"].get<int>(), 3);
    EXPECT_EQ(j[1]["role"], "instructor");

    const std::filesystem::path dir =
        std::filesystem::temp_directory_path() / ("trephine-debrief-" + std::to_string(::getpid()));
    const Assessment& a = rig.step.assessment();
    const auto files = writeDebriefs(dir.string(), a, a.metrics(rig.now), a.timelines());
    ASSERT_EQ(files.size(), 2u);
    std::ifstream md(files[0]);
    std::stringstream text;
    text << md.rdbuf();
    EXPECT_NE(text.str().find("| sinus |"), std::string::npos);
    EXPECT_NE(text.str().find("1-ada__lee_-distance.svg"), std::string::npos);
    std::ifstream svg(dir / "1-ada__lee_-distance.svg");
    std::stringstream plot;
    plot << svg.rdbuf();
    EXPECT_NE(plot.str().find("<polyline"), std::string::npos);
    EXPECT_NE(plot.str().find("danger"), std::string::npos);
    // Each warning is marked: a vertical line with its title.
    EXPECT_NE(plot.str().find("<title>violation sinus"), std::string::npos);
    std::filesystem::remove_all(dir);
}

TEST(Assessment, SkullStructuresHaveFields) {
    ReportBook book;
    const Volume skull = makeSkull(64, 1);
    Assessment a(skull, {}, book);
    ASSERT_GE(a.fields().size(), 1u);
    EXPECT_EQ(a.fields().structure(0).name, "dura");
    const AssessmentSummary s = book.read([](const ServerReport& r) { return r.assessment; });
    EXPECT_EQ(s.structures.size(), a.fields().size());
    EXPECT_GT(s.fieldBytes, 0u);
}

TEST(AssessmentProtocol, MessagesRoundTripAndOutOfRangeIsMalformed) {
    SafetyWarning w;
    w.clientId = 7;
    w.zone = Zone::Danger;
    w.previous = Zone::Caution;
    w.structure = "sinus";
    w.distanceMm = 0.75f;
    w.toolSequence = 99;
    w.serverTimeUs = 123456;
    std::vector<uint8_t> bytes = encodeMessage(w);
    SafetyWarning back;
    ASSERT_TRUE(decodeMessage(bytes, back));
    EXPECT_EQ(back.structure, "sinus");
    EXPECT_EQ(back.zone, Zone::Danger);
    EXPECT_FLOAT_EQ(back.distanceMm, 0.75f);
    bytes[3] = 4; // the zone byte: no fifth zone
    EXPECT_FALSE(decodeMessage(bytes, back));

    AssessmentSnapshot s;
    s.serverTimeUs = 5;
    ParticipantFigures f;
    f.clientId = 2;
    f.zone = Zone::Violation;
    f.removed.push_back({uint8_t(Material::Cortical), 12.5f});
    f.structures.push_back({"dura", 0.5f, 1.5f, 2});
    f.tools.push_back({"burr 4 mm", 3.0f});
    s.list.push_back(f);
    f.clientId = 1; // out of order: malformed
    AssessmentSnapshot unordered = s;
    unordered.list.push_back(f);
    bytes = encodeMessage(s);
    AssessmentSnapshot sback;
    ASSERT_TRUE(decodeMessage(bytes, sback));
    ASSERT_EQ(sback.list.size(), 1u);
    EXPECT_EQ(sback.list[0].structures[0].contacts, 2u);
    EXPECT_EQ(sback.list[0].tools[0].tool, "burr 4 mm");
    EXPECT_FALSE(decodeMessage(encodeMessage(unordered), sback));
    bytes.pop_back(); // cut short
    EXPECT_FALSE(decodeMessage(bytes, sback));
}

// Over loopback ENet: the same rules reach real clients.
TEST(AssessmentSession, WarningsAndSnapshotsReachWhomTheyShould) {
    using namespace trephine::testing;
    const Volume v = sinusUnderBone();
    SessionServer server(v, loopbackServerConfig("sinus"));
    Pumped pumped(server);
    SessionClient ada(namedClientConfig(v, "ada", Role::Trainee, 32));
    SessionClient ben(namedClientConfig(v, "ben", Role::Trainee, 32));
    SessionClient iris(namedClientConfig(v, "iris", Role::Instructor, 32));
    std::vector<SessionClient*> all{&ada, &ben, &iris};
    for (SessionClient* c : all)
        c->connect(loopback(server.port()));
    ASSERT_TRUE(pumpUntil(all, [&] {
        return ada.welcomed() && ben.welcomed() && iris.welcomed() &&
               iris.participants().size() == 3;
    }));
    const uint16_t adaId = ada.welcome().clientId, benId = ben.welcome().clientId;
    // Ada's burr goes down onto the sinus; Ben's stays high above the bone.
    float z = 6.0f;
    ASSERT_TRUE(pumpUntil(all, [&] {
        ToolState t;
        t.diameterMm = 3.0f;
        t.position = {0.0f, 0.0f, z};
        z = std::max(-4.0f, z - 0.05f);
        ada.sendToolState(t);
        t.position = {8.0f, 8.0f, 9.0f};
        ben.sendToolState(t);
        auto mine = ada.warnings().find(adaId);
        auto seen = iris.warnings().find(adaId);
        return mine != ada.warnings().end() && mine->second.zone == Zone::Violation &&
               seen != iris.warnings().end() && seen->second.zone == Zone::Violation &&
               iris.assessment().list.size() == 3 && ben.snapshotsReceived() > 0 &&
               ada.snapshotsReceived() > 0;
    }));
    EXPECT_EQ(ben.warningsReceived(), 0u) << "another trainee's warnings never reach a trainee";
    ASSERT_EQ(ben.assessment().list.size(), 1u);
    EXPECT_EQ(ben.assessment().list[0].clientId, benId);
    ASSERT_EQ(ada.assessment().list.size(), 1u);
    std::set<Zone> zones;
    for (const SafetyWarning& w : iris.warningLog())
        zones.insert(w.zone);
    EXPECT_TRUE(zones.count(Zone::Danger)) << "the instructor heard of the danger before";
    for (SessionClient* c : all)
        c->disconnect();
    server.stop();
    const nlohmann::json report = nlohmann::json::parse(server.reportJson());
    ASSERT_EQ(report["participants"].size(), 3u);
    std::map<std::string, nlohmann::json> byName; // ids follow the order the connections came in
    for (const auto& p : report["participants"])
        byName[p["name"].get<std::string>()] = p;
    EXPECT_EQ(byName.at("ada")["id"], adaId);
    EXPECT_EQ(byName.at("ada")["metrics"]["contacts"]["sinus"], 1);
    EXPECT_GE(byName.at("ada")["metrics"]["warnings"].get<int>(), 3);
    EXPECT_EQ(byName.at("ben")["metrics"]["warnings"], 0);
    EXPECT_EQ(byName.at("iris")["role"], "instructor");
    // No artery in this volume: the structures present only.
    EXPECT_EQ(report["assessment"]["structures"], nlohmann::json::array({"dura", "sinus"}));
}

TEST(Assessment, OnTheSkullTheDangerWarningPrecedesContactWithTheSinus) {
    const Volume skull = makeSkull(128);
    // A column down the midline whose first soft tissue under the bone is the sinus.
    const glm::ivec3 d = skull.dims();
    glm::vec3 top(0.0f), sinus(0.0f);
    bool found = false;
    for (int y = d.y / 2; y < d.y && !found; ++y)
        for (int x : {d.x / 2 - 1, d.x / 2}) {
            int z = d.z - 1;
            while (z >= 0 && skull.material(x, y, z) == Material::Air)
                --z;
            int bone = z;
            while (z >= 0 && isBone(skull.material(x, y, z)))
                --z;
            if (z >= 0 && bone > z && skull.material(x, y, z) == Material::Sinus) {
                top = skull.voxelCenter({x, y, bone});
                sinus = skull.voxelCenter({x, y, z});
                found = true;
                break;
            }
        }
    ASSERT_TRUE(found) << "skull:128 has a sinus under the vault's midline";
    Rig rig(skull);
    rig.join(1, "ada", Role::Trainee);
    // Straight down from 4 mm above the bone at 4 mm/s, drilling, 1 kHz states.
    uint32_t firstDanger = 0, firstViolation = 0;
    bool contact = false;
    glm::vec3 p = top + glm::vec3(0.0f, 0.0f, 4.0f);
    for (int batch = 0; batch < 1000 && !contact && p.z > sinus.z - 3.0f; ++batch) {
        std::vector<LogRecord> events;
        for (int i = 0; i < 10; ++i, p.z -= 0.004f)
            events.push_back(rig.tool(1, p, true));
        rig.run(events);
        for (auto& [w, to] : rig.warnings()) {
            if (w.zone == Zone::Danger && !firstDanger)
                firstDanger = w.toolSequence;
            if (w.zone == Zone::Violation && !firstViolation)
                firstViolation = w.toolSequence;
        }
        contact = rig.metrics(1).structures.at("sinus").contacts > 0;
    }
    ASSERT_TRUE(contact) << "the burr reached the sinus";
    ASSERT_NE(firstDanger, 0u);
    EXPECT_LT(firstDanger, firstViolation);
    EXPECT_EQ(rig.metrics(1).structures.at("dura").contacts, 0u) << "the sinus first";
}

// Participants' colours: the server gives each participant one, so every window draws the same
// person in the same colour; a newcomer gets a colour nobody wears, and a leaver's colour is free
// again while everyone else keeps theirs. No sockets: the policy on its own.
#include "net/participant_colours.h"
#include "net/session_policy.h"

#include "libsim/skull.h"
#include "net/view.h"

#include <gtest/gtest.h>

#include <set>

using namespace trephine;
using namespace trephine::net;

namespace {

struct Rig {
    ServerConfig config;
    ReportBook book;
    std::optional<SessionPolicy> policy;
    uint64_t now = 1'000'000;
    Rig() {
        config.volumeName = "sphere:32";
        const Volume sphere = makeSphere(32);
        config.scene = std::make_shared<const Scene>(buildScene(sphere));
        policy.emplace(config, sphere.dims(), sphere.spacing(), book,
                       [](const ToolState&, glm::vec3) { return SessionPolicy::ForceAnswer{}; });
    }
    uint16_t join(const std::string& name, Role role) {
        PolicyOutput out;
        const uint16_t id = policy->connect(kProtocolVersion, now, out);
        Hello h;
        h.name = name;
        h.role = role;
        h.view.width = h.view.height = 32;
        policy->receive(id, encodeMessage(h), now);
        return id;
    }
    // The roster each listed client got at the next pass, by receiver.
    std::map<uint16_t, std::map<uint16_t, Rgb8>> rosters() {
        now += 100'000;
        PolicyOutput out;
        policy->update(now, out);
        std::map<uint16_t, std::map<uint16_t, Rgb8>> got;
        for (const PolicyOutput::Message& m : out.messages) {
            Participants p;
            if (peekMessageType(m.bytes) != uint8_t(MessageType::Participants))
                continue;
            EXPECT_TRUE(decodeMessage(m.bytes, p));
            for (uint16_t to : m.to)
                for (const ParticipantInfo& i : p.list)
                    got[to][i.clientId] = i.colour;
        }
        return got;
    }
};

std::set<std::tuple<int, int, int>> distinct(const std::map<uint16_t, Rgb8>& colours) {
    std::set<std::tuple<int, int, int>> s;
    for (const auto& [id, c] : colours)
        s.insert({c.r, c.g, c.b});
    return s;
}

} // namespace

TEST(ParticipantColours, EveryoneSeesTheSameColourForEachParticipant) {
    Rig rig;
    const uint16_t alex = rig.join("Alex", Role::Trainee);
    const uint16_t drK = rig.join("Dr K", Role::Instructor);
    const uint16_t bo = rig.join("Bo", Role::Trainee);
    auto got = rig.rosters();
    ASSERT_EQ(got.size(), 3u) << "everyone got the roster";
    for (uint16_t who : {alex, drK, bo}) {
        ASSERT_EQ(got[who].size(), 3u);
        EXPECT_EQ(got[who], got[alex]) << "client " << who << " sees the colours Alex sees";
    }
    EXPECT_EQ(distinct(got[alex]).size(), 3u) << "three people, three colours";

    // Bo leaves and Cy joins: Cy wears Bo's freed colour, Alex and Dr K keep theirs.
    const auto before = got[alex];
    PolicyOutput out;
    rig.policy->disconnect(bo, rig.now, out);
    const uint16_t cy = rig.join("Cy", Role::Trainee);
    got = rig.rosters();
    ASSERT_EQ(got[drK].size(), 3u);
    EXPECT_EQ(got[drK].at(alex), before.at(alex));
    EXPECT_EQ(got[drK].at(drK), before.at(drK));
    EXPECT_EQ(got[drK].at(cy), before.at(bo)) << "the colour nobody wears any more";
    EXPECT_EQ(got[cy], got[drK]);
}

TEST(ParticipantColours, ANewcomerGetsAColourNobodyWearsThenTheLeastWorn) {
    const auto palette = participantPalette();
    ASSERT_GE(palette.size(), 6u);
    EXPECT_EQ(pickParticipantColour({}), 0);
    EXPECT_EQ(pickParticipantColour({0, 1, 3}), 2);
    std::vector<uint8_t> all;
    for (size_t i = 0; i < palette.size(); ++i)
        all.push_back(uint8_t(i));
    EXPECT_EQ(pickParticipantColour(all), 0) << "all worn once: the lowest";
    all.push_back(0);
    EXPECT_EQ(pickParticipantColour(all), 1) << "0 worn twice";
    // The palette's colours are told apart.
    for (size_t i = 0; i < palette.size(); ++i)
        for (size_t j = i + 1; j < palette.size(); ++j)
            EXPECT_NE(palette[i], palette[j]) << i << " " << j;
}

TEST(ParticipantColours, TheColourTravelsInTheRoster) {
    Participants p;
    p.list.push_back({3, Role::Trainee, Sync::Dbi, "Alex", 0, {217, 89, 51}});
    Participants back;
    ASSERT_TRUE(decodeMessage(encodeMessage(p), back));
    ASSERT_EQ(back.list.size(), 1u);
    EXPECT_EQ(back.list[0].colour, (Rgb8{217, 89, 51}));
    // Cut inside the colour: malformed.
    std::vector<uint8_t> bytes = encodeMessage(p);
    bytes.pop_back();
    EXPECT_FALSE(decodeMessage(bytes, back));
}

// The message list (TREPHINE_MESSAGES) against what is built from it: docs/protocol.md's tables,
// the dispatch each side goes through, and the server's refusal of messages only it sends.
#include "net/messages.h"

#include "net/budgets.h"
#include "net/session_policy.h"

#include "libsim/skull.h"

#include <gtest/gtest.h>

#include <fstream>
#include <map>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

using namespace trephine;
using namespace trephine::net;

namespace {

std::string readDoc(const std::string& name) {
    std::ifstream in(std::string(TREPHINE_SOURCE_DIR) + "/docs/" + name);
    EXPECT_TRUE(in) << "docs/" << name << " not found under " << TREPHINE_SOURCE_DIR;
    std::stringstream ss;
    ss << in.rdbuf();
    return ss.str();
}

std::string trim(const std::string& s) {
    const size_t a = s.find_first_not_of(' ');
    const size_t b = s.find_last_not_of(' ');
    return a == std::string::npos ? std::string() : s.substr(a, b - a + 1);
}

// The cells of a Markdown table row ("| a | b |"), trimmed.
std::vector<std::string> cells(const std::string& line) {
    std::vector<std::string> out;
    size_t at = 1;
    for (size_t bar; (bar = line.find('|', at)) != std::string::npos; at = bar + 1)
        out.push_back(trim(line.substr(at, bar - at)));
    return out;
}

// The body rows of the table whose header row is exactly `header`.
std::vector<std::vector<std::string>> tableRows(const std::string& doc, const std::string& header) {
    std::vector<std::vector<std::string>> rows;
    std::istringstream in(doc);
    std::string line;
    bool inTable = false;
    while (std::getline(in, line)) {
        if (!inTable) {
            inTable = line == header;
            continue;
        }
        if (line.empty() || line[0] != '|')
            break;
        if (line.rfind("|---", 0) != 0)
            rows.push_back(cells(line));
    }
    return rows;
}

const char* directionText(Direction d) {
    switch (d) {
    case Direction::ClientToServer:
        return "client → server";
    case Direction::ServerToClient:
        return "server → client";
    case Direction::Both:
        return "both";
    }
    return "?";
}

} // namespace

TEST(MessageTable, DocsListMatchesTheCode) {
    const auto rows = tableRows(readDoc("protocol.md"),
                                "| type | name | direction | channel | newest wins | since |");
    ASSERT_EQ(rows.size(), kMessages.size()) << "one row a message in docs/protocol.md's list";
    for (size_t i = 0; i < rows.size(); ++i) {
        const MessageInfo& m = kMessages[i];
        ASSERT_EQ(rows[i].size(), 6u) << "row " << i;
        EXPECT_EQ(rows[i][0], std::to_string(int(m.type)));
        EXPECT_EQ(rows[i][1], m.name);
        EXPECT_EQ(rows[i][2], directionText(m.direction)) << m.name;
        EXPECT_EQ(rows[i][3], channelName(m.channel)) << m.name;
        EXPECT_EQ(rows[i][4], m.newestWins ? "yes" : "no") << m.name;
        EXPECT_EQ(rows[i][5], std::to_string(m.since)) << m.name;
        EXPECT_LE(m.since, kProtocolVersion) << m.name;
    }
}

TEST(MessageTable, DocsFieldsTableHasEveryMessageInTypeOrder) {
    const auto rows = tableRows(readDoc("protocol.md"), "| type | name | fields |");
    ASSERT_EQ(rows.size(), kMessages.size());
    for (size_t i = 0; i < rows.size(); ++i) {
        EXPECT_EQ(rows[i].at(0), std::to_string(int(kMessages[i].type)));
        EXPECT_EQ(rows[i].at(1), kMessages[i].name);
    }
}

TEST(MessageTable, DocsVersionsTableListsEveryVersion) {
    const auto rows = tableRows(readDoc("protocol.md"), "| version | changes |");
    ASSERT_EQ(rows.size(), size_t(kProtocolVersion));
    for (size_t i = 0; i < rows.size(); ++i)
        EXPECT_EQ(rows[i].at(0), std::to_string(i + 1));
    // Each message is named in the row of the version it came in.
    for (const MessageInfo& m : kMessages)
        EXPECT_NE(rows[m.since - 1].at(1).find(m.name), std::string::npos)
            << m.name << " in version " << m.since << "'s row";
}

// Each side's dispatch calls a handler for exactly the messages the list says it receives, and
// answers `otherwise` for the rest: another side's messages and bytes of no message.
TEST(MessageTable, EachSideDispatchesWhatItReceivesOnly) {
    for (Side side : {Side::Client, Side::Server}) {
        size_t handled = 0;
        for (int type = 0; type < 256; ++type) {
            std::optional<MessageType> called;
            const auto handler = [&]<typename M>(MessageTag<M>) {
                called = M::kType;
                return 1;
            };
            const int r = side == Side::Server
                              ? dispatchReceived<Side::Server>(uint8_t(type), handler, -1)
                              : dispatchReceived<Side::Client>(uint8_t(type), handler, -1);
            const MessageInfo* m = messageInfo(uint8_t(type));
            const bool receives = m && net::receives(side, m->direction);
            EXPECT_EQ(r, receives ? 1 : -1) << "type " << type;
            EXPECT_EQ(called.has_value(), receives) << "type " << type;
            if (called) {
                EXPECT_EQ(uint8_t(*called), type);
            }
            handled += receives;
        }
        // 11 client -> server, 15 server -> client, 3 both ways.
        EXPECT_EQ(handled, side == Side::Server ? 14u : 18u);
    }
}

TEST(MessageTable, ControlBudgetHoldsTheNewestOfTheControlMessagesWhoseNewestWins) {
    ControlBudget budget(0); // always over budget
    for (const MessageInfo& m : kMessages) {
        const std::vector<uint8_t> msg = {uint8_t(m.type), 1};
        const ControlBudget::Action a = budget.offer(1, msg, 1);
        if (m.newestWins && m.channel == Channel::Control)
            EXPECT_EQ(a, ControlBudget::Action::Hold) << m.name;
        else if (m.type == MessageType::Pong)
            EXPECT_EQ(a, ControlBudget::Action::Drop);
        else
            EXPECT_EQ(a, ControlBudget::Action::Send) << m.name;
    }
}

// A client that sends, well-formed, a message only the server sends is malformed, counted and
// not acted on: the policy reads who sends what from the list.
TEST(MessageTable, TheServerRefusesMessagesOnlyItSends) {
    ServerConfig config;
    config.volumeName = "sphere:16";
    config.malformedLimit = 1000;
    const Volume sphere = makeSphere(16);
    config.scene = std::make_shared<const Scene>(buildScene(sphere));
    ReportBook book;
    SessionPolicy policy(config, sphere.dims(), sphere.spacing(), book,
                         [](const ToolState&, glm::vec3) { return SessionPolicy::ForceAnswer{}; });
    uint64_t now = 1'000'000;
    PolicyOutput out;
    const uint16_t id = policy.connect(kProtocolVersion, now, out);
    ASSERT_NE(id, 0);
    Hello h;
    h.view.width = h.view.height = 32;
    ASSERT_FALSE(policy.receive(id, encodeMessage(h), now).malformed);
    policy.update(now, out);

    Welcome w;
    w.volumeDims = {16, 16, 16};
    w.volumeName = "forged";
    Pong pong{1, 2};
    Participants roster;
    ParticipantView seen{id, h.view};
    const std::vector<std::vector<uint8_t>> fromServer = {
        encodeMessage(w), encodeMessage(pong), encodeMessage(roster), encodeMessage(seen)};
    for (const std::vector<uint8_t>& m : fromServer) {
        ASSERT_FALSE(m.empty());
        ASSERT_FALSE(receives(Side::Server, messageInfo(m[0])->direction));
        now += 1000;
        const PolicyOutput answer = policy.receive(id, m, now);
        EXPECT_TRUE(answer.malformed) << messageInfo(m[0])->name;
        EXPECT_TRUE(answer.messages.empty()) << messageInfo(m[0])->name;
    }
    // A ping, which clients send, is still answered.
    Ping ping{7};
    const PolicyOutput answer = policy.receive(id, encodeMessage(ping), now);
    EXPECT_FALSE(answer.malformed);
    EXPECT_EQ(answer.messages.size(), 1u);
    EXPECT_EQ(book.read([&](const ServerReport& r) { return r.peers.at(id).malformed; }),
              uint64_t(fromServer.size()));
}

// What the view says and where: the link's message (connecting, lost with the picture dimmed, the
// likely causes after a few failures) and labels placed so they avoid each other. No GL.
#include "ui/layout.h"
#include "ui/link_message.h"

#include "net/protocol.h"

#include <gtest/gtest.h>

using namespace trephine;
using namespace trephine::ui;

namespace {

bool overlap(const UiRect& a, const UiRect& b) {
    return a.x < b.x + b.w && b.x < a.x + a.w && a.y < b.y + b.h && b.y < a.y + a.h;
}

bool has(const std::string& text, const std::string& part) {
    return text.find(part) != std::string::npos;
}

} // namespace

TEST(LinkMessage, AWrongAddressOrPortGetsItsLikelyCausesAfterAFewAttempts) {
    using net::LinkState;
    const std::string addr = "10.0.0.7:7778";
    LinkMessage m = linkMessage(LinkState::Connecting, 1, -1, "", addr, false);
    EXPECT_EQ(m.text, "Connecting to 10.0.0.7:7778 (attempt 1)...");
    EXPECT_FALSE(m.dim) << "no picture to dim";
    m = linkMessage(LinkState::Connecting, 3, -1, "", addr, false);
    EXPECT_FALSE(has(m.text, "Likely causes")) << "two failures: not yet\n" << m.text;
    m = linkMessage(LinkState::Retrying, 3, -1, "no answer", addr, false);
    EXPECT_TRUE(has(m.text, "No answer after 3 attempts. Likely causes:")) << m.text;
    EXPECT_TRUE(has(m.text, "is not running")) << m.text;
    EXPECT_TRUE(has(m.text, "wrong address")) << m.text;
    EXPECT_TRUE(has(m.text, "UDP port 7778")) << m.text;
    EXPECT_TRUE(linkMessage(LinkState::Connected, 3, -1, "", addr, true).text.empty());
    const std::string busy = net::refuseReasonText(uint32_t(net::RefuseReason::Busy));
    // Told busy while connecting (the client tries again by itself): said at once.
    m = linkMessage(LinkState::Connecting, 1, -1, busy, addr, false);
    EXPECT_EQ(m.text, "Connecting to 10.0.0.7:7778 (attempt 1)...\n" + busy);
    // A server that said it is busy is there: no hints that it is not.
    m = linkMessage(LinkState::Retrying, 5, -1, addr + " is busy: " + busy, addr, false);
    EXPECT_TRUE(has(m.text, "every place for joining is taken")) << m.text;
    EXPECT_FALSE(has(m.text, "Likely causes")) << m.text;
}

TEST(LinkMessage, ALostServerDimsThePictureAndSaysSo) {
    using net::LinkState;
    // Up on attempt 2, then lost: reconnecting on attempt 3.
    LinkMessage m = linkMessage(LinkState::Connecting, 3, 2, "the server stopped", "h:7777", true);
    EXPECT_TRUE(m.dim);
    EXPECT_TRUE(has(m.text, "Lost the server at h:7777: the server stopped")) << m.text;
    EXPECT_FALSE(has(m.text, "Likely causes")) << "failures count from the last connection";
    m = linkMessage(LinkState::Retrying, 5, 2, "timed out", "h:7777", true);
    EXPECT_TRUE(has(m.text, "has stopped")) << m.text;
}

// A view the server does not serve says why: one larger than any it serves, or one past the
// session's total that it refused, while the window is that size; nothing otherwise.
TEST(LinkMessage, AViewTheServerDoesNotServeSaysWhy) {
    net::ClientSnapshot snap;
    EXPECT_EQ(net::viewNotServedText(snap, 900, 900, "--size"), "") << "not connected yet";
    snap.state = net::LinkState::Connected;
    snap.welcome = net::Welcome{};
    snap.welcome->maxViewPixels = 640000;
    EXPECT_EQ(net::viewNotServedText(snap, 900, 900, "--size"),
              "The server serves views of at most 640000 pixels; this view is 900 x 900: restart "
              "with --size 800 or less");
    EXPECT_EQ(net::viewNotServedText(snap, 700, 500, "--size"), "");
    snap.viewRefusal = net::ViewRefusal{700, 500, 120000};
    EXPECT_EQ(net::viewNotServedText(snap, 700, 500, "--size"),
              "The session's views are full: the server has 120000 pixels free for your view and "
              "this one is 700 x 500");
    EXPECT_EQ(net::viewNotServedText(snap, 300, 300, "--size"), "") << "another size: asked anew";
}

TEST(Labels, LabelsAtOnePointDoNotCoverEachOther) {
    const UiRect view{0, 0, 500, 500};
    std::vector<LabelRequest> at(5, LabelRequest{200, 200, 80, 14});
    at.push_back({205, 198, 120, 14}); // a mark's label next to them
    const std::vector<UiRect> placed = placeLabels(at, view);
    ASSERT_EQ(placed.size(), at.size());
    for (size_t i = 0; i < placed.size(); ++i) {
        EXPECT_GE(placed[i].x, 0.0f);
        EXPECT_LE(placed[i].x + placed[i].w, 500.0f);
        for (size_t j = 0; j < i; ++j)
            EXPECT_FALSE(overlap(placed[i], placed[j])) << i << " and " << j;
    }
    EXPECT_EQ(placed[0].x, 210.0f) << "the first keeps its place right of its anchor";
    // Near the view's right edge a label goes to the anchor's left rather than out of the view.
    const auto edge = placeLabels({{490, 100, 80, 14}}, view);
    EXPECT_LE(edge[0].x + edge[0].w, 500.0f);
}

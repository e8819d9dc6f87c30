// The trainee's scripts (net/scripts.h): `--script burrhole` is one hole in every shell.
#include "net/scripts.h"

#include "libsim/tool_catalogue.h"

#include <glm/geometric.hpp>
#include <gtest/gtest.h>

using namespace trephine;
using namespace trephine::net;

// The headless trainee's burr hole is the window's, sampled at 100 Hz: the same poses, drilling
// while the window's drills, a 5 mm burr, lifted and resting at its end.
TEST(Scripts, TheBurrholeScriptIsTheWindowsHoleSampledAt100Hz) {
    const SurfaceSite site{{1.0f, 2.0f, 60.0f}, glm::normalize(glm::vec3(0.2f, 0.1f, 1.0f))};
    const std::vector<ScriptSample> script = burrholeScript(site);
    ASSERT_EQ(script.size(), size_t(kBurrholeSeconds * 100.0 + 0.5) + 1);
    int drilling = 0;
    for (const ScriptSample& s : script) {
        const ScriptPose p = burrholePose(site, s.t);
        EXPECT_LT(glm::length(s.tool.position - p.position), 1e-5f) << s.t;
        EXPECT_LT(glm::length(s.tool.orientation * glm::vec3(0, 0, 1) - p.axis), 1e-5f) << s.t;
        EXPECT_EQ(s.tool.drilling, p.drilling) << s.t;
        EXPECT_EQ(s.tool.toolKind, uint8_t(ToolKind::Burr));
        EXPECT_EQ(s.tool.diameterMm, kBurrholeDiameterMm);
        drilling += s.tool.drilling;
    }
    EXPECT_EQ(drilling, 400) << "plunge 1 s, spiral 3 s";
    EXPECT_FALSE(script.back().tool.drilling);
    EXPECT_TRUE(burrholePose(site, script.back().t + 0.01).done);
    // A shorter run is the hole's start, and stops drilling at its end.
    const std::vector<ScriptSample> second = burrholeScript(site, 1.0);
    ASSERT_EQ(second.size(), 101u);
    EXPECT_TRUE(second[99].tool.drilling);
    EXPECT_FALSE(second.back().tool.drilling);
    EXPECT_EQ(second[50].tool.position, script[50].tool.position);
}

// Predicted image updates end to end: a zstd client receives rectangles coded against the pixels
// it holds, ends up with exactly what the quantised codec gives for a fresh server render, and a
// client whose copy the server no longer knows refuses the update and resynchronises.
#include "net/session_client.h"
#include "net/session_server.h"

#include "libsim/dirty_rect.h"
#include "libsim/skull.h"
#include "net/codec.h"
#include "net/view.h"

#include "loopback.h"

#include <gtest/gtest.h>

using namespace trephine;
using namespace trephine::net;
using trephine::testing::loopback;
using trephine::testing::loopbackServerConfig;
using trephine::testing::pumpUntil;
using trephine::testing::quantised;

namespace {

struct Fixture : trephine::testing::PaperZstdSession {
    bool converged() {
        return pumpUntil({client.get()}, [&] {
            return server->idle() && client->hasFullImage() &&
                   client->dbi() == quantised(server->renderView(view), view);
        });
    }
};

} // namespace

TEST(SessionPredicted, BurstsOfCutsConvergeExactlyWithoutResyncs) {
    Fixture f;
    // Cuts submitted back to back while the client is not polling: updates pile up and merge.
    for (int round = 0; round < 3; ++round) {
        for (int i = 0; i < 20; ++i)
            f.server->submitBoxCut(surfaceBox(f.volume, 3 + i % 4, (i * 7) % 21 - 10));
        ASSERT_TRUE(f.converged()) << "round " << round;
    }
    EXPECT_GT(f.client->predictedApplied(), 0u);
    EXPECT_EQ(f.client->resyncs(), 0u);
    EXPECT_EQ(f.client->updatesRejected(), 0u);
}

TEST(SessionPredicted, AClientWhoseCopyDiffersResynchronisesInsteadOfShowingWrongPixels) {
    Fixture f;
    const Box3i box = surfaceBox(f.volume, 6);
    const PixelRect rect = dirtyScreenRect(toCamera(f.view), f.volume, box);
    ASSERT_FALSE(rect.empty());
    // A pixel in the rectangle the next update covers no longer matches the server's copy.
    f.client->damagePixelForTest(rect.x + rect.w / 2, rect.y + rect.h / 2);
    f.server->submitBoxCut(box);
    ASSERT_TRUE(pumpUntil({f.client.get()}, [&] { return f.client->resyncs() > 0; }));
    ASSERT_TRUE(f.converged()); // the full image that answered the resync repaired it
    EXPECT_EQ(f.client->updatesRejected(), 0u);
}

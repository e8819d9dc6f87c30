// A server started with the GPU renderer (llvmpipe through EGL here) serves a trainee the picture
// a CPU server serves, within the renderers' tolerance, before and after the same drilling; and
// its own updates converge bit for bit on its own full render. Both servers are pumped.
#include "libsim_gpu/gpu_renderer.h"

#include "dbi_agreement.h"
#include "gpu_test.h"
#include "loopback.h"

#include "libsim/skull.h"
#include "net/codec.h"
#include "net/session_client.h"
#include "net/session_server.h"
#include "net/view.h"

#include <gtest/gtest.h>

#include <algorithm>

using namespace trephine;
using namespace trephine::net;
using trephine::testing::agree;
using trephine::testing::expectAgreement;
using trephine::testing::loopback;
using trephine::testing::loopbackServerConfig;
using trephine::testing::Pumped;
using trephine::testing::pumpUntil;

namespace {

using GpuServerTest = trephine::testing::GpuTest;

// A raw-coded trainee of `server` with the working view.
std::unique_ptr<SessionClient> trainee(SessionServer& server, const ViewSpec& view) {
    ClientConfig cc;
    cc.codec = Codec::Raw;
    cc.view = view;
    auto c = std::make_unique<SessionClient>(cc);
    c->connect(loopback(server.port()));
    return c;
}

bool converged(SessionServer& server, SessionClient& client) {
    return client.hasFullImage() && server.idle() &&
           compare(client.dbi(), server.renderView(client.view())).identical();
}

} // namespace

TEST_F(GpuServerTest, ATraineeOfAGpuServerSeesTheCpuServersPicture) {
    const Volume skull = makeSkull(64);
    const ViewSpec view = toViewSpec(cameraPreset("working", skull, {160, 160}));
    const Camera cam = toCamera(view);
    const float voxel = std::min({skull.spacing().x, skull.spacing().y, skull.spacing().z});

    SessionServer cpuServer(skull, loopbackServerConfig("skull:64"));
    ServerConfig gpuConfig = loopbackServerConfig("skull:64");
    std::string why;
    auto factory = gpu::chooseRenderer(gpu::RendererChoice::Gpu, &why);
    ASSERT_TRUE(factory) << why;
    gpuConfig.renderer = *factory;
    SessionServer gpuServer(skull, gpuConfig);
    Pumped pumpedCpu(cpuServer), pumpedGpu(gpuServer);
    auto onCpu = trainee(cpuServer, view), onGpu = trainee(gpuServer, view);
    const std::vector<SessionClient*> both{onCpu.get(), onGpu.get()};
    ASSERT_TRUE(pumpUntil(both, [&] { return onCpu->hasFullImage() && onGpu->hasFullImage(); }));
    expectAgreement(agree(onGpu->dbi(), onCpu->dbi(), cam, voxel));
    const Dbi before = onGpu->dbi();

    // The same burr stroke into both skulls.
    const SurfaceSite site = defaultBurrSite(skull);
    for (int i = 0; i < 60; ++i) {
        onCpu->sendToolState(trephine::testing::burrState(site, i, 60, 1000000));
        onGpu->sendToolState(trephine::testing::burrState(site, i, 60, 1000000));
        trephine::testing::pollAll(both);
    }
    ASSERT_TRUE(pumpUntil(both, [&] {
        return cpuServer.toolStatesApplied() == 60 && gpuServer.toolStatesApplied() == 60;
    }));
    int polls = 0;
    ASSERT_TRUE(pumpUntil(both, [&] {
        return ++polls % 10 == 0 && converged(cpuServer, *onCpu) && converged(gpuServer, *onGpu);
    })) << "the GPU server's rectangles add up to its full render";
    EXPECT_GT(compare(before, onGpu->dbi()).differingPixels, 50) << "the drilling shows";
    EXPECT_GT(onGpu->updatesApplied(), 1u);
    expectAgreement(agree(onGpu->dbi(), onCpu->dbi(), cam, voxel));
    cpuServer.stop();
    gpuServer.stop();
}

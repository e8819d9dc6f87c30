#include "net/force_round_trip.h"

#include "libsim/error.h"
#include "libsim/stats.h"
#include "net/session_client.h"

#include <algorithm>
#include <chrono>
#include <thread>

namespace trephine::net {

ForceRoundTripResult measureForceRoundTrip(const ENetAddress& server,
                                           const ForceRoundTripConfig& config) {
    ClientConfig cc;
    cc.name = "force-round-trip";
    cc.code = config.code;
    cc.view.width = cc.view.height = 8; // the image does not matter here
    SessionClient client(cc);
    client.connect(server);
    uint64_t guard = steadyNowUs() + uint64_t(config.guardS * 1e6);
    while (!client.hasFullImage() && !client.closed() && steadyNowUs() < guard)
        client.poll(1);
    if (!client.hasFullImage())
        throw Error("force round trip: no session with " + formatAddress(server) + ": " +
                    client.closeReason());

    uint32_t awaited = 0;
    uint64_t sentUs = 0;
    bool answered = false;
    SampleWindow rtt(size_t(std::max(config.samples, 1)));
    SampleWindow serverUs(size_t(std::max(config.samples, 1)));
    ForceRoundTripResult r;
    client.setHapticCallback([&](const HapticModel& m, uint64_t arrivalUs) {
        if (m.toolSequence != awaited || answered)
            return;
        answered = true;
        if (m.clientTimeUs != sentUs || arrivalUs < sentUs)
            return;
        rtt.add(double(arrivalUs - sentUs));
        // A server's two stamps out of order (not ours: some other build) would wrap to ~1.8e19.
        if (m.serverSentUs >= m.serverReceivedUs)
            serverUs.add(double(m.serverSentUs - m.serverReceivedUs));
        r.contacts += m.contact;
    });
    const uint64_t periodUs = config.rateHz > 0 ? uint64_t(1e6 / config.rateHz) : 0;
    uint64_t next = steadyNowUs();
    for (int i = 0; i < config.warmup + config.samples && !client.closed(); ++i) {
        if (steadyNowUs() > guard)
            break;
        while (steadyNowUs() < next)
            std::this_thread::sleep_for(std::chrono::microseconds(50));
        next += periodUs;
        if (i == config.warmup) {
            rtt.clear();
            serverUs.clear();
            r.contacts = 0;
            r.lost = 0;
        }
        ToolState t;
        t.toolKind = uint8_t(config.shape.kind);
        t.diameterMm = config.shape.diameterMm;
        t.position = config.pose.position;
        t.orientation = config.pose.orientation;
        sentUs = steadyNowUs();
        t.clientTimeUs = sentUs;
        answered = false;
        awaited = client.sendToolState(t);
        uint64_t timeout = sentUs + 100000;
        while (!answered && !client.closed() && steadyNowUs() < timeout)
            client.poll(1);
        r.lost += !answered;
    }
    client.setHapticCallback({});
    client.disconnect();
    r.samples = int(rtt.size());
    r.p50Us = rtt.percentile(50);
    r.p99Us = rtt.percentile(99);
    r.meanUs = rtt.mean();
    r.maxUs = rtt.max();
    r.serverP50Us = serverUs.percentile(50);
    return r;
}

} // namespace trephine::net

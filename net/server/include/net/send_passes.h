// The hand-off of posted updates to the network thread: the network thread counts its passes over
// the outbox, and before another peer's chunked work the simulation waits for one that began after
// the last post (StepConfig::letSend, docs/session.md "Availability"). On a two-core server that
// work's render would otherwise take half the CPU the send needs.
#pragma once

#include <condition_variable>
#include <cstdint>
#include <mutex>

namespace trephine::net {

class SendPasses {
public:
    // How long the simulation waits at most: a network thread busy elsewhere (a flood of volume
    // fragments) slows the simulation by at most this a piece.
    static constexpr uint64_t kMaxWaitUs = 1000;

    // [Network thread] Its loop runs from open() to close(); a closed hand-off never waits.
    void open();
    void close();
    // [Network thread] One pass over the outbox, from construction to destruction.
    class Pass {
    public:
        explicit Pass(SendPasses& passes);
        ~Pass();
        Pass(const Pass&) = delete;
        Pass& operator=(const Pass&) = delete;

    private:
        SendPasses& m_passes;
    };
    // [Any thread] Something was posted for the network thread to send.
    void posted();
    // [Simulation thread] Returns once a pass that began after the last post has ended (at once
    // if one has), the network thread is closed, or `maxWaitUs` has passed; false if the bound
    // was reached.
    bool awaitPosted(uint64_t maxWaitUs = kMaxWaitUs);

private:
    std::mutex m_mutex;
    std::condition_variable m_ended;
    uint64_t m_begun = 0, m_done = 0, m_wanted = 0; // passes begun, ended, to wait for
    bool m_open = false;
};

} // namespace trephine::net

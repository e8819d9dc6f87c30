#include "net/link_emulator.h"

#include "libsim/error.h"

#include <algorithm>
#include <chrono>
#include <cstring>
#include <deque>
#include <map>
#include <memory>
#include <poll.h>
#include <pthread.h>
#include <sstream>
#include <sys/prctl.h>
#include <vector>

namespace trephine::net {

LinkConditions LinkConditions::parse(const std::string& text) {
    LinkConditions c;
    std::stringstream ss(text);
    std::string item;
    while (std::getline(ss, item, ',')) {
        if (item.empty())
            continue;
        size_t eq = item.find('=');
        std::string key = item.substr(0, eq);
        double value = 0;
        try {
            size_t used = 0;
            if (eq == std::string::npos)
                throw std::invalid_argument("no value");
            value = std::stod(item.substr(eq + 1), &used);
            // Finite and at most 1e6: an hour of delay or a terabit link is no link to emulate,
            // and larger values overflow the clock's durations. Written so that NaN fails too.
            if (used != item.size() - eq - 1 || !(value >= 0 && value <= 1e6))
                throw std::invalid_argument("bad value");
        } catch (const std::exception&) {
            throw Error("link conditions '" + text + "': '" + item +
                        "' is not key=value with a number from 0 to 1000000");
        }
        if (key == "latency")
            c.latencyMs = value;
        else if (key == "jitter")
            c.jitterMs = value;
        else if (key == "loss")
            c.lossPercent = std::min(value, 100.0);
        else if (key == "rate")
            c.rateMbps = value;
        else if (key == "seed")
            c.seed = uint32_t(value);
        else if (key == "shared" && (value == 0 || value == 1))
            c.shared = value == 1;
        else if (key == "shared")
            throw Error("link conditions '" + text + "': shared is 0 or 1");
        else
            throw Error("link conditions '" + text + "': unknown key '" + key +
                        "' (use latency, jitter, loss, rate, shared, seed)");
    }
    return c;
}

std::string LinkConditions::describe() const {
    std::ostringstream o;
    o << "latency " << latencyMs << " ms, jitter " << jitterMs << " ms, loss " << lossPercent
      << " %, rate ";
    if (rateMbps > 0)
        o << rateMbps << " Mbit/s";
    else
        o << "unlimited";
    if (shared && rateMbps > 0)
        o << " shared by all clients";
    return o.str();
}

namespace {

using Clock = std::chrono::steady_clock;

struct Datagram {
    Clock::time_point due;
    std::vector<uint8_t> bytes;
};

// One direction of the link: a FIFO of datagrams waiting for their delivery time.
struct Lane {
    std::deque<Datagram> queue;
    Clock::time_point busyUntil{};
    Clock::time_point lastDue{};
};

// Small deterministic generator (xorshift) so runs with one seed drop the same datagrams.
struct Rng {
    uint64_t s;
    double uniform() {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        return double(s >> 11) * (1.0 / 9007199254740992.0);
    }
};

struct Client {
    ENetAddress address{};
    ENetSocket back = ENET_SOCKET_NULL;
    Lane up, down; // up: client -> target; down: target -> client
};

// ENetBuffer's field order differs between platforms: name the fields.
ENetBuffer makeBuffer(uint8_t* data, size_t n) {
    ENetBuffer b;
    b.data = data;
    b.dataLength = n;
    return b;
}

uint64_t addressKey(const ENetAddress& a) {
    return (uint64_t(a.host) << 16) | a.port;
}

// A non-blocking UDP socket bound to `at`, with room for bursts; ENET_SOCKET_NULL if it cannot be.
ENetSocket bindSocket(const ENetAddress& at) {
    ENetSocket s = enet_socket_create(ENET_SOCKET_TYPE_DATAGRAM);
    if (s == ENET_SOCKET_NULL)
        return s;
    if (enet_socket_bind(s, &at) != 0) {
        enet_socket_destroy(s);
        return ENET_SOCKET_NULL;
    }
    enet_socket_set_option(s, ENET_SOCKOPT_NONBLOCK, 1);
    enet_socket_set_option(s, ENET_SOCKOPT_RCVBUF, 4 * 1024 * 1024);
    enet_socket_set_option(s, ENET_SOCKOPT_SNDBUF, 4 * 1024 * 1024);
    return s;
}

// Loopback, unless `anyHost`: a server's public port, and the sockets towards a target that may be
// another machine (one bound to 127.0.0.1 cannot send off it).
ENetSocket makeSocket(uint16_t port, bool anyHost) {
    ENetAddress a{};
    if (anyHost)
        a.host = ENET_HOST_ANY;
    else
        enet_address_set_host(&a, "127.0.0.1");
    a.port = port;
    ENetSocket s = bindSocket(a);
    if (s == ENET_SOCKET_NULL)
        throw Error("link emulator: cannot bind UDP port " + std::to_string(port));
    return s;
}

// Towards a target on this machine, a client's socket is bound to a loopback address of its own,
// one per client host (127.0.0.0/8 is all loopback on Linux): the target then tells clients'
// hosts apart as it would without the relay (a server's per-address limits and removals).
ENetSocket makeBackSocket(const ENetAddress& client, const ENetAddress& target) {
    if ((ENET_NET_TO_HOST_32(target.host) >> 24) != 127)
        return makeSocket(0, true);
    // A host's alias in 127.0.0.2 ... 127.255.255.254, the same for every port of it.
    uint32_t h = ENET_NET_TO_HOST_32(client.host) * 0x9E3779B1u;
    h = std::clamp<uint32_t>((h ^ (h >> 15)) & 0xFFFFFFu, 2, 0xFFFFFEu);
    ENetAddress a{};
    a.host = ENET_HOST_TO_NET_32((127u << 24) | h);
    ENetSocket s = bindSocket(a);
    return s != ENET_SOCKET_NULL ? s : makeSocket(0, true); // no alias: all from one address
}

// Waits until a datagram arrives or the next queued one is due, at most 1 ms (the relay's loop
// sees its stop then). ppoll, not select: whole milliseconds would make a relay with datagrams
// queued spin a core until they are due, taking it from the peers it serves.
// Every datagram waiting on `s`, each into `buffer` and to `f(from, bytes)`.
template <typename F>
void receiveAll(ENetSocket s, std::vector<uint8_t>& buffer, F f) {
    for (;;) {
        ENetAddress from{};
        ENetBuffer b = makeBuffer(buffer.data(), buffer.size());
        const int n = enet_socket_receive(s, &from, &b, 1);
        if (n <= 0)
            return;
        f(from, size_t(n));
    }
}

// `polled` gets the client of each fds entry after the first (the front's).
void waitForTraffic(ENetSocket front, const std::map<uint64_t, std::unique_ptr<Client>>& clients,
                    std::vector<pollfd>& fds, std::vector<Client*>& polled) {
    fds.assign(1, pollfd{front, POLLIN, 0});
    polled.clear();
    Clock::time_point wake = Clock::now() + std::chrono::milliseconds(1);
    for (const auto& [key, cl] : clients) {
        fds.push_back({cl->back, POLLIN, 0});
        polled.push_back(cl.get());
        for (const Lane* lane : {&cl->up, &cl->down})
            if (!lane->queue.empty())
                wake = std::min(wake, lane->queue.front().due);
    }
    const auto wait = std::max(Clock::duration::zero(), wake - Clock::now());
    const auto ns = std::chrono::duration_cast<std::chrono::nanoseconds>(wait).count();
    const timespec timeout{time_t(ns / 1000000000), long(ns % 1000000000)};
    ppoll(fds.data(), nfds_t(fds.size()), &timeout, nullptr);
}

} // namespace

LinkEmulator::LinkEmulator(uint16_t listenPort, const ENetAddress& target,
                           LinkConditions conditions, bool anyHost)
    : m_target(target), m_conditions(conditions) {
    if (enet_initialize() != 0)
        throw Error("could not initialise ENet");
    try {
        m_front = makeSocket(listenPort, anyHost);
    } catch (...) {
        enet_deinitialize();
        throw;
    }
    ENetAddress bound{};
    enet_socket_get_address(m_front, &bound);
    m_port = bound.port;
    m_thread = std::thread([this] { run(); });
}

LinkEmulator::~LinkEmulator() {
    m_stop = true;
    if (m_thread.joinable())
        m_thread.join();
    enet_socket_destroy(m_front);
    enet_deinitialize();
}

void LinkEmulator::setConditions(const LinkConditions& c) {
    std::lock_guard lock(m_mutex);
    m_conditions = c;
}

LinkConditions LinkEmulator::conditions() const {
    std::lock_guard lock(m_mutex);
    return m_conditions;
}

void LinkEmulator::run() {
    pthread_setname_np(pthread_self(), "link-emulator");
    // Wake when a datagram is due, not up to the default 50 us of timer slack later.
    prctl(PR_SET_TIMERSLACK, 1UL, 0UL, 0UL, 0UL);
    std::map<uint64_t, std::unique_ptr<Client>> clients;
    Rng rng{0x9E3779B97F4A7C15ull};
    uint32_t seededWith = 0;
    std::vector<uint8_t> buffer(65536);
    std::vector<pollfd> fds; // the sockets to wait on, refilled each pass (kept: no allocation)
    std::vector<Client*> polled;
    // With LinkConditions::shared, every client's lane in one direction waits for these.
    Clock::time_point sharedUp{}, sharedDown{};

    auto enqueue = [&](Lane& lane, Clock::time_point& sharedBusy, const uint8_t* data, size_t n,
                       const LinkConditions& c) {
        if (c.lossPercent > 0 && rng.uniform() * 100.0 < c.lossPercent) {
            ++m_dropped;
            return;
        }
        auto now = Clock::now();
        auto delay = std::chrono::duration<double, std::milli>(
            c.latencyMs + (c.jitterMs > 0 ? rng.uniform() * c.jitterMs : 0.0));
        auto start = now;
        if (c.rateMbps > 0) {
            Clock::time_point& busy = c.shared ? sharedBusy : lane.busyUntil;
            start = std::max(now, busy);
            // On the wire a datagram is its payload plus its framing (kWireOverheadBytes).
            const double wireBytes = double(n + LinkConditions::kWireOverheadBytes);
            busy = start + std::chrono::duration_cast<Clock::duration>(
                               std::chrono::duration<double>(wireBytes * 8.0 / (c.rateMbps * 1e6)));
            start = busy;
        }
        auto due =
            std::max(start + std::chrono::duration_cast<Clock::duration>(delay), lane.lastDue);
        lane.lastDue = due;
        lane.queue.push_back({due, std::vector<uint8_t>(data, data + n)});
    };

    auto deliver = [&](Lane& lane, ENetSocket sock, const ENetAddress& to, Clock::time_point now) {
        while (!lane.queue.empty() && lane.queue.front().due <= now) {
            auto& d = lane.queue.front();
            ENetBuffer b = makeBuffer(d.bytes.data(), d.bytes.size());
            enet_socket_send(sock, &to, &b, 1);
            ++m_forwarded;
            lane.queue.pop_front();
        }
    };

    while (!m_stop) {
        LinkConditions c;
        {
            std::lock_guard lock(m_mutex);
            c = m_conditions;
        }
        if (c.seed != seededWith) {
            rng.s = 0x9E3779B97F4A7C15ull ^ (uint64_t(c.seed) * 0xBF58476D1CE4E5B9ull);
            seededWith = c.seed;
        }

        waitForTraffic(m_front, clients, fds, polled);

        // From clients to the target.
        receiveAll(m_front, buffer, [&](const ENetAddress& from, size_t n) {
            auto& cl = clients[addressKey(from)];
            if (!cl) {
                cl = std::make_unique<Client>();
                cl->address = from;
                cl->back = makeBackSocket(from, m_target);
            }
            m_bytesUp += n;
            enqueue(cl->up, sharedUp, buffer.data(), n, c);
        });
        // From the target back to each client whose socket has some: a receive on each of a
        // classroom's 64 sockets every pass took a core from the server it relays for.
        for (size_t i = 0; i < polled.size(); ++i)
            if (fds[i + 1].revents & POLLIN)
                receiveAll(polled[i]->back, buffer,
                           [&, cl = polled[i]](const ENetAddress&, size_t n) {
                               m_bytesDown += n;
                               enqueue(cl->down, sharedDown, buffer.data(), n, c);
                           });
        auto now = Clock::now();
        for (auto& [key, cl] : clients) {
            deliver(cl->up, cl->back, m_target, now);
            deliver(cl->down, m_front, cl->address, now);
        }
    }
    for (auto& [key, cl] : clients)
        enet_socket_destroy(cl->back);
}

LinkConditions linkSpecConditions(const std::string& spec) {
    // "", "," or " " would parse as no conditions: a link that emulates nothing, said to be there.
    if (spec.find_first_not_of(" ,") == std::string::npos)
        throw Error("link conditions '" + spec +
                    "': give the link's conditions, e.g. latency=50,loss=1");
    const LinkConditions c = LinkConditions::parse(spec);
    if (!(c.lossPercent < 100.0))
        throw Error("link conditions '" + spec +
                    "': a loss of 100 % lets nothing through; give under 100");
    return c;
}

std::unique_ptr<LinkEmulator> startLinkEnd(const std::string& spec, LinkEnd end,
                                           const ENetAddress& target, uint16_t publicPort) {
    if (spec.empty())
        return nullptr;
    const LinkConditions c = linkSpecConditions(spec);
    try {
        return std::make_unique<LinkEmulator>(publicPort, target, c, end == LinkEnd::Server);
    } catch (const Error& e) {
        throw Error("--link '" + spec + "': " + e.what());
    }
}

std::string relayAddress(const LinkEmulator& link) {
    return "127.0.0.1:" + std::to_string(link.port());
}

} // namespace trephine::net

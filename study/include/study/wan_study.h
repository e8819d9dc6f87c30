// The WAN and classroom study (issue 32): both designs (DBI and replicated volume) through the
// link emulator (net/link_emulator.h), a real SessionServer and real SessionClients in one
// process. Per link: join time, view change time, then a drilling soak per box size (cuts and
// restores of an N^3 box at a fixed pace) giving the update rate, latency and longest stall. The
// classroom: N clients on one shared link, one drilling, the others watching. docs/study.md.
#pragma once

#include "libsim/volume.h"
#include "net/link_emulator.h"
#include "net/protocol.h"
#include "study/update_study.h"

#include <functional>
#include <memory>
#include <string>
#include <vector>

namespace trephine::study {

// One emulated link of the sweep.
struct WanLink {
    double rttMs = 0, lossPct = 0, rateMbit = 100;
    net::LinkConditions conditions() const; // one-way latency = rtt / 2 in each direction
};

struct WanStudyConfig {
    std::string volumeName = "skull:128";
    int window = 500;                    // square, pixels: a join and a view change are 500^2
    net::Codec codec = net::Codec::Zstd; // image updates (the update study's default)
    std::vector<WanLink> links;          // empty: wanSweep(false)
    std::vector<int> boxes{10, 40, 80};
    double soakS = 10;       // drilling soak per (design, link, box)
    double targetSoakS = 60; // ... at the target link (100 ms, 1 %, 20 Mbit/s)
    double cutHz = 40;       // box cuts and restores offered per second during a soak
    std::vector<int> classroom{1, 4, 16, 64}; // clients; empty: no classroom
    int classroomBox = 40;                    // one of `boxes` (else the largest given)
    double classroomRateMbit = 100;           // the classroom's one shared link; 0: no limit
    double classroomSoakS = 10;
    double joinTimeoutS = 60; // a client not joined by then: its row says so (-1), no soak
    std::function<void(const std::string& label, int done, int total)> progress;
};

// The sweep: RTT {0, 20, 50, 100, 200, 300} ms x loss {0, 1, 5} % at 100 Mbit/s, then 20 Mbit/s
// at RTT {50, 100, 200} ms with 1 % loss; quick: RTT {0, 100} x loss {0, 1} at 100 Mbit/s and
// the target link.
std::vector<WanLink> wanSweep(bool quick);
// The target link: 100 ms RTT, 1 % loss, 20 Mbit/s.
WanLink wanTargetLink();
// The classroom's link in words: "one shared 100 Mbit/s link", or loopback for a rate of 0.
std::string classroomLink(double rateMbit);

// One row of wan.csv. A figure not measured is NaN (an empty cell); a join that timed out is -1.
struct WanRow {
    std::string design; // "dbi" or "volume"
    double rttMs = 0, lossPct = 0, rateMbit = 0;
    int clients = 1, box = 0;
    double updatesPerS = 0, latencyP50Ms = 0, latencyP99Ms = 0;
    double joinMs = 0, viewChangeMs = 0, maxStallMs = 0;
    double soakS = 0, offeredPerS = 0;
    double egressBytesPerS = 0; // the server's UDP payload towards the clients, during the soak
    double minUpdatesPerS = 0;  // classroom: the slowest client's rate
    double firstViewBytes = 0;  // the join's full picture (DBI) or volume, on the wire
    uint64_t updates = 0;       // updates applied during the soak, all clients
    bool classroom = false;     // a classroom run (no RTT, no loss, the shared link)
};

// One client of a classroom run (wan-classroom.csv).
struct WanClientRow {
    std::string design;
    int clients = 0, index = 0;
    bool driller = false;
    float yawDeg = 0; // its view: the paper camera orbited by this much
    double joinMs = 0, updatesPerS = 0, latencyP50Ms = 0, latencyP99Ms = 0, maxStallMs = 0;
};

struct WanResults {
    std::vector<WanRow> rows;
    std::vector<WanClientRow> clients;
};

// Throws the one-line trephine::Error that runWanStudy would for this volume and config.
void checkWanStudy(const Volume& volume, const WanStudyConfig& config);
// Runs it on `volume` (config.volumeName's, with the paper spacing for the paper camera).
WanResults runWanStudy(const Volume& volume, const WanStudyConfig& config);

// wan.csv: the columns first, then soak_s, offered_per_s, egress_bytes_per_s,
// min_client_updates_per_s, first_view_bytes, updates.
std::string wanCsvHeader();
std::string wanCsvRow(const WanRow& row);
std::string wanClientsCsvHeader();
std::string wanClientsCsvRow(const WanClientRow& row);

// The WAN and classroom targets as PASS/MISS lines beside the figures they judge.
std::vector<std::string> wanTargetLines(const WanResults& results);
// Issue 32's LAN non-regression target: the update study over the emulated 100 Mbit/s LAN keeps
// dbi / volume >= kLanRateTarget at 10^3, 40^3 and 80^3 (the sizes it has of these).
constexpr double kLanRateTarget = 7.8;
std::vector<std::string> lanTargetLines(const std::vector<UpdateStudyRow>& lanRows);

// `study wan`'s options (apps/mode_study.cpp parses them).
struct WanOptions {
    std::string out = ".";
    std::string volume = "skull:128";
    std::string codec = "zstd";
    std::vector<int> clients{1, 4, 16, 64};
    bool clientsGiven = false; // --clients wins over --quick's {1, 4}
    std::vector<int> boxes{10, 40, 80};
    bool boxesGiven = false;
    // Given: the sweep is these RTTs x losses at 100 Mbit/s, and the target link.
    std::vector<double> rtts, losses;
    double soakS = 0;               // given (> 0): each soak's seconds but the target link's 60
    double classroomRateMbit = 100; // 0: no limit, the relay alone (loopback)
    bool quick = false;
    std::shared_ptr<const Volume> opened; // study all's volume, already open
};
// Writes OUT/wan.csv and OUT/wan-classroom.csv, prints the table and the targets; `config`
// receives what it ran with.
WanResults runWanCommand(const WanOptions& o, WanStudyConfig& config);
// Throws what runWanCommand would for these options, without running anything.
void checkWanOptions(const WanOptions& o, const Volume& volume);

} // namespace trephine::study

// The update study (the paper's Table 1 and Figures 7 and 8): a real SessionServer and real
// headless SessionClients over loopback ENet in one process cut an N^3 box of bone per size and
// time each method's full update cycle, server erosion to the client's screen (dbi,
// dbi-fullrender, volume, volume-<codec>). docs/study.md gives the method and the columns.
#pragma once

#include "libsim/box.h"
#include "libsim/volume.h"
#include "net/link_emulator.h"
#include "net/protocol.h"

#include <functional>
#include <optional>
#include <string>
#include <vector>

namespace trephine::study {

struct UpdateStudyConfig {
    std::vector<int> sizes{10, 20, 30, 40, 50, 60, 70, 80};
    std::string volumeName = "skull:128";
    std::string camera = "paper";
    int window = 500;                   // square window, pixels
    net::Codec codec = net::Codec::Lz4; // image updates, and the compressed volume variant
    int cycles = 100;                   // measured cycles per method and size
    int warmup = 3;                     // cycles run first and discarded, per round
    // The sweep (every method, every size) runs this many times, each with its share of the
    // cycles and a fresh client per method; each (method, size) pools its samples over the
    // rounds, so its medians draw on several stretches of the run and a burst of other work on
    // the machine lands in one round of every cell it touches instead of in one whole cell.
    int rounds = 4;
    // A link to put between the clients and the server (net/link_emulator.h), e.g. the paper's
    // 100 Mbit/s LAN; none: plain loopback.
    std::optional<net::LinkConditions> link;
    double cycleTimeoutS = 10;        // one cycle that takes longer fails the study (an Error)
    std::vector<std::string> methods; // a subset of updateStudyMethods(codec); empty: all
    // Run the session with role codes, so every message is sealed (docs/security.md); false: an
    // open session, in the clear (what the encryption's cost is measured against).
    bool sealed = false;
    // A new file to log the server's session to (net/session_log.h), to measure what recording
    // costs; empty: none.
    std::string record;
    // Called before each (method, size) with a label and the steps done/total.
    std::function<void(const std::string& label, int done, int total)> progress;
};

// Median stage times of one (method, size), milliseconds.
struct StageBreakdown {
    double erode = 0, render = 0, encode = 0, transmit = 0, clientApply = 0, clientRender = 0;
    // The brick-grid update: a part of `render` (DBI, at the server) or of `clientApply`
    // (volume, at the client), not a stage of its own, so not in sum().
    double grid = 0;
    double sum() const { return erode + render + encode + transmit + clientApply + clientRender; }
};

struct UpdateStudyRow {
    std::string method;
    int box = 0;
    int bbScreenW = 0, bbScreenH = 0;
    double bytesPerUpdate = 0; // payload on the wire, mean
    double rawBytesPerUpdate =
        0;                  // DBI: 5 bytes a BB_screen pixel (RGB + 16-bit depth); volume: N^3
    double updatesPerS = 0; // 1000 / latencyP50Ms: cycles run back to back, one at a time
    double latencyP50Ms = 0, latencyP99Ms = 0;
    StageBreakdown stages;
    int cycles = 0;
};

// The study's methods, in order, for a codec ("dbi", "dbi-fullrender", "volume", "volume-lz4").
std::vector<std::string> updateStudyMethods(net::Codec codec);

// Throws the one-line trephine::Error that runUpdateStudy would for this volume and config (a box
// size that does not fit, rounds out of range, an unknown method, no bone where the study cuts)
// without starting anything, so `study all` can refuse before its first study.
void checkUpdateStudy(const Volume& volume, const UpdateStudyConfig& config);

// Runs the whole study on `volume` (which should be what config.volumeName names). Throws
// trephine::Error with one line when a cycle times out or the server cannot start.
std::vector<UpdateStudyRow> runUpdateStudy(const Volume& volume, const UpdateStudyConfig& config);

// The exact first columns the issue names, then the stage breakdown, the cycle count and the
// grid update's share (grid_ms).
std::string updatesCsvHeader();
std::string updatesCsvRow(const UpdateStudyRow& row);

} // namespace trephine::study

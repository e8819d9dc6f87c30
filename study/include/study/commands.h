// What `trephine study SUBCOMMAND` runs: each study with its checks, its console table and its
// files. apps/mode_study.cpp only parses the flags into these options and calls them; every
// function throws trephine::Error with one line for a user's mistake.
#pragma once

#include "study/report.h"

#include <memory>
#include <string>
#include <vector>

namespace trephine {
class Volume;
}

namespace trephine::study {

// `study haptics`: multi-rate haptics against a zero-order hold, the force model's time per
// update, the 1 kHz loop and the force round trip through a server. Writes OUT/haptics.csv.
struct HapticsOptions {
    std::vector<double> updateRates{20, 50, 100, 1000};
    std::vector<double> latencies{0, 25, 50, 100, 200, 300};
    std::string out = ".";
    std::string volume = "skull:128"; // a volume spec, or "box" for a flat bone block
    float burrMm = 2.0f;
    // The hand: "device" (the simulated force device through the plugin ABI, built beside the
    // program), "device:PATH.so", or "spring" (the same physics in the study's own code).
    std::string hand = "device";
    bool quick = false;
    // Given on the command line: they win over --quick's reduced grid.
    bool ratesGiven = false, latenciesGiven = false;
};
HapticsFigures runHapticsStudy(const HapticsOptions& o);

// `study updates`: DBI against replicated-volume update cycles. Writes OUT/csvName.
struct UpdatesOptions {
    std::string out = ".";
    std::vector<int> sizes{10, 20, 30, 40, 50, 60, 70, 80};
    std::string volume = "skull:128";
    std::string camera = "paper";
    // zstd: with predicted updates it sends ~35 % fewer bytes than lz4 for ~0.1-0.4 ms more
    // encoding per update (docs/study.md); the bytes target at 10^3 needs it.
    std::string codec = "zstd";
    // A burst of other work on a shared machine weighs less in each median than with 30.
    int cycles = 100;
    // The sweep runs 4 times, each with a quarter of the cycles: a cell's medians draw on four
    // stretches of the run (docs/study.md).
    int rounds = 4;
    std::string link; // empty: plain loopback
    std::string csvName = "updates.csv";
    std::vector<std::string> methods; // empty: every method
    std::string record;               // log the server's session here (docs/recording.md)
    bool quick = false;
    bool sizesGiven = false;  // --sizes on the command line wins over --quick's sizes
    bool cyclesGiven = false; // likewise --cycles, and --rounds
    bool roundsGiven = false; // without --rounds, fewer cycles than rounds means fewer rounds
    // The volume, already opened from `volume` (study all checks it before its first study).
    std::shared_ptr<const Volume> opened;
};
// `config` receives the configuration the study ran with (the report describes it).
std::vector<UpdateStudyRow> runUpdatesStudy(const UpdatesOptions& o, UpdateStudyConfig& config);

// `study display`: the DBI composite's display rate against local volume rendering. Writes
// OUT/display.csv when it ran; without the GUI, or without a display, the figures say why not.
struct DisplayOptions {
    std::string out = ".";
    bool quick = false;
};
DisplayFigures runDisplayStudy(const DisplayOptions& o);

// The link `study all` runs the update study over a second time: the paper's 100 Mbit/s LAN.
constexpr const char* kPaperLink = "rate=100";

// `study all`: every study, then OUT/report.md with the paper's figures beside ours.
struct AllOptions {
    std::string out = "study";
    std::string volume = "skull:128";
    std::string codec = "zstd";
    // The update study runs over loopback, then again over this emulated link; "off": only once.
    std::string link = kPaperLink;
    bool quick = false;
};
// `command` is how it was run, for the report. The files are written into a staging folder in
// OUT and moved into OUT together once the report is written, so a run that stops part way
// leaves the earlier run's set whole.
void runAllStudies(const AllOptions& o, const std::string& command);

} // namespace trephine::study

// `trephine study all`'s report.md: each study's results beside the paper's figures and the
// issue's targets, with the paper's Table 1 and Figures 7 and 8 as tables and SVG plots. Pure
// formatting of results measured elsewhere (update study, display study, haptics study).
#pragma once

#include "study/haptics_study.h"
#include "study/update_study.h"
#include "study/wan_study.h"

#include <string>
#include <vector>

namespace trephine::study {

// The display study (ui::measureDisplayRates), as plain figures.
struct DisplayFigures {
    bool measured = false;
    std::string why; // when not measured: one line
    std::string glRenderer;
    struct Entry {
        std::string name; // "dbi composite", "volume 128^3", "volume 256^3"
        double fps = 0, frameP50Ms = 0, frameP99Ms = 0;
        double paperFps = 0;
    };
    std::vector<Entry> entries;
};

struct ForceTiming {
    std::string tool;
    double p50Ms = 0, p99Ms = 0, paperServerMs = 0, paperClientMs = 0, targetMs = 0;
};

struct HapticsFigures {
    bool measured = false;
    std::vector<HapticsCaseResult> cases;
    std::vector<ForceTiming> timings;
    double loopRateHz = 0;
    double roundTripP50Ms = 0, roundTripP99Ms = 0, roundTripServerMs = 0;
};

struct StudyReportInput {
    std::string command; // how it was run
    std::string machine; // describeMachine()
    bool quick = false;
    UpdateStudyConfig updateConfig;
    std::vector<UpdateStudyRow> updates;
    // The update study run again over an emulated link (`study all`: the paper's 100 Mbit/s LAN
    // unless --link says otherwise), written to updates-link.csv and updates-link.svg; empty
    // when it was not run. Its Figure 7, stage breakdown and rate targets follow the first run's.
    UpdateStudyConfig linkUpdateConfig;
    std::vector<UpdateStudyRow> linkUpdates;
    DisplayFigures display;
    HapticsFigures haptics;
    // The WAN and classroom study (`study all` runs it quick-sized); empty rows: not run.
    WanStudyConfig wanConfig;
    WanResults wan;
};

// CPU model, cores, memory and kernel of this machine, one line.
std::string describeMachine();

// The paper's Table 1: BB_screen edge (pixels) for BB_volume N^3, N = 10..80; 0 when not listed.
int paperBbScreen(int n);

// Writes DIR/updates.svg and DIR/bytes.svg and returns report.md's text (which links them).
std::string writeStudyReport(const StudyReportInput& input, const std::string& dir);

// One line per issue target: "PASS"/"MISS", the figure and the target (also in the report):
// the update-rate lines (DBI / volume rate, per box size) then the update-size lines.
std::vector<std::string> updateTargetLines(const std::vector<UpdateStudyRow>& rows);
std::vector<std::string> rateTargetLines(const std::vector<UpdateStudyRow>& rows);
std::vector<std::string> sizeTargetLines(const std::vector<UpdateStudyRow>& rows);
std::vector<std::string> displayTargetLines(const DisplayFigures& d);

// The DBI / volume rate ratio at box n were BB_screen's rays free to cast: both cycles' medians
// less that ray casting (the DBI render stage less its grid update; as much of the volume
// client's re-render, at most all of it). No renderer could lift the ratio above this on the
// machine and network measured. 0 when the rows lack the figures.
double rateRatioWithoutRayCasting(const std::vector<UpdateStudyRow>& rows, int n);
// When some DBI/volume rate target missed on plain loopback (no emulated link): why, where the
// paper's network is, and the ratio each missed size would reach with free ray casting. Empty
// otherwise. In report.md under the targets, and printed by `study updates`.
std::vector<std::string> rateMissNotes(const std::vector<UpdateStudyRow>& rows, bool emulatedLink);

} // namespace trephine::study

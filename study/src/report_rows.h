// The study report's row look-ups and target arithmetic, shared by the target lines
// (targets.cpp) and report.md's tables (report.cpp).
#pragma once

#include "study/update_study.h"

#include <string>
#include <vector>

namespace trephine::study {

// The row of `method` at box edge `box`, or null.
const UpdateStudyRow* findRow(const std::vector<UpdateStudyRow>& rows, const std::string& method,
                              int box);
std::vector<int> boxesOf(const std::vector<UpdateStudyRow>& rows);           // ascending
std::vector<std::string> methodsOf(const std::vector<UpdateStudyRow>& rows); // in row order

// The update-rate target: DBI at least this many times the volume method's rate.
constexpr double kRateTarget = 5.0;

// DBI / volume update rate at box n; -1 when either row is missing or the volume has no rate.
double rateRatio(const std::vector<UpdateStudyRow>& rows, int n);

// `v` with `decimals` decimals, or more where rounding would carry it across `target` and the
// figure would contradict its PASS/MISS (4.96 against 5 reads "4.96", not "5.0").
std::string figureAgainst(double v, double target, bool passAbove, int decimals);

} // namespace trephine::study

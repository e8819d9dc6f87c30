// `study all`: every option checked before the first study, the studies run into a staging folder
// inside OUT, the report written there, and the whole set moved into OUT together.
#include "study/commands.h"
#include "study/wan_study.h"

#include "output.h"

#include "libsim/error.h"
#include "libsim_image/volume_slices.h"
#include "net/codec.h"

#include <fmt/format.h>

#include <unistd.h>

#include <filesystem>

namespace trephine::study {

namespace {

namespace fs = std::filesystem;

// Every file `study all` may write into OUT.
constexpr const char* kOutputs[] = {
    "haptics.csv",      "updates.csv",   "updates.svg", "bytes.svg",         "updates-link.csv",
    "updates-link.svg", "display.csv",   "wan.csv",     "wan-classroom.csv", "wan.svg",
    "wan-join.svg",     "classroom.svg", "report.md"};

// Each file moves over its name in OUT at the end, which fails for a folder (or anything but a
// file) there: refused before the first study.
void checkOutputsAreFiles(const std::string& out) {
    for (const char* name : kOutputs) {
        const fs::path there = fs::path(out) / name;
        std::error_code ec;
        const auto st = fs::symlink_status(there, ec);
        if (!ec && fs::exists(st) && !fs::is_regular_file(st) && !fs::is_symlink(st))
            throw Error("--out " + out + ": " + name + " there is not a file, and the study's " +
                        name + " cannot replace it (move it away)");
    }
}

// Staging folders of `study all` runs that ended without cleaning up (killed): their process is
// gone. A running study's folder (another process writing to OUT) is left alone.
void removeAbandonedStaging(const std::string& out) {
    std::error_code ec;
    for (const auto& entry : fs::directory_iterator(out, ec)) {
        const std::string name = entry.path().filename().string();
        const std::string prefix = ".study-all-";
        if (name.rfind(prefix, 0) != 0 || !entry.is_directory(ec))
            continue;
        const std::string pid = name.substr(prefix.size());
        if (pid.empty() || pid.find_first_not_of("0123456789") != std::string::npos ||
            fs::exists("/proc/" + pid, ec))
            continue;
        fs::remove_all(entry.path(), ec);
    }
}

// Removes the staging folder when the run ends, unless told to keep it (its files are then the
// only complete set).
struct StagingFolder {
    fs::path path;
    ~StagingFolder() {
        std::error_code ec;
        if (!path.empty())
            fs::remove_all(path, ec);
    }
};

// Moves every staged file over its name in OUT; a move that fails keeps the staging folder.
void moveIntoPlace(StagingFolder& staging, const std::string& out) {
    for (const auto& entry : fs::directory_iterator(staging.path)) {
        std::error_code ec;
        fs::rename(entry.path(), fs::path(out) / entry.path().filename(), ec);
        if (ec) {
            const std::string kept = staging.path.string();
            staging.path.clear();
            throw Error("cannot move " + entry.path().filename().string() + " into " + out + ": " +
                        ec.message() + "; this run's files are in " + kept);
        }
    }
}

// Files of ours an earlier run left in OUT that this run did not write (--link off, or no
// display): beside a report that does not mention them they would pass for its figures. Removed
// once the new report is in place; their names are returned, comma-separated.
std::string removeStale(const std::string& out, bool linkRun, bool displayMeasured) {
    std::vector<std::string> stale;
    if (!linkRun)
        stale.insert(stale.end(), {"updates-link.csv", "updates-link.svg"});
    if (!displayMeasured)
        stale.push_back("display.csv");
    std::string removed;
    for (const std::string& name : stale) {
        const auto file = fs::path(out) / name;
        std::error_code ec;
        if (fs::is_directory(file, ec))
            continue; // not one of ours
        if (fs::remove(file, ec))
            removed += (removed.empty() ? "" : ", ") + name;
        else if (ec)
            throw Error("cannot remove the earlier run's " + file.string() + ": " + ec.message());
    }
    return removed;
}

} // namespace

void runAllStudies(const AllOptions& o, const std::string& command) {
    // Options of the later studies are checked before the first one runs.
    net::parseCodec(o.codec);
    const bool linkRun = o.link != "off";
    // An empty --link would parse as no conditions: a second loopback run reported as a link.
    if (linkRun && o.link.find_first_not_of(" ,") == std::string::npos)
        throw Error("--link: give the link's conditions (e.g. rate=100) or off, not '" + o.link +
                    "'");
    if (linkRun)
        studyLink(o.link);
    // A volume that does not open, is too small for the cuts or has no bone where they fall
    // fails here, before the haptics study replaces the folder's haptics.csv.
    auto volume = std::make_shared<const Volume>(openVolume(o.volume));
    UpdatesOptions u;
    u.out = o.out;
    u.volume = o.volume;
    u.opened = volume;
    u.codec = o.codec;
    u.quick = o.quick;
    checkUpdatesOptions(u, *volume);
    // The WAN study runs quick-sized in `study all` (its whole sweep takes an hour).
    WanOptions w;
    w.volume = o.volume;
    w.opened = volume;
    w.codec = o.codec;
    w.quick = true;
    checkWanOptions(w, *volume);
    makeOutDir(o.out);
    checkOutputsAreFiles(o.out);

    const fs::path stagingPath = fs::path(o.out) / (".study-all-" + std::to_string(getpid()));
    removeAbandonedStaging(o.out);
    fs::remove_all(stagingPath);
    makeOutDir(stagingPath.string());
    StagingFolder staging{stagingPath};
    u.out = stagingPath.string();
    StudyReportInput input;
    input.command = command;
    input.machine = describeMachine();
    input.quick = o.quick;

    const int studies = linkRun ? 5 : 4;
    fmt::print("== 1/{} haptics ==\n", studies);
    HapticsOptions h;
    h.out = stagingPath.string();
    h.quick = o.quick;
    input.haptics = runHapticsStudy(h);

    fmt::print("\n== 2/{} updates over loopback ==\n", studies);
    input.updates = runUpdatesStudy(u, input.updateConfig);

    if (linkRun) {
        fmt::print("\n== 3/{} updates over an emulated link ==\n", studies);
        u.link = o.link;
        u.csvName = "updates-link.csv";
        input.linkUpdates = runUpdatesStudy(u, input.linkUpdateConfig);
    }

    fmt::print("\n== {}/{} display ==\n", studies - 1, studies);
    DisplayOptions d;
    d.out = stagingPath.string();
    d.quick = o.quick;
    input.display = runDisplayStudy(d);

    fmt::print("\n== {}/{} WAN and classroom (quick-sized) ==\n", studies, studies);
    w.out = stagingPath.string();
    input.wan = runWanCommand(w, input.wanConfig);

    const std::string report = writeStudyReport(input, stagingPath.string());
    writeText(stagingPath / "report.md", report);
    moveIntoPlace(staging, o.out);
    fmt::print("\nwrote {} (with updates.svg{}, bytes.svg, wan.svg, wan-join.svg and "
               "classroom.svg; the studies' files moved there "
               "from {})\n",
               (fs::path(o.out) / "report.md").string(), linkRun ? ", updates-link.svg" : "",
               stagingPath.filename().string());
    const std::string removed = removeStale(o.out, linkRun, input.display.measured);
    if (!removed.empty())
        fmt::print("removed {} from an earlier run: this run has no such results\n", removed);
}

} // namespace trephine::study

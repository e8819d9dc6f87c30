#include "study/report.h"

#include "report_rows.h"

#include "libsim/error.h"
#include "libsim/replacing_file.h"
#include "net/codec.h"
#include "study/svg_plot.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <ctime>
#include <filesystem>
#include <sstream>

namespace trephine::study {

using net::codecName;

namespace {

std::string bytesText(double b) {
    if (b >= 1e6)
        return fmt::format("{:.2f} MB", b / 1e6);
    if (b >= 1e4)
        return fmt::format("{:.1f} kB", b / 1e3);
    return fmt::format("{:.0f} B", b);
}

// Through a temporary file renamed into place: a full disk or a stopped run leaves the earlier
// plot whole, not one cut off mid-tag.
void writeFile(const std::string& path, const std::string& text) {
    if (!writeReplacing(path, text))
        throw Error("cannot write " + path);
}

std::string utcNow() {
    const std::time_t t = std::time(nullptr);
    std::tm utc{};
    gmtime_r(&t, &utc);
    return fmt::format("{:04}-{:02}-{:02} {:02}:{:02} UTC", utc.tm_year + 1900, utc.tm_mon + 1,
                       utc.tm_mday, utc.tm_hour, utc.tm_min);
}

// The paper's stage shares at 80^3 (section 4.1), percent.
const char* paperStages(const std::string& method) {
    if (method == "dbi" || method == "dbi-fullrender")
        return "volume update 63, transmit 21, DBI creation 13 (render 1 + capture 12), client DBI "
               "3, erosion <1";
    if (method == "volume")
        return "volume update 67, transmit 23, render 8, erosion <1";
    return "";
}

// Figure 7 of one run of the update study: a table of the rates per method and size with
// dbi / volume and dbi-fullrender / volume, the plot (DIR/svgName), `note`, then the latencies.
void writeFigure7(std::ostringstream& md, const std::vector<UpdateStudyRow>& rows,
                  const std::string& dir, const std::string& svgName, const std::string& title,
                  const std::string& note) {
    const std::vector<int> boxes = boxesOf(rows);
    const std::vector<std::string> methods = methodsOf(rows);
    std::vector<std::string> h7{"BB_volume"};
    for (const std::string& m : methods)
        h7.push_back(m + " (/s)");
    h7.push_back("dbi / volume");
    h7.push_back("dbi-fullrender / volume");
    std::vector<std::vector<std::string>> t7;
    PlotSpec rate;
    rate.title = title;
    rate.xLabel = "BB_volume edge N (voxels)";
    rate.yLabel = "updates per second";
    rate.logY = true;
    for (const std::string& m : methods) {
        PlotSeries s{m, {}, {}, "", false};
        for (int n : boxes)
            if (const UpdateStudyRow* r = findRow(rows, m, n)) {
                s.x.push_back(n);
                s.y.push_back(r->updatesPerS);
            }
        rate.series.push_back(s);
    }
    for (int n : boxes) {
        std::vector<std::string> row{fmt::format("{}^3", n)};
        for (const std::string& m : methods) {
            const UpdateStudyRow* r = findRow(rows, m, n);
            row.push_back(r ? fmt::format("{:.1f}", r->updatesPerS) : "-");
        }
        const UpdateStudyRow* d = findRow(rows, "dbi", n);
        const UpdateStudyRow* f = findRow(rows, "dbi-fullrender", n);
        const UpdateStudyRow* v = findRow(rows, "volume", n);
        // The same figure as the target line's (4.96 reads 4.96x, not 5.0x, beside a MISS).
        row.push_back(d && v && v->updatesPerS > 0
                          ? figureAgainst(d->updatesPerS / v->updatesPerS, kRateTarget, true, 1) +
                                "x"
                          : "-");
        row.push_back(f && v ? fmt::format("{:.1f}x", f->updatesPerS / v->updatesPerS) : "-");
        t7.push_back(row);
    }
    md << markdownTable(h7, t7);
    writeFile((std::filesystem::path(dir) / svgName).string(), svgLinePlot(rate));
    md << "\n![" << title << "](" << svgName << ")\n\n" << note << "\n\n";
    std::vector<std::vector<std::string>> tl;
    for (int n : boxes) {
        std::vector<std::string> row{fmt::format("{}^3", n)};
        for (const std::string& m : methods) {
            const UpdateStudyRow* r = findRow(rows, m, n);
            row.push_back(r ? fmt::format("{:.2f} / {:.2f}", r->latencyP50Ms, r->latencyP99Ms)
                            : "-");
        }
        tl.push_back(row);
    }
    std::vector<std::string> hl{"latency p50 / p99 (ms)"};
    hl.insert(hl.end(), methods.begin(), methods.end());
    md << markdownTable(hl, tl) << "\n";
}

// One table per method of one run: median stage times as shares of their sum, the sum and the
// brick-grid update.
void writeStageBreakdown(std::ostringstream& md, const std::vector<UpdateStudyRow>& rows) {
    for (const std::string& m : methodsOf(rows)) {
        std::vector<std::vector<std::string>> ts;
        for (int n : boxesOf(rows)) {
            const UpdateStudyRow* r = findRow(rows, m, n);
            if (!r)
                continue;
            const StageBreakdown& s = r->stages;
            const double sum = std::max(s.sum(), 1e-9);
            auto pct = [&](double v) { return fmt::format("{:.1f}%", 100.0 * v / sum); };
            ts.push_back({fmt::format("{}^3", n), pct(s.erode), pct(s.render), pct(s.encode),
                          pct(s.transmit), pct(s.clientApply), pct(s.clientRender),
                          fmt::format("{:.3f}", s.sum()), fmt::format("{:.3f}", s.grid)});
        }
        md << "**" << m << "**";
        if (*paperStages(m))
            md << " (paper at 80^3: " << paperStages(m) << ")";
        md << "\n\n";
        md << markdownTable({"BB_volume", "erode", "render", "encode", "transmit", "client apply",
                             "client render", "sum (ms)", "of which grid (ms)"},
                            ts)
           << "\n";
    }
}

// "an emulated link (...)" or "loopback": the network a run's clients reached the server over.
std::string networkOf(const UpdateStudyConfig& config) {
    return config.link ? "an emulated link (" + config.link->describe() +
                             ", net/link_emulator.h) on loopback"
                       : std::string("loopback");
}

// The run: command, date, machine and each study's setup, beside the paper's.
void writeHeader(std::ostringstream& md, const StudyReportInput& in) {
    const std::string network = networkOf(in.updateConfig);
    const bool linkRun = !in.linkUpdates.empty();
    md << "# Trephine study report\n\n";
    md << "Run `" << in.command << "` on " << utcNow()
       << (in.quick ? " (**--quick**: a reduced run)" : "") << ".\n\n";
    md << "- Machine: " << in.machine << "\n";
    if (in.display.measured)
        md << "- OpenGL: " << in.display.glRenderer << "\n";
    md << "- Update study: `" << in.updateConfig.volumeName << "`, camera `"
       << in.updateConfig.camera << "`, " << in.updateConfig.window << "x" << in.updateConfig.window
       << " window, image codec `" << codecName(in.updateConfig.codec) << "`, "
       << in.updateConfig.cycles << " measured cycles per method and size in "
       << in.updateConfig.rounds << " round" << (in.updateConfig.rounds == 1 ? "" : "s")
       << " of the whole sweep (after " << in.updateConfig.warmup
       << " warm-up a round), real ENet over " << network
       << (linkRun ? ", then the same again over " + networkOf(in.linkUpdateConfig) : std::string())
       << ", server and clients in one process\n";
    md << "- The paper: server (system 1) updating a client (system 2) over a 100 Mbit/s LAN, "
          "128^3 volume, camera 13\" away, 60 degrees, 500x500 window.\n\n";
}

// Targets first: what a reader wants to know. The sizes are payloads, the same on any network;
// the rates are per network.
void writeTargets(std::ostringstream& md, const StudyReportInput& in) {
    const std::vector<UpdateStudyRow>& rows = in.updates;
    const std::string network = networkOf(in.updateConfig);
    const bool linkRun = !in.linkUpdates.empty();
    md << "## Targets\n\n";
    if (linkRun)
        md << "Over " << network << ":\n\n";
    for (const std::string& l : updateTargetLines(rows))
        md << "- " << l << "\n";
    for (const std::string& l : rateMissNotes(rows, in.updateConfig.link.has_value()))
        md << "- " << l << "\n";
    if (linkRun) {
        md << "\nOver " << networkOf(in.linkUpdateConfig) << ":\n\n";
        for (const std::string& l : rateTargetLines(in.linkUpdates))
            md << "- " << l << "\n";
        // Issue 32's non-regression target is over the paper's LAN only (no added delay or loss).
        const auto& lan = in.linkUpdateConfig.link;
        if (lan && lan->rateMbps == 100 && lan->latencyMs == 0 && lan->lossPercent == 0)
            for (const std::string& l : lanTargetLines(in.linkUpdates))
                md << "- " << l << "\n";
        md << "\nThe display rate (one client, no network):\n\n";
    }
    for (const std::string& l : displayTargetLines(in.display))
        md << "- " << l << "\n";
    if (!in.display.measured)
        md << "- display study not run: " << in.display.why << "\n";
    if (!in.wan.rows.empty()) {
        md << "\nOver the emulated WAN and in a classroom (issue 32; most miss today: the "
              "baseline for the transport work):\n\n";
        for (const std::string& l : wanTargetLines(in.wan))
            md << "- " << l << "\n";
    }
    md << "\n";
}

// Table 1: BB_screen per box, ours beside the paper's.
void writeTable1(std::ostringstream& md, const std::vector<UpdateStudyRow>& rows) {
    const std::vector<int> boxes = boxesOf(rows);
    const std::vector<std::string> methods = methodsOf(rows);
    md << "## Table 1: BB_screen per BB_volume\n\n";
    std::vector<std::vector<std::string>> t1;
    for (int n : boxes) {
        const UpdateStudyRow* r = findRow(rows, methods.front(), n);
        const int p = paperBbScreen(n);
        t1.push_back({fmt::format("{}^3", n), fmt::format("{}x{}", r->bbScreenW, r->bbScreenH),
                      p ? fmt::format("{}^2", p) : "-"});
    }
    md << markdownTable({"BB_volume (voxels)", "BB_screen, ours (pixels)", "paper"}, t1);
    md << "\nOurs is the projection of the box grown by the renderer's 2-voxel shading stencil "
          "(docs/architecture.md), so every pixel the cut can change is inside it.\n\n";
}

// Figure 8 (bytes per update, ours beside the paper's) as a table and DIR/bytes.svg.
void writeFigure8(std::ostringstream& md, const std::vector<UpdateStudyRow>& rows,
                  const std::string& dir) {
    const std::vector<int> boxes = boxesOf(rows);
    const std::vector<std::string> methods = methodsOf(rows);
    md << "## Figure 8: update sizes\n\n";
    PlotSpec size;
    size.title = "Bytes per update (Figure 8)";
    size.xLabel = "BB_volume edge N (voxels)";
    size.yLabel = "bytes";
    size.logY = true;
    std::vector<std::vector<std::string>> t8;
    PlotSeries paperDbi{"paper DBI 4M^2", {}, {}, "#999999", true};
    PlotSeries paperVol{"paper volume N^3", {}, {}, "#444444", true};
    for (const std::string& m : methods) {
        if (m == "dbi-fullrender")
            continue; // the same coding as dbi: the same bytes
        PlotSeries s{m, {}, {}, "", false};
        for (int n : boxes)
            if (const UpdateStudyRow* r = findRow(rows, m, n)) {
                s.x.push_back(n);
                s.y.push_back(r->bytesPerUpdate);
            }
        size.series.push_back(s);
    }
    for (int n : boxes) {
        const UpdateStudyRow* d = findRow(rows, "dbi", n);
        const UpdateStudyRow* v = findRow(rows, "volume", n);
        const int p = paperBbScreen(n);
        if (p) {
            paperDbi.x.push_back(n);
            paperDbi.y.push_back(4.0 * p * p);
        }
        paperVol.x.push_back(n);
        paperVol.y.push_back(double(n) * n * n);
        std::vector<std::string> row{fmt::format("{}^3", n)};
        for (const std::string& m : methods) {
            const UpdateStudyRow* r = findRow(rows, m, n);
            row.push_back(r ? bytesText(r->bytesPerUpdate) : "-");
        }
        row.push_back(d ? bytesText(d->rawBytesPerUpdate) : "-");
        row.push_back(p ? bytesText(4.0 * p * p) : "-");
        row.push_back(bytesText(double(n) * n * n));
        row.push_back(d && v ? fmt::format("{:.3f}", d->bytesPerUpdate / v->rawBytesPerUpdate)
                             : "-");
        t8.push_back(row);
    }
    // The paper's references first, so the measured series are drawn over them: the volume's
    // N^3 is the paper's N^3, and drawn after it would hide the measured line and markers.
    size.series.insert(size.series.begin(), {paperDbi, paperVol});
    std::vector<std::string> h8{"BB_volume"};
    for (const std::string& m : methods)
        h8.push_back(m);
    h8.insert(h8.end(), {"dbi uncompressed (5 B/px)", "paper DBI (4M^2)", "paper volume (N^3)",
                         "dbi / volume raw"});
    md << markdownTable(h8, t8);
    writeFile((std::filesystem::path(dir) / "bytes.svg").string(), svgLinePlot(size));
    md << "\n![Update sizes](bytes.svg)\n\n";
    md << "Paper: DBI updates (4 bytes a pixel) were larger than the volume's N^3 up to 30^3. "
          "Target: dbi <= volume raw at every size, <= 1/10 at 80^3. Bytes are payloads on "
          "the wire (means); `dbi` is coded against the pixels the client already holds "
          "(docs/protocol.md, predicted image updates); `dbi-fullrender` sends the same "
          "coding. A cut box is all air, so the compressed volume variant shrinks to a "
          "few bytes; drilling leaves partial densities that compress far less.\n\n";
}

void writeStages(std::ostringstream& md, const StudyReportInput& in) {
    const bool linkRun = !in.linkUpdates.empty();
    md << "## Stage breakdown\n\n";
    md << "Median stage times as a share of their sum (and the sum in ms). Erode, render and "
          "encode run on the server; transmit is server sent -> client received; client "
          "apply is decode + write for DBI, voxels + rendering data for volume; client render "
          "is the volume client's re-render of its view. The last column is the brick-grid "
          "update (the renderer's empty-space data), in ms: part of render for DBI, of client "
          "apply for volume.\n\n";
    if (linkRun)
        md << "Over " << networkOf(in.updateConfig) << ":\n\n";
    writeStageBreakdown(md, in.updates);
    if (linkRun) {
        md << "Over the emulated link (the paper's shares were measured on its LAN):\n\n";
        writeStageBreakdown(md, in.linkUpdates);
    }
}

void writeDisplay(std::ostringstream& md, const DisplayFigures& display) {
    md << "## Display rate\n\n";
    if (display.measured) {
        std::vector<std::vector<std::string>> td;
        for (const DisplayFigures::Entry& e : display.entries)
            td.push_back({e.name, fmt::format("{:.1f}", e.fps), fmt::format("{:.3f}", e.frameP50Ms),
                          fmt::format("{:.3f}", e.frameP99Ms),
                          e.paperFps > 0 ? fmt::format("{:.0f}", e.paperFps) : "-"});
        md << markdownTable(
            {"client draws", "FPS", "frame p50 (ms)", "frame p99 (ms)", "paper FPS"}, td);
        // llvmpipe (Mesa's software rasteriser, the renderer of a machine without a GPU) runs
        // the "GPU" ray caster on the CPU: said so, not called the GPU.
        const std::string& gl = display.glRenderer;
        const bool software = gl.find("llvmpipe") != std::string::npos ||
                              gl.find("softpipe") != std::string::npos ||
                              gl.find("swrast") != std::string::npos;
        md << "\nThe same view (paper camera, 500x500) in one process and run: the DBI composite "
              "(restore colour + depth, draw a tool) against local volume ray casting through "
              "OpenGL ("
           << gl << (software ? ": software rendering on the CPU, no GPU" : "")
           << "). Paper: 990 vs 57 FPS (128^3) and 26 FPS (256^3).\n\n";
    } else {
        md << "Not measured: " << display.why << "\n\n";
    }
}

// Our force-model timings and haptics cases beside the paper's.
void writeHaptics(std::ostringstream& md, const HapticsFigures& haptics) {
    md << "## Haptics\n\n";
    if (haptics.measured) {
        std::vector<std::vector<std::string>> th;
        for (const ForceTiming& t : haptics.timings) {
            const double localHz = t.p50Ms > 0 ? 1000.0 / t.p50Ms : 0.0;
            const double remoteMs = haptics.roundTripP50Ms - haptics.roundTripServerMs + t.p50Ms;
            const double remoteHz = remoteMs > 0 ? 1000.0 / remoteMs : 0.0;
            const double paperLocal = t.paperClientMs > 0 ? 1000.0 / t.paperClientMs : 0.0;
            const double paperRemote =
                t.paperServerMs > 0 ? 1000.0 / (t.paperServerMs + 0.82) : 0.0;
            th.push_back({t.tool, fmt::format("{:.4f}", t.p50Ms), fmt::format("{:.4f}", t.p99Ms),
                          fmt::format("{:.0f}", localHz), fmt::format("{:.0f}", remoteHz),
                          fmt::format("{:.2f} / {:.2f}", t.paperServerMs, t.paperClientMs),
                          fmt::format("{:.0f} -> {:.0f} ({:+.0f}%)", paperLocal, paperRemote,
                                      100.0 * (paperRemote / paperLocal - 1.0))});
        }
        md << markdownTable({"tool", "force model p50 (ms)", "p99 (ms)",
                             "model rate computed locally (Hz)",
                             "model rate from the server over loopback (Hz)",
                             "paper server / client (ms)", "paper rate local -> server"},
                            th);
        md << fmt::format(
            "\nForce round trip over loopback through a session server: p50 {:.3f} ms, p99 {:.3f} "
            "ms "
            "(server share {:.3f} ms; paper 0.82 ms on its LAN). The 1 kHz haptic loop ran at "
            "{:.0f} Hz. Here server and client are the same machine, so computing forces on the "
            "server cannot raise the model rate the way the paper's faster server did (+27 % "
            "drill, +142 % perforator); the table gives both rates so the trade is visible.\n\n",
            haptics.roundTripP50Ms, haptics.roundTripP99Ms, haptics.roundTripServerMs,
            haptics.loopRateHz);
        std::vector<std::vector<std::string>> tc;
        for (const HapticsCaseResult& r : haptics.cases)
            tc.push_back({hapticMethodName(r.c.method), fmt::format("{:.0f}", r.c.updateHz),
                          fmt::format("{:.0f}", r.c.latencyMs),
                          fmt::format("{:.4f}", r.forceRmsErrorN),
                          fmt::format("{:.3f}", r.energyInjectedJ * 1e3),
                          fmt::format("{:.4f}", r.excessOscillationMm), r.stable ? "yes" : "NO"});
        md << markdownTable({"method", "model rate (Hz)", "latency (ms)", "rms force error (N)",
                             "energy injected (mJ)", "added oscillation (mm)", "stable"},
                            tc);
        md << "\nMulti-rate extrapolation (the paper's method) against a zero-order hold of the "
              "server's force, each judged against the same hand on the exact force with no delay "
              "(haptics.csv has every column).\n";
    } else {
        md << "Not run.\n";
    }
}

// [WAN] The rows of one design at one box over single-client links of `rate`, by RTT.
PlotSeries wanSeries(const WanResults& r, const std::string& design, double loss, double rate,
                     int box, double WanRow::*figure) {
    PlotSeries s{fmt::format("{} {:.0f} % loss", design, loss), {}, {}, "", design == "volume"};
    for (const WanRow& row : r.rows)
        if (row.design == design && !row.classroom && row.box == box && row.lossPct == loss &&
            row.rateMbit == rate && std::isfinite(row.*figure) && row.*figure >= 0) {
            s.x.push_back(row.rttMs);
            s.y.push_back(row.*figure);
        }
    return s;
}

std::string wanFigure(double v) {
    return std::isnan(v) ? "-" : v < 0 ? "never" : fmt::format("{:.0f}", v);
}

// [WAN] Both designs per link: the table, latency and join plots (DIR/wan.svg, wan-join.svg).
void writeWan(std::ostringstream& md, const StudyReportInput& in, const std::string& dir) {
    const WanResults& r = in.wan;
    const WanStudyConfig& c = in.wanConfig;
    md << "## WAN: both designs through the link emulator\n\n";
    md << fmt::format(
        "A real server and client in one process, every datagram through the link emulator "
        "(RTT split evenly between the two directions, loss in each, the rate per direction "
        "with "
        "Ethernet framing). Per link a fresh client joins (connect to its first full "
        "picture, or "
        "volume), asks for a view 5 degrees round (request to exact picture; the volume "
        "client "
        "renders it itself), then per box size a drilling soak: the server cuts the N^3 box "
        "and "
        "restores it, {:.0f} changes a second, for {:.1f} s ({:.1f} s at the issue's target "
        "link, "
        "100 ms / 1 % / 20 Mbit/s){}. Latency is the client's own figure: the server's cut "
        "to the "
        "changed picture, so at least RTT/2; a tool state's way up adds another RTT/2. "
        "Stall: the "
        "longest time the picture did not change while the drilling went on. Egress: the "
        "server's UDP payload towards the client. The volume design sends 1 byte a voxel "
        "(raw, "
        "as the paper). Every column is in wan.csv.\n\n",
        c.cutHz, c.soakS, c.targetSoakS,
        c.targetSoakS < 60
            ? " (`study all` runs the study quick-sized: `trephine study wan --quick`; "
              "`trephine study wan` runs the whole sweep)"
            : "");
    std::vector<std::vector<std::string>> t;
    for (const WanRow& w : r.rows)
        if (!w.classroom)
            t.push_back({w.design,
                         fmt::format("{:.0f} / {:.0f} / {:.0f}", w.rttMs, w.lossPct, w.rateMbit),
                         fmt::format("{}^3", w.box), fmt::format("{:.1f}", w.updatesPerS),
                         wanFigure(w.latencyP50Ms) + " / " + wanFigure(w.latencyP99Ms),
                         wanFigure(w.joinMs), wanFigure(w.viewChangeMs), wanFigure(w.maxStallMs),
                         fmt::format("{:.2f}", w.egressBytesPerS * 1e-6)});
    md << markdownTable({"design", "RTT (ms) / loss (%) / rate (Mbit/s)", "box", "updates/s",
                         "latency p50 / p99 (ms)", "join (ms)", "view change (ms)", "stall (ms)",
                         "egress (MB/s)"},
                        t);
    const std::vector<int>& boxes = c.boxes;
    const int box = std::find(boxes.begin(), boxes.end(), 40) != boxes.end() ? 40 : boxes.front();
    PlotSpec latency{fmt::format("Update latency p99 at {}^3, 100 Mbit/s", box),
                     "RTT (ms)",
                     "ms",
                     true,
                     640,
                     400,
                     {}};
    PlotSpec join{
        "Join (connect to first full picture), 100 Mbit/s", "RTT (ms)", "ms", true, 640, 400, {}};
    std::vector<double> losses;
    for (const WanRow& w : r.rows)
        if (std::find(losses.begin(), losses.end(), w.lossPct) == losses.end())
            losses.push_back(w.lossPct);
    for (const char* design : {"dbi", "volume"})
        for (double loss : losses) {
            latency.series.push_back(wanSeries(r, design, loss, 100, box, &WanRow::latencyP99Ms));
            join.series.push_back(wanSeries(r, design, loss, 100, box, &WanRow::joinMs));
        }
    writeFile((std::filesystem::path(dir) / "wan.svg").string(), svgLinePlot(latency));
    writeFile((std::filesystem::path(dir) / "wan-join.svg").string(), svgLinePlot(join));
    md << "\n![Update latency over the WAN](wan.svg)\n\n![Join time over the WAN](wan-join.svg)"
          "\n\nPaper: it planned \"to see how the two volumetric C-VE methods compare over a wide "
          "area network\" and measured only its LAN. Image and volume updates travel as reliable "
          "ENet data, retransmitted in order: a lost fragment holds back everything behind it for "
          "a round trip or more, so the p99s and stalls grow with RTT x loss.\n\n";
}

// [Classroom] One driller and N-1 watchers on one shared link (DIR/classroom.svg).
void writeClassroom(std::ostringstream& md, const StudyReportInput& in, const std::string& dir) {
    const WanResults& r = in.wan;
    md << "## Classroom: one driller, the others watching\n\n";
    md << fmt::format(
        "N in-process clients of one design on {} (a shared rate: every client's datagrams "
        "queue for one serialiser each way): client 0 "
        "drills (the server cuts its {}^3 box), the others watch from distinct views (the "
        "paper camera orbited by +-5 to +-35 and 40 degrees: 16 distinct views, then again). "
        "Volume watchers do not re-render on the CPU (a window ray casts on its GPU). "
        "wan-classroom.csv has every client's figures.\n\n",
        classroomLink(in.wanConfig.classroomRateMbit), in.wanConfig.classroomBox);
    std::vector<std::vector<std::string>> t;
    PlotSpec egress{fmt::format("Server egress in a classroom ({})",
                                classroomLink(in.wanConfig.classroomRateMbit)),
                    "clients",
                    "Mbit/s",
                    true,
                    640,
                    400,
                    {}};
    PlotSeries link{"the shared link", {}, {}, "#999999", true};
    for (const char* design : {"dbi", "volume"}) {
        PlotSeries s{design, {}, {}, "", false};
        for (const WanRow& w : r.rows) {
            if (w.design != design || !w.classroom)
                continue;
            s.x.push_back(w.clients);
            s.y.push_back(w.egressBytesPerS * 8e-6);
            if (design == std::string("dbi") && w.rateMbit > 0) {
                link.x.push_back(w.clients);
                link.y.push_back(w.rateMbit);
            }
            t.push_back({design, std::to_string(w.clients),
                         fmt::format("{:.1f}", w.egressBytesPerS * 8e-6),
                         fmt::format("{:.1f}", w.updatesPerS),
                         fmt::format("{:.1f}", w.minUpdatesPerS), wanFigure(w.latencyP50Ms),
                         wanFigure(w.latencyP99Ms), wanFigure(w.maxStallMs), wanFigure(w.joinMs)});
        }
        egress.series.push_back(s);
    }
    if (!link.x.empty())
        egress.series.insert(egress.series.begin(), link);
    md << markdownTable({"design", "clients", "server egress (Mbit/s)", "updates/s (median client)",
                         "slowest client (/s)", "latency p50 (median client, ms)", "worst p99 (ms)",
                         "longest stall (ms)", "last join (ms)"},
                        t);
    writeFile((std::filesystem::path(dir) / "classroom.svg").string(), svgLinePlot(egress));
    md << "\n![Server egress in a classroom](classroom.svg)\n\nPaper: the volume design would "
          "\"quickly flood the network as the number of clients increases\": every volume client "
          "is sent every changed voxel, every DBI client only its view's changed pixels.\n\n";
}

} // namespace

std::string writeStudyReport(const StudyReportInput& in, const std::string& dir) {
    std::filesystem::create_directories(dir);
    const bool linkRun = !in.linkUpdates.empty();
    std::ostringstream md;
    writeHeader(md, in);
    writeTargets(md, in);
    if (!in.updates.empty()) {
        writeTable1(md, in.updates);
        // Figure 7.
        md << "## Figure 7: update rates" << (linkRun ? " over loopback" : "") << "\n\n";
        writeFigure7(
            md, in.updates, dir, "updates.svg", "Update rate (Figure 7)",
            "Paper: the DBI method updated the client 1.5-2.0x faster than the volume method at "
            "every size, over its 100 Mbit/s LAN; both re-rendered the whole 128^3 view. Target: "
            "dbi >= 5x volume.\nAn update rate is 1000 / the median full cycle in ms (server "
            "erosion -> change on the client's screen; cycles run back to back, one at a time).");
        if (linkRun) {
            md << "## Figure 7 over the emulated link\n\n";
            writeFigure7(md, in.linkUpdates, dir, "updates-link.svg",
                         "Update rate over the emulated link (Figure 7)",
                         "The same study and cuts, every client's traffic through " +
                             networkOf(in.linkUpdateConfig) +
                             " (updates-link.csv). `rate=100` is the paper's 100 Mbit/s LAN: "
                             "there a volume update's N^3 bytes cost what they cost the paper.");
        }
        writeFigure8(md, in.updates, dir);
        writeStages(md, in);
    }
    writeDisplay(md, in.display);
    writeHaptics(md, in.haptics);
    if (!in.wan.rows.empty()) {
        writeWan(md, in, dir);
        writeClassroom(md, in, dir);
    }
    return md.str();
}

} // namespace trephine::study

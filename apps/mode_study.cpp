// `trephine study SUBCOMMAND`: the reproducible studies. `haptics`: multi-rate haptics against a
// zero-order hold. `updates`: DBI against replicated-volume update cycles (the paper's Table 1,
// Figures 7 and 8). `display`: the DBI composite's display rate against local volume rendering.
// `wan`: both designs through the link emulator, and a classroom. `all`: every study and
// DIR/report.md. Each takes --quick (a run under a minute). The studies
// live in the study target (study/commands.h); this file parses their flags.
#include "modes.h"

#include "study/commands.h"
#include "study/wan_study.h"

#include <fmt/format.h>

#include <memory>
#include <string>

namespace trephine::app {

using namespace trephine::study;

namespace {

void addHapticsCommand(CLI::App* study, int& exitCode) {
    auto o = std::make_shared<HapticsOptions>();
    CLI::App* haptics = study->add_subcommand(
        "haptics", "Multi-rate haptics vs zero-order hold across update rates and latencies");
    haptics->add_option("--update-rates", o->updateRates, "Force update rates, Hz")
        ->delimiter(',')
        ->capture_default_str();
    haptics->add_option("--latencies", o->latencies, "Round-trip latencies, ms")
        ->delimiter(',')
        ->capture_default_str();
    haptics->add_option("--out", o->out, "Folder for haptics.csv")->capture_default_str();
    haptics->add_option("--volume", o->volume, "Volume spec, or `box` for a flat bone block")
        ->capture_default_str();
    haptics->add_option("--burr", o->burrMm, "Burr diameter, mm (1-6)")->capture_default_str();
    haptics
        ->add_option("--hand", o->hand,
                     "The hand: device (the simulated force device, through the plugin ABI), "
                     "device:PATH.so, or spring (the same physics in the study's code)")
        ->capture_default_str();
    haptics->add_flag("--quick", o->quick,
                      "A reduced grid in well under a minute (--update-rates and --latencies "
                      "given win)");
    haptics->callback([o, haptics, &exitCode] {
        o->ratesGiven = haptics->count("--update-rates") > 0;
        o->latenciesGiven = haptics->count("--latencies") > 0;
        runHapticsStudy(*o);
        exitCode = 0;
    });
}

void addUpdatesCommand(CLI::App* study, int& exitCode) {
    auto u = std::make_shared<UpdatesOptions>();
    CLI::App* updates = study->add_subcommand(
        "updates", "DBI vs replicated-volume update cycles per box size (Table 1, Figures 7, 8)");
    updates->add_option("--out", u->out, "Folder for updates.csv")->capture_default_str();
    updates->add_option("--sizes", u->sizes, "Box edges N (voxels) of the N^3 cuts")
        ->delimiter(',')
        ->check(CLI::Range(1, 512))
        ->capture_default_str();
    updates->add_option("--volume", u->volume, "Volume spec")->capture_default_str();
    updates->add_option("--camera", u->camera, "Camera preset (paper: the paper's setup)")
        ->capture_default_str();
    updates->add_option("--codec", u->codec, "Image codec: raw, lz4 or zstd")
        ->capture_default_str();
    updates->add_option("--cycles", u->cycles, "Measured cycles per method and size")
        ->capture_default_str();
    updates
        ->add_option("--rounds", u->rounds,
                     "Run the sweep this many times, each with its share of the cycles, and pool "
                     "them")
        ->capture_default_str();
    updates
        ->add_option("--link", u->link,
                     "Emulate a link between clients and server, e.g. rate=100,latency=0.1 (the "
                     "paper's 100 Mbit/s LAN); default: plain loopback")
        ->capture_default_str();
    updates
        ->add_option("--methods", u->methods,
                     "Only these methods (dbi, dbi-fullrender, volume, volume-CODEC)")
        ->delimiter(',');
    updates
        ->add_option("--record", u->record,
                     "Log the server's session to this new file (docs/recording.md), to measure "
                     "what recording costs")
        ->check(outputFile());
    updates->add_flag(
        "--quick", u->quick,
        "Sizes 10, 40, 80 and 5 cycles in one round, under a minute (--sizes, --cycles and "
        "--rounds given win)");
    updates->callback([u, updates, &exitCode] {
        u->sizesGiven = updates->count("--sizes") > 0;
        u->cyclesGiven = updates->count("--cycles") > 0;
        u->roundsGiven = updates->count("--rounds") > 0;
        UpdateStudyConfig config;
        runUpdatesStudy(*u, config);
        exitCode = 0;
    });
}

void addDisplayCommand(CLI::App* study, int& exitCode) {
    auto d = std::make_shared<DisplayOptions>();
    CLI::App* display = study->add_subcommand(
        "display", "Display rate: DBI composite vs local volume rendering at 128^3 and 256^3");
    display->add_option("--out", d->out, "Folder for display.csv")->capture_default_str();
    display->add_flag("--quick", d->quick, "Fewer frames: a few seconds");
    display->callback([d, &exitCode] {
        DisplayFigures f = runDisplayStudy(*d);
        if (!f.measured) // said where a script looks for a failure (stdout has it too)
            fmt::print(stderr, "trephine: the display study did not run: {}\n", f.why);
        exitCode = f.measured ? 0 : 1;
    });
}

void addWanCommand(CLI::App* study, int& exitCode) {
    auto o = std::make_shared<WanOptions>();
    CLI::App* wan = study->add_subcommand(
        "wan", "Both designs through an emulated WAN (RTT x loss x rate) and a classroom");
    wan->add_option("--out", o->out, "Folder for wan.csv and wan-classroom.csv")
        ->capture_default_str();
    wan->add_option("--volume", o->volume, "Volume spec")->capture_default_str();
    wan->add_option("--codec", o->codec, "Image codec: raw, lz4 or zstd")
        ->check(CLI::IsMember({"raw", "lz4", "zstd"}))
        ->capture_default_str();
    wan->add_option("--clients", o->clients,
                    "Classroom sizes: one client drills, the others watch (in this process)")
        ->delimiter(',')
        ->check(CLI::Range(1, 256))
        ->capture_default_str();
    wan->add_option("--boxes", o->boxes, "Box edges N (voxels) of the drilling soak's N^3 cuts")
        ->delimiter(',')
        ->check(CLI::Range(1, 512))
        ->capture_default_str();
    wan->add_option("--rtts", o->rtts,
                    "Only these round trips (ms), at 100 Mbit/s, and the target link")
        ->delimiter(',')
        ->check(CLI::Range(0.0, 2000.0));
    wan->add_option("--losses", o->losses, "Only these losses (%), with --rtts")
        ->delimiter(',')
        ->check(CLI::Range(0.0, 50.0));
    wan->add_option("--classroom-rate", o->classroomRateMbit,
                    "The classroom's shared link, Mbit/s (0: no limit, loopback through the relay)")
        ->check(CLI::Range(0.0, 100000.0))
        ->capture_default_str();
    wan->add_option("--soak", o->soakS, "Seconds of each drilling soak (the target link's: 60)")
        ->check(CLI::Range(0.5, 600.0));
    wan->add_flag("--quick", o->quick,
                  "RTT 0 and 100 ms, loss 0 and 1 %, the target link, box 40, short soaks, "
                  "classrooms of 1 and 4: under a minute (--clients and --boxes given win)");
    wan->callback([o, wan, &exitCode] {
        o->clientsGiven = wan->count("--clients") > 0;
        o->boxesGiven = wan->count("--boxes") > 0;
        WanStudyConfig config;
        runWanCommand(*o, config);
        exitCode = 0;
    });
}

void addAllCommand(CLI::App* study, int& exitCode) {
    auto a = std::make_shared<AllOptions>();
    CLI::App* all = study->add_subcommand(
        "all", "Every study, then DIR/report.md with the paper's figures beside ours");
    all->add_option("--out", a->out, "Folder for the CSVs, SVGs and report.md")
        ->capture_default_str();
    all->add_option("--volume", a->volume, "Volume spec for the update study")
        ->capture_default_str();
    all->add_option("--codec", a->codec, "Image codec: raw, lz4 or zstd")->capture_default_str();
    all->add_option("--link", a->link,
                    "Run the update study over loopback, then again over this emulated link "
                    "(default: the paper's 100 Mbit/s LAN); off: loopback only")
        ->capture_default_str();
    all->add_flag("--quick", a->quick, "A reduced run of every study, under a minute");
    all->callback([a, &exitCode] {
        std::string command = "trephine study all --out " + a->out + " --volume " + a->volume +
                              " --codec " + a->codec + " --link " + a->link +
                              (a->quick ? " --quick" : "");
        runAllStudies(*a, command);
        exitCode = 0;
    });
}

} // namespace

void addStudyMode(CLI::App& root, int& exitCode) {
    CLI::App* study = root.add_subcommand("study", "Run the reproducible studies");
    study->require_subcommand(1);
    addHapticsCommand(study, exitCode);
    addUpdatesCommand(study, exitCode);
    addDisplayCommand(study, exitCode);
    addWanCommand(study, exitCode);
    addAllCommand(study, exitCode);
}

} // namespace trephine::app

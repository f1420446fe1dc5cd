// ganache: the command line. Parses arguments, calls the pipeline, maps errors to exit codes:
// 0 success, 2 bad input, 1 run-time failure, 130 / 143 stopped by SIGINT / SIGTERM (after a checkpoint).

#include "app/interrupt.h"
#include "core/errors.h"
#include "core/memory.h"
#include "farm/farm.h"
#include "pipeline/pipeline.h"
#include "tools/study/study.h"

#include <CLI/CLI.hpp>
#include <fmt/format.h>

#include <cmath>
#include <cstdio>

int main(int argc, char** argv) {
    using namespace ganache;
    keepFreedMemory();
    CLI::App app{"ganache: offline simulation of highly viscous and melting fluids.\n"
                 "Stages: sample -> simulate -> surface -> render; `run` does every stage the scene asks for."};
    app.require_subcommand(1);
    RunOptions opt;

    auto addSceneArgs = [&](CLI::App* c) {
        c->add_option("scene", opt.scene, "scene file (YAML, `ganache: 1`; see scenes/README.md)")->required();
        c->add_option("--quality", opt.quality,
                      "preview (default: particle radius x the scene's preview_scale), final (the scene's radius), "
                      "or a number that multiplies the radius");
    };
    // Range messages written for people (CLI11's own quote the type's limits in hundreds of digits).
    const CLI::Validator threadCount(
        [](std::string& text) {
            int v = 0;
            return CLI::detail::lexical_cast(text, v) && v >= 0
                       ? std::string()
                       : fmt::format("must be 0 (every core) or a positive whole number (got '{}')", text);
        },
        "");
    const CLI::Validator positive(
        [](std::string& text) {
            long long v = 0;
            return CLI::detail::lexical_cast(text, v) && v > 0
                       ? std::string()
                       : fmt::format("must be a positive whole number (got '{}')", text);
        },
        "");
    auto addRunArgs = [&](CLI::App* c) {
        addSceneArgs(c);
        c->add_option("--out", opt.out, "output folder (default: out/<scene name>)");
        c->add_option("--frames", opt.frames, "frame range A-B (or one frame A) within the scene's frames");
        c->add_option("--report", opt.report,
                      "where to write the run's report (default: <out>/report.json); runs that share an output "
                      "folder at once, e.g. frame ranges on several machines, each name their own");
        c->add_option("--threads", opt.threads, "worker threads (default 0: every core)")->check(threadCount);
        c->add_flag("--skip-resource-check", opt.skipResourceCheck,
                    "run even when the memory or disk estimate printed at the start exceeds what the machine has");
    };

    struct Command {
        const char* name;
        const char* help;
        std::vector<StageId> stages;
    };
    const std::vector<Command> commands = {
        {"run", "run every stage the scene asks for, in order",
         {StageId::Sample, StageId::Simulate, StageId::Surface, StageId::Render}},
        {"sample", "turn the scene's shapes into fluid and boundary particles (writes sample/<scene>.vdb)",
         {StageId::Sample}},
        {"simulate", "simulate from the sample, writing particles/<scene>.NNNN.vdb", {StageId::Simulate}},
        {"surface", "turn particle caches into level sets and meshes when the scene has a `surface:` section (writes "
                    "surface/<scene>.NNNN.vdb, mesh/<scene>.NNNN.obj)",
         {StageId::Surface}},
        {"render", "render previews of the meshes or particles when the scene has a `render:` section (writes "
                   "preview/<scene>.NNNN.png, a contact sheet, an MP4 when ffmpeg is installed)",
         {StageId::Render}},
    };
    std::vector<CLI::App*> subs;
    for (const auto& c : commands) {
        subs.push_back(app.add_subcommand(c.name, c.help));
        addRunArgs(subs.back());
    }
    for (std::size_t i : {std::size_t(0), std::size_t(2)})
        subs[i]->add_flag("--resume", opt.resume,
                          "continue the simulation from the newest valid checkpoint in the output folder (none: from "
                          "the start); frames written before it are kept");
    for (std::size_t i : {std::size_t(0), std::size_t(3), std::size_t(4)})
        subs[i]->add_flag("--force", opt.force,
                          "redo surface and render frames whose outputs are newer than their inputs");
    subs[4]->add_flag("--frames-only", opt.framesOnly,
                      "render the frames only, no contact sheet or MP4 (a part of a range, as a farm's render task)");
    for (std::size_t i : {std::size_t(0), std::size_t(3)}) {
        subs[i]->add_option("--memory", opt.memoryGiB,
                            "GiB the run may plan for (default: 80 % of what the machine, or its cgroup, has "
                            "free); the surface stage runs frames in parallel as far as it allows")
            ->check(CLI::Validator(
                [](std::string& text) {
                    double v = 0;
                    return CLI::detail::lexical_cast(text, v) && v > 0 && std::isfinite(v)
                               ? std::string()
                               : fmt::format("must be a number of GiB above 0 (got '{}')", text);
                },
                ""));
    }
    bool check = false;
    subs[1]->add_flag("--check", check,
                      "print a pre-flight report of every mesh (closed or not, bad edges and faces, bounds, the "
                      "inside/outside method) and sample nothing");
    bool explain = false;
    CLI::App* sceneCmd = app.add_subcommand("scene", "validate a scene file; --explain prints it with defaults filled in");
    addSceneArgs(sceneCmd);
    sceneCmd->add_flag("--explain", explain, "print the effective scene (every value, defaults included, with units)");

    StudyOptions study;
    CLI::App* studyCmd = app.add_subcommand(
        "study", "what accuracy costs in time: sweep the settings that trade accuracy for speed on the cases in "
                 "scenes/study/ and write study.csv, a chart per case and report.md");
    studyCmd->add_flag("--quick", study.quick, "shorter runs and two settings per knob (a few minutes on 2 cores)");
    studyCmd->add_option("--out", study.out, "output folder (default: out/study; the committed study is docs/study)");
    studyCmd->add_option("--scenes", study.scenes, "folder of the study's scenes (default: scenes/study)");
    studyCmd->add_option("--case", study.cases, "only these cases: spinning_cube, couette, viscous_bunny, stiff_arm");
    studyCmd->add_option("--threads", study.threads, "worker threads (default 0: every core)")->check(threadCount);

    FarmOptions farm;
    std::string farmOut;
    CLI::App* farmCmd = app.add_subcommand(
        "farm", "submit the scene to a Slurm cluster as a job graph: simulate, surface and render arrays over chunks of "
                "frames, and an assemble job (batch scripts in <out>/farm/)");
    farmCmd->add_option("scene", opt.scene, "scene file (YAML, `ganache: 1`; see scenes/README.md)");
    farmCmd->add_option("--quality", opt.quality, "preview (default), final, or a number that multiplies the radius");
    farmCmd->add_option("--out", opt.out,
                        "output folder on a file system every node sees (default: out/<scene name>)");
    farmCmd->add_option("--frames", opt.frames, "frame range A-B (or one frame A) within the scene's frames");
    farmCmd->add_option("--chunk", farm.chunk, "frames per surface and render task (default 10)")->check(positive);
    farmCmd->add_option("--partition", farm.partition, "Slurm partition (default: the cluster's default)");
    farmCmd->add_option("--cpus", farm.cpus,
                        "CPUs of each surface and render task (default: a node's, at most 4; the simulation takes a "
                        "whole node's)")
        ->check(positive);
    farmCmd->add_option("--sbatch", farm.sbatch,
                        "a further sbatch option for every job, e.g. --sbatch=--account=vfx (repeatable)")
        ->allow_extra_args(false);
    farmCmd->add_flag("--resume", opt.resume,
                      "the simulate job continues from the newest valid checkpoint in the output folder (a requeued "
                      "simulate job always does)");
    farmCmd->add_flag("--dry-run", farm.dryRun, "write the batch scripts and print the plan; submit nothing");
    farmCmd->add_flag("--assume-shared", farm.assumeShared,
                      "do not refuse an output folder, scene or program on a file system local to this machine "
                      "(when the same path holds the same files on every node)");
    CLI::App* farmStatus =
        farmCmd->add_subcommand("status", "which frames are done, which jobs run, wait or failed, and how to rerun a task");
    farmStatus->add_option("out", farmOut, "the output folder the farm was submitted with")->required();
    CLI::App* farmReport =
        farmCmd->add_subcommand("report", "merge the tasks' reports into <out>/report.json (the assemble job does it)");
    farmReport->add_option("out", farmOut, "the output folder the farm was submitted with")->required();

    try {
        app.parse(argc, argv);
    } catch (const CLI::ParseError& e) {
        const int code = app.exit(e);
        return code == 0 ? 0 : 2;
    }

    try {
        if (sceneCmd->parsed()) {
            sceneCommand(opt, explain);
            return 0;
        }
        if (studyCmd->parsed()) {
            const InterruptGuard guard;
            study.stopSignal = [] { return InterruptGuard::received(); };
            studyCommand(study);
            return 0;
        }
        if (farmStatus->parsed()) {
            farmStatusCommand(farmOut);
            return 0;
        }
        if (farmReport->parsed()) {
            farmReportCommand(farmOut);
            return 0;
        }
        if (farmCmd->parsed()) {
            if (opt.scene.empty())
                throw InputError("ganache farm: no scene file\n  fix: `ganache farm SCENE [options]`, or `ganache farm "
                                 "status OUT`");
            farmSubmitCommand(opt, farm);
            return 0;
        }
        if (check) {
            meshCheckCommand(opt);
            return 0;
        }
        for (std::size_t i = 0; i < commands.size(); ++i)
            if (subs[i]->parsed()) runCommand(opt, commands[i].stages);
        return 0;
    } catch (const InputError& e) {
        fmt::print(stderr, "error: {}\n", e.what());
        return 2;
    } catch (const Interrupted& e) {
        fmt::print(stderr, "stopped: {}\n", e.what());
        return 128 + e.signal();
    } catch (const std::exception& e) {
        fmt::print(stderr, "error: {}\n", e.what());
        return 1;
    }
}

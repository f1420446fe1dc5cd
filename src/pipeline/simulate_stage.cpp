// The simulate stage: the sample stepped frame by frame into particle caches, with checkpoints every few frames
// (simulation.checkpoint_every), on SIGINT / SIGTERM, and after the last frame; `--resume` continues from the
// newest one that reads back whole.

#include "pipeline/pipeline.h"
#include "pipeline/stages.h"

#include "app/interrupt.h"
#include "app/progress.h"
#include "app/report.h"
#include "core/errors.h"
#include "io/checkpoint.h"
#include "io/particle_cache.h"
#include "physics/simulation.h"

#include <fmt/format.h>

#include <algorithm>
#include <csignal>
#include <cstring>

namespace ganache {

namespace fs = std::filesystem;

namespace {

// The scene's checkpoints in the folder, oldest first: names sort by frame, then step.
std::vector<fs::path> checkpointFiles(const OutputLayout& layout) {
    std::vector<fs::path> out;
    std::error_code ec;
    for (auto it = fs::directory_iterator(layout.checkpoints(), ec); !ec && it != fs::directory_iterator();
         it.increment(ec)) {
        const std::string name = it->path().filename().string();
        if (name.size() > layout.name.size() + 6 && name.rfind(layout.name + ".", 0) == 0 &&
            name.compare(name.size() - 5, 5, ".ckpt") == 0)
            out.push_back(it->path());
    }
    std::sort(out.begin(), out.end());
    return out;
}

// Writes the checkpoint, then drops the scene's checkpoints that sort after it (left by an earlier run that went
// further: not this run's history) and all but the newest `kept` before it.
fs::path saveCheckpoint(const Scene& scene, const OutputLayout& layout, const Simulation& sim, std::int64_t frame) {
    const SimulationState state = sim.state();
    const fs::path path = layout.checkpoint(frame, state.step);
    writeCheckpoint(path, {scene.name, scene.hash, scene.particleRadius, frame}, state);
    const std::vector<fs::path> files = checkpointFiles(layout);
    const auto self = std::find(files.begin(), files.end(), path);
    std::error_code ec;
    for (auto it = files.begin(); it != files.end(); ++it)
        if (it > self || self - it >= scene.checkpointsKept) fs::remove(*it, ec);
    return path;
}

}  // namespace

std::optional<Checkpoint> findResumePoint(const Scene& scene, const OutputLayout& layout, RunReport& report) {
    const std::vector<fs::path> files = checkpointFiles(layout);
    for (auto it = files.rbegin(); it != files.rend(); ++it) {
        Checkpoint c;
        try {
            c = readCheckpoint(*it);
        } catch (const std::exception& e) {
            const std::string text =
                fmt::format("checkpoint {} is unusable: {}; {}", it->string(), e.what(),
                            std::next(it) != files.rend() ? "trying the one before it" : "no older one is left");
            fmt::print(stderr, "resume: {}\n", text);
            report.addWarning("resume: " + text);
            continue;
        }
        if (c.info.sceneHash != scene.hash || c.info.scene != scene.name)
            throw InputError(fmt::format(
                "--resume: {} was saved from another version of the scene (hash {}; {} now has hash {})\n  fix: "
                "restore the scene file it was saved from, or run without --resume to start over",
                it->string(), c.info.sceneHash, scene.file.string(), scene.hash));
        if (std::abs(c.info.particleRadius - scene.particleRadius) > 1e-9 * scene.particleRadius)
            throw InputError(fmt::format("--resume: {} was saved at particle radius {} m, this run uses {} m ({} "
                                         "quality)\n  fix: resume with the --quality it was run at, or run "
                                         "without --resume to start over",
                                         it->string(), formatNumber(c.info.particleRadius),
                                         formatNumber(scene.particleRadius), scene.quality.str()));
        fmt::print(stderr, "resume: from {} (frame {}, t = {:.4f} s, step {})\n", it->string(), c.info.frame,
                   c.state.time, c.state.step);
        return c;
    }
    const std::string text = files.empty()
                                 ? fmt::format("no checkpoint in {}: starting from the beginning",
                                               layout.checkpoints().string())
                                 : "no checkpoint reads back whole: starting from the beginning";
    fmt::print(stderr, "resume: {}\n", text);
    if (!files.empty()) report.addWarning("resume: " + text);
    return std::nullopt;
}

void runSimulate(const Scene& scene, const OutputLayout& layout, std::pair<std::int64_t, std::int64_t> frames,
                 const std::optional<Checkpoint>& from, RunReport& report) {
    StageRecord& stage = report.addStage("simulate");
    Stopwatch clock;
    CacheContents start = readParticleCache(layout.sample());
    if (std::abs(start.info.particleRadius - scene.particleRadius) > 1e-9 * scene.particleRadius)
        throw InputError(fmt::format("{}: sampled at particle radius {} m, but this run uses {} m ({} quality)\n  fix: "
                                     "run `ganache sample` with the same --quality first",
                                     layout.sample().string(), formatNumber(start.info.particleRadius),
                                     formatNumber(scene.particleRadius), scene.quality.str()));
    std::size_t boundaryCount = 0;
    for (const auto& b : start.boundaries) boundaryCount += b.x.size();
    report.setCounts(start.fluid.size(), boundaryCount);

    Simulation sim(simulationSetup(scene), std::move(start.fluid), start.boundaries);
    const FrameRange& fr = scene.frames;
    if (scene.exportPly) fs::create_directories(layout.points(frames.first).parent_path());
    std::size_t written = 0;
    // A frame is written from the step that reaches or passes its time (Simulation::advancePast, writeAt).
    auto writeFrame = [&](std::int64_t f) {
        if (f < frames.first || f > frames.second) return;
        ++written;
        const CacheInfo info{scene.name, f, fr.timeOf(f), fr.fps, scene.particleRadius};
        sim.writeAt(fr.timeOf(f), [&](const ParticleSet& fluid, const std::vector<BoundaryBody>& bodies) {
            writeParticleCache(layout.particles(f), fluid, bodies, info);
            if (scene.exportPly) writeParticlePly(layout.points(f), fluid, info);
        });
        stage.outputs.push_back(layout.particles(f).string());
        if (scene.exportPly) stage.outputs.push_back(layout.points(f).string());
    };
    std::int64_t next = fr.start + 1;
    if (from) {
        try {
            sim.restore(from->state);
        } catch (const std::exception& e) {
            throw InputError(fmt::format("--resume: the checkpoint of frame {} does not fit this scene and sample: "
                                         "{}\n  fix: run without --resume to start over",
                                         from->info.frame, e.what()));
        }
        next = from->info.frame + 1;
    } else {
        writeFrame(fr.start);
    }

    // SIGINT / SIGTERM (caught by the caller's InterruptGuard) stop the run between two steps, with a checkpoint of
    // that moment.
    const auto keepGoing = [] { return InterruptGuard::received() == 0; };
    std::size_t checkpoints = 0;
    double checkpointSeconds = 0;
    Progress progress("simulate", std::size_t(std::max<std::int64_t>(0, frames.second - next + 1)));
    for (std::int64_t f = next; f <= frames.second; ++f) {
        if (!sim.advancePast(fr.timeOf(f), keepGoing)) {
            const int signal = InterruptGuard::received();
            const fs::path saved = saveCheckpoint(scene, layout, sim, f - 1);
            stage.status = "interrupted";
            stage.seconds = clock.seconds();
            stage.outputs.push_back(saved.string());
            report.setSimulation(sim.stats(), sim.time(), sim.effectSummaries(), sim.particles().size());
            throw Interrupted(signal,
                              fmt::format("{} during frame {} (t = {:.4f} s); the state is saved in {}",
                                          strsignal(signal), f, sim.time(), saved.string()));
        }
        writeFrame(f);
        if (scene.checkpointEvery > 0 && ((f - fr.start) % scene.checkpointEvery == 0 || f == frames.second)) {
            const ScopedTimer timer(checkpointSeconds);
            stage.outputs.push_back(saveCheckpoint(scene, layout, sim, f).string());
            ++checkpoints;
        }
        progress.update(std::size_t(f - next + 1));
    }
    progress.finish();
    // The frames' time: the last step may pass the last frame by less than a step.
    report.setSimulation(sim.stats(), std::min(sim.time(), fr.timeOf(frames.second)), sim.effectSummaries(),
                         sim.particles().size());
    report.setBodies(sim.boundary().names, sim.bodyReports());
    if (const auto* emitters = sim.findEffect<Emitters>()) report.setEmitters(emitters->reports());
    stage.seconds = clock.seconds();
    stage.frames = frames.second - (next - 1);
    const SolverStats& s = sim.stats();
    report.measureCount("checkpoints/written", checkpoints);
    report.measure("checkpoints/seconds", checkpointSeconds);
    stage.note = fmt::format("{}{} steps to t = {:.3f} s, {} frames written{}, {} checkpoints ({:.2f} s){}",
                             from ? fmt::format("resumed at frame {} (t = {:.4f} s); ", from->info.frame,
                                                from->state.time)
                                  : std::string(),
                             s.steps, sim.time(), written, scene.exportPly ? " (with PLY points)" : "", checkpoints,
                             checkpointSeconds,
                             s.warningCount ? fmt::format(", {} warnings", s.warningCount) : std::string());
}

}  // namespace ganache

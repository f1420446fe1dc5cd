#include "pipeline/pipeline.h"
#include "pipeline/stages.h"

#include "app/interrupt.h"
#include "app/report.h"
#include "core/errors.h"
#include "io/atomic_file.h"

#include <fmt/format.h>
#include <tbb/global_control.h>
#include <tbb/info.h>

#include <algorithm>
#include <cstdio>
#include <cstring>

namespace ganache {

std::filesystem::path OutputLayout::preview(std::int64_t frame) const {
    return root / "preview" / fmt::format("{}.{:04}.png", name, frame);
}

std::filesystem::path OutputLayout::checkpoint(std::int64_t frame, std::uint64_t step) const {
    return checkpoints() / fmt::format("{}.{:04}.{:07}.ckpt", name, frame, step);
}

std::filesystem::path OutputLayout::particles(std::int64_t frame) const {
    return root / "particles" / fmt::format("{}.{:04}.vdb", name, frame);
}

std::filesystem::path OutputLayout::points(std::int64_t frame) const {
    return root / "points" / fmt::format("{}.{:04}.ply", name, frame);
}

std::filesystem::path OutputLayout::surface(std::int64_t frame) const {
    return root / "surface" / fmt::format("{}.{:04}.vdb", name, frame);
}

std::filesystem::path OutputLayout::mesh(std::int64_t frame) const {
    return root / "mesh" / fmt::format("{}.{:04}.{}", name, frame, meshExtension);
}

std::pair<std::int64_t, std::int64_t> parseFrameRange(const std::string& text, const FrameRange& scene) {
    auto bad = [&](const std::string& why) {
        return InputError(fmt::format("--frames {}: {}\n  fix: give A-B or A within the scene's frames {}-{}", text,
                                      why, scene.start, scene.end));
    };
    std::int64_t a = 0, b = 0;
    char dash = 0, extra = 0;
    const int n = std::sscanf(text.c_str(), "%ld%c%ld%c", &a, &dash, &b, &extra);
    if (n == 1) b = a;
    else if (n != 3 || dash != '-') throw bad("not a frame range");
    if (b < a) throw bad("the range ends before it starts");
    if (a < scene.start || b > scene.end) throw bad("outside the frames the scene defines");
    return {a, b};
}

namespace {

constexpr const char* kStageNames[] = {"sample", "simulate", "surface", "render"};

/// How to carry on after a stop in stage k of `stages`: where a simulation can resume, the same command with
/// --resume; past it, the per-frame stages left, which skip the frames already done.
std::string continueAdvice(const RunOptions& options, const std::vector<StageId>& stages, std::size_t k,
                           const std::filesystem::path& out, const std::function<bool(StageId)>& works) {
    const bool simulates = std::find(stages.begin(), stages.end(), StageId::Simulate) != stages.end();
    if (stages[k] == StageId::Sample || stages[k] == StageId::Simulate)
        return simulates ? "run the same command with --resume" : "run the same command";
    std::string commands;
    for (std::size_t i = k; i < stages.size(); ++i)
        if (works(stages[i]))
            commands += fmt::format("{}`ganache {} {} --out {}{}{}`", commands.empty() ? "" : ", then ",
                                kStageNames[int(stages[i])], options.scene.string(), out.string(),
                                options.quality == "preview" ? "" : " --quality " + options.quality,
                                options.frames.empty() ? "" : " --frames " + options.frames);
    return commands + " (frames already done are skipped)";
}

}  // namespace

void runCommand(const RunOptions& options, const std::vector<StageId>& stages) {
    const Quality quality = Quality::parse(options.quality);
    if (options.threads < 0) throw InputError("--threads must be 0 (every core) or a positive number");
    const Scene scene = loadScene(options.scene, quality);
    const auto frames = options.frames.empty() ? std::make_pair(scene.frames.start, scene.frames.end)
                                               : parseFrameRange(options.frames, scene.frames);

    const int threads = options.threads > 0 ? options.threads : tbb::info::default_concurrency();
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism, std::size_t(threads));
    const OutputLayout layout{options.out.empty() ? std::filesystem::path("out") / scene.name : options.out,
                              scene.name, scene.surface.meshPly ? "ply" : "obj"};
    prepareOutputFolder(layout.root, "--out");
    const std::filesystem::path reportFile = options.report.empty() ? layout.report() : options.report;
    if (!options.report.empty()) prepareOutputFolder(std::filesystem::absolute(reportFile).parent_path(), "--report");
    // From here on SIGINT / SIGTERM stop the run at the next safe point (a step, a frame), and every ending, good
    // or bad, leaves a report.json that says how it ended: an older report never stays behind to mislead.
    const InterruptGuard guard;
    RunReport report(scene, threads);
    report.setFrames(frames.first, frames.second);
    std::size_t current = 0;  // the stage under way
    auto writeOutcome = [&](const char* status, const std::string& why) {
        report.setOutcome(status, why);
        try {
            report.write(reportFile);
        } catch (const std::exception&) {  // e.g. the full disk that stopped the run: its error is the one to see
        }
    };
    // The stages that will do work: `run` passes over those the scene does not ask for.
    const std::function<bool(StageId)> works = [&](StageId id) {
        return !(stages.size() > 1 && ((id == StageId::Surface && !scene.surface.requested) ||
                                       (id == StageId::Render && !scene.render.requested)));
    };
    try {
        checkResources(scene, layout, frames, stages, options.memoryGiB, options.skipResourceCheck, report);
        if (const std::size_t stale = removeStaleTemporaries(layout.root))
            fmt::print(stderr, "removed {} unfinished file(s) that a killed run left in {}\n", stale,
                       layout.root.string());
        const bool simulates = std::find(stages.begin(), stages.end(), StageId::Simulate) != stages.end();
        const std::optional<Checkpoint> resumeFrom =
            options.resume && simulates ? findResumePoint(scene, layout, report) : std::nullopt;

        // A stage run on its own must be asked for by the scene (`run` skips it quietly instead).
        auto requireSection = [&](const char* section, bool requested) {
            if (stages.size() == 1 && !requested)
                throw InputError(fmt::format("ganache {0}: scene '{1}' ({2}) has no `{0}:` section\n  fix: add `{0}: "
                                             "{{}}` for the defaults (see scenes/README.md)",
                                             section, scene.name, scene.file.string()));
        };
        for (current = 0; current < stages.size(); ++current) {
            const StageId id = stages[current];
            if (const int signal = InterruptGuard::received(); signal && works(id))
                throw Interrupted(signal, fmt::format("{} before the {} stage; the stages before it are complete",
                                                      strsignal(signal), kStageNames[int(id)]));
            if (id == StageId::Sample) {
                if (resumeFrom && std::filesystem::exists(layout.sample())) {
                    StageRecord& stage = report.addStage("sample");
                    stage.status = "skipped";
                    stage.note = "resuming: the sample the checkpoint was simulated from is kept";
                } else {
                    runSample(scene, layout, report);
                }
            } else if (id == StageId::Simulate) {
                runSimulate(scene, layout, frames, resumeFrom, report);
            } else if (id == StageId::Surface) {
                requireSection("surface", scene.surface.requested);
                runSurface(scene, layout, frames, options.force, threads, options.memoryGiB, report);
            } else {
                requireSection("render", scene.render.requested);
                runRender(scene, layout, frames, options.force, options.framesOnly, report);
            }
        }
    } catch (const Interrupted& e) {
        const std::string what =
            fmt::format("{}\n  continue: {}", e.what(), continueAdvice(options, stages, current, layout.root, works));
        writeOutcome("interrupted", what);
        throw Interrupted(e.signal(), what);
    } catch (const std::exception& e) {
        writeOutcome("failed", e.what());
        throw;
    }
    report.setOutcome("done", "");
    report.write(reportFile);
    fmt::print(stderr, "{}", report.table());
    fmt::print(stderr, "outputs in {} (report: {})\n", layout.root.string(), reportFile.string());
}

void meshCheckCommand(const RunOptions& options) {
    const Scene scene = loadScene(options.scene, Quality::parse(options.quality));
    auto report = [](const std::string& role, const std::string& name, const MeshShape& m) {
        const MeshCheck& c = m.check;
        const auto [lo, hi] = m.mesh->bounds();
        const char* method = m.method() == InsideMethod::LevelSet ? "level set (OpenVDB mesh to level set)"
                                                                  : "generalised winding numbers";
        fmt::print("{} '{}': {}\n"
                   "  {} vertices, {} triangles in {} piece(s); {}\n"
                   "  boundary edges {}, non-manifold edges {}, degenerate triangles {} (dropped), flipped triangles "
                   "{} (turned back)\n"
                   "  bounds in the scene [{:.4g}, {:.4g}, {:.4g}] to [{:.4g}, {:.4g}, {:.4g}] m, volume {:.4g} m^3\n"
                   "  inside/outside: {}{}\n",
                   role, name, m.description, c.vertices, c.triangles, c.components,
                   c.closed() ? "closed" : "NOT closed", c.boundaryEdges, c.nonManifoldEdges, c.degenerateTriangles,
                   c.flippedTriangles, lo.x(), lo.y(), lo.z(), hi.x(), hi.y(), hi.z(), c.volume, method,
                   m.inside == InsideMethod::Auto ? " (chosen automatically)" : "");
    };
    std::size_t meshes = 0;
    for (const auto& f : scene.fluids)
        if (auto* m = std::get_if<MeshShape>(&f.shape)) report("fluid", f.name, *m), ++meshes;
    for (const auto& b : scene.boundaries)
        if (auto* m = std::get_if<MeshShape>(&b.shape)) report("boundary", b.name, *m), ++meshes;
    fmt::print("{}: {} mesh(es); about {:.3g} fluid particles at {} quality (r = {} m)\n", scene.file.string(), meshes,
               estimateFluidParticles(scene, scene.particleRadius), scene.quality.str(),
               formatNumber(scene.particleRadius));
}

void sceneCommand(const RunOptions& options, bool explain) {
    const Scene scene = loadScene(options.scene, Quality::parse(options.quality));
    if (explain) {
        fmt::print("{}", explainScene(scene));
        return;
    }
    fmt::print("{}: scene '{}' is valid: {} fluid(s), {} boundary(ies), {} emitter(s), effects: {}; about {:.3g} fluid "
               "particles at {} quality (r = {} m)\n",
               scene.file.string(), scene.name, scene.fluids.size(), scene.boundaries.size(), scene.emitters.size(),
               scene.effects.empty() ? std::string("none") : [&] {
                   std::vector<std::string> names;
                   for (const auto& e : scene.effects) names.push_back(e.name);
                   return joinNames(names);
               }(),
               estimateFluidParticles(scene, scene.particleRadius), scene.quality.str(),
               formatNumber(scene.particleRadius));
}

}  // namespace ganache

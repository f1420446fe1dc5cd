#include "pipeline/pipeline.h"
#include "pipeline/stages.h"

#include "io/atomic_file.h"
#include "io/particle_cache.h"
#include "core/errors.h"
#include "app/progress.h"
#include "app/report.h"
#include "sampler/sampler.h"
#include "physics/simulation.h"
#include "surfacer/surfacer.h"

#include <fmt/format.h>
#include <tbb/global_control.h>
#include <tbb/info.h>

#include <tbb/parallel_for.h>

#include <cstdio>
#include <fstream>
#include <memory>
#include <mutex>

namespace ganache {

namespace {

void runSample(const Scene& scene, const OutputLayout& layout, RunReport& report) {
    StageRecord& stage = report.addStage("sample");
    Stopwatch clock;
    const SampleCache cache(layout.sampleCache());
    const Sample sample = sampleScene(scene, &cache);
    std::size_t boundaryCount = 0;
    for (const auto& b : sample.boundaries) boundaryCount += b.x.size();
    report.setCounts(sample.fluid.size(), boundaryCount);

    for (std::size_t f = 0; f < scene.fluids.size(); ++f)
        report.measureCount("sample/fluid_particles/" + scene.fluids[f].name, sample.fluidCounts[f]);
    for (const auto& b : sample.boundaries) report.measureCount("sample/boundary_particles/" + b.name, b.x.size());
    report.measureCount("sample/lattice_sites_carved/by_earlier_fluids", sample.carved);
    report.measureCount("sample/lattice_sites_carved/near_boundaries", sample.carvedByBoundaries);
    report.measure("sample/initial_density_error/max_compression", sample.density.maxCompression);
    report.measure("sample/initial_density_error/mean_interior", sample.density.meanInterior);
    report.measureCount("sample/initial_density_error/interior_particles", sample.density.interiorCount);
    for (std::size_t f = 0; f < scene.fluids.size(); ++f) {
        if (sample.fluidCounts[f] > 0) continue;
        const std::string why =
            sample.fluidSites[f] == 0 ? "no lattice site of spacing 2r lies inside it"
            : sample.fluidCarvedByBoundaries[f] > 0 ? "it lies entirely inside a boundary or within 2r of one"
                                                    : "an earlier fluid already holds all of it";
        throw SceneError(scene.fluids[f].at,
                         fmt::format("fluid '{}' holds no particle at particle radius {} m: {}", scene.fluids[f].name,
                                     formatNumber(scene.particleRadius), why),
                         "make the fluid larger than one particle diameter, move it out of the solids, or use a "
                         "finer --quality");
    }

    CacheInfo info{scene.name, scene.frames.start, 0.0, scene.frames.fps, scene.particleRadius};
    writeParticleCache(layout.sample(), sample.fluid, sample.boundaries, info);
    stage.seconds = clock.seconds();
    stage.outputs.push_back(layout.sample().string());
    stage.note = fmt::format("{} fluid + {} boundary particles; initial max compression {:.2g} %{}", sample.fluid.size(),
                             boundaryCount, 100 * sample.density.maxCompression,
                             sample.cacheHits + sample.cacheMisses
                                 ? fmt::format("; meshes: {} from the cache, {} sampled", sample.cacheHits,
                                               sample.cacheMisses)
                                 : std::string());
    report.measureCount("sample/mesh_cache/hits", sample.cacheHits);
    report.measureCount("sample/mesh_cache/misses", sample.cacheMisses);
}

void runSurface(const Scene& scene, const OutputLayout& layout, std::pair<std::int64_t, std::int64_t> frames,
                bool force, int threads, double memoryGiB, RunReport& report) {
    StageRecord& stage = report.addStage("surface");
    const SurfaceSettings& settings = scene.surface;
    if (!settings.requested) {
        stage.status = "skipped";
        stage.note = "the scene asks for no surface (no `surface:` section)";
        return;
    }
    Stopwatch clock;
    requireParticleCaches("surface", scene, layout, frames);
    std::vector<std::int64_t> todo;
    std::size_t skipped = 0;
    for (std::int64_t f = frames.first; f <= frames.second; ++f) {
        const bool fresh = upToDate(layout.surface(f), layout.particles(f)) &&
                           (!settings.mesh || upToDate(layout.mesh(f), layout.particles(f)));
        if (fresh && !force) ++skipped;
        else todo.push_back(f);
    }
    auto readFrame = [&](std::int64_t f) {
        try {
            return readParticleCache(layout.particles(f));
        } catch (const std::exception& e) {
            throw InputError(fmt::format("surface: frame {}: {}", f, e.what()));
        }
    };
    std::mutex lock;
    std::size_t done = 0, particles = 0, triangles = 0;
    double frameSeconds = 0;
    std::string failure;
    std::optional<Progress> progress;  // none when every frame is up to date
    if (!todo.empty()) progress.emplace("surface", todo.size());
    // Frames in parallel, as many at once as the memory allows (each frame is itself parallel).
    std::size_t batch = 1;
    for (std::size_t start = 0; start < todo.size() && failure.empty(); start += batch) {
        // The batch's first frame sizes the batch, and is then surfaced from this same read.
        std::optional<CacheContents> first = readFrame(todo[start]);
        const double need = estimateSurfaceBytes(first->fluid.size(), scene.particleRadius, settings);
        // What frames may use: as much as --memory says, or 80 % of what is free (the rest for everything else).
        const double budget = memoryGiB > 0 ? memoryGiB * (1 << 30) : 0.8 * availableBytes();
        if (need > budget)
            throw SceneError(settings.at,
                             fmt::format("surfacing frame {} ({}, {} particles) at a voxel of {} x the particle "
                                         "radius needs about {:.2f} GiB, more than the {:.2f} GiB {}",
                                         todo[start], layout.particles(todo[start]).string(), first->fluid.size(),
                                         formatNumber(settings.voxelFraction), need / (1 << 30), budget / (1 << 30),
                                         memoryGiB > 0 ? "--memory allows" : "it may use of what is free"),
                             "raise surface.voxel_size, or surface on a machine with more free memory");
        batch = std::size_t(std::clamp<double>(std::floor(budget / need), 1, threads));
        const std::size_t end = std::min(todo.size(), start + batch);
        tbb::parallel_for(std::size_t(start), end, [&](std::size_t k) {
            const std::int64_t f = todo[k];
            try {
                Stopwatch frameClock;
                const CacheContents cache = k == start ? std::move(*first) : readFrame(f);
                const FrameSurface surface = surfaceParticles(cache.fluid, scene.particleRadius, settings);
                std::filesystem::create_directories(layout.surface(f).parent_path());
                surface.writeVdb(layout.surface(f), scene.name, f);
                if (settings.mesh) {
                    std::filesystem::create_directories(layout.mesh(f).parent_path());
                    writeObj(layout.mesh(f), surface.mesh(),
                             fmt::format("ganache {} frame {} (t = {:.4f} s): {} particles\n"
                                         "units: metres; y up{}",
                                         scene.name, f, cache.info.time, cache.fluid.size(),
                                         surface.mesh().temperature.empty()
                                             ? ""
                                             : "; vt u = temperature [C] per vertex"));
                }
                const std::lock_guard<std::mutex> guard(lock);
                ++done;
                particles += cache.fluid.size();
                triangles += surface.mesh().triangles.size();
                frameSeconds += frameClock.seconds();
                progress->update(done);
            } catch (const InputError& e) {
                const std::lock_guard<std::mutex> guard(lock);
                if (failure.empty()) failure = e.what();
            } catch (const std::exception& e) {
                const std::lock_guard<std::mutex> guard(lock);
                if (failure.empty()) failure = fmt::format("surface: frame {}: {}", f, e.what());
            }
        });
    }
    if (progress) progress->finish();
    if (!failure.empty()) throw InputError(failure + "\n  (frames finished before it are complete and kept)");
    for (std::int64_t f : todo) {
        stage.outputs.push_back(layout.surface(f).string());
        if (settings.mesh) stage.outputs.push_back(layout.mesh(f).string());
    }
    stage.seconds = clock.seconds();
    stage.status = todo.empty() ? "skipped" : "done";
    stage.note = fmt::format("{} frames surfaced with method {}, voxel {} r{}{}", done, surfaceMethodName(settings.method),
                             formatNumber(settings.voxelFraction),
                             done ? fmt::format("; {:.1f} core-us per particle per frame, {:.0f} triangles per frame",
                                                1e6 * frameSeconds * threads / std::max<double>(1, double(particles)),
                                                double(triangles) / double(done))
                                  : std::string(),
                             skipped ? fmt::format("; {} up to date, skipped (--force redoes them)", skipped)
                                     : std::string());
}

}  // namespace

bool upToDate(const std::filesystem::path& output, const std::filesystem::path& input) {
    std::error_code ec;
    const auto out = std::filesystem::last_write_time(output, ec);
    if (ec) return false;
    return out >= std::filesystem::last_write_time(input, ec) && !ec;
}

void requireParticleCaches(const char* stage, const Scene& scene, const OutputLayout& layout,
                           std::pair<std::int64_t, std::int64_t> frames) {
    for (std::int64_t f = frames.first; f <= frames.second; ++f)
        if (!std::filesystem::exists(layout.particles(f)))
            throw InputError(fmt::format("{}: frame {} has no particle cache ({})\n  fix: simulate frames {}-{} "
                                         "first (`ganache simulate {} --frames {}-{}`), or pick frames that were "
                                         "simulated with --frames",
                                         stage, f, layout.particles(f).string(), frames.first, frames.second,
                                         scene.file.string(), frames.first, frames.second));
}

std::filesystem::path OutputLayout::preview(std::int64_t frame) const {
    return root / "preview" / fmt::format("{}.{:04}.png", name, frame);
}

std::filesystem::path OutputLayout::checkpoint(std::int64_t frame, std::uint64_t step) const {
    return checkpoints() / fmt::format("{}.{:04}.{:07}.ckpt", name, frame, step);
}

std::filesystem::path OutputLayout::particles(std::int64_t frame) const {
    return root / "particles" / fmt::format("{}.{:04}.vdb", name, frame);
}

std::filesystem::path OutputLayout::surface(std::int64_t frame) const {
    return root / "surface" / fmt::format("{}.{:04}.vdb", name, frame);
}

std::filesystem::path OutputLayout::mesh(std::int64_t frame) const {
    return root / "mesh" / fmt::format("{}.{:04}.obj", name, frame);
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

void runCommand(const RunOptions& options, const std::vector<StageId>& stages) {
    const Quality quality = Quality::parse(options.quality);
    if (options.threads < 0) throw InputError("--threads must be 0 (every core) or a positive number");
    const Scene scene = loadScene(options.scene, quality);
    const auto frames = options.frames.empty() ? std::make_pair(scene.frames.start, scene.frames.end)
                                               : parseFrameRange(options.frames, scene.frames);

    const int threads = options.threads > 0 ? options.threads : tbb::info::default_concurrency();
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism, std::size_t(threads));
    const OutputLayout layout{options.out.empty() ? std::filesystem::path("out") / scene.name : options.out,
                              scene.name};
    RunReport report(scene, threads);
    checkResources(scene, layout, frames, stages, options.memoryGiB, options.skipResourceCheck, report);
    if (const std::size_t stale = removeStaleTemporaries(layout.root))
        fmt::print(stderr, "removed {} unfinished file(s) that a killed run left in {}\n", stale, layout.root.string());
    const bool simulates = std::find(stages.begin(), stages.end(), StageId::Simulate) != stages.end();
    const std::optional<Checkpoint> resumeFrom =
        options.resume && simulates ? findResumePoint(scene, layout, report) : std::nullopt;

    // A stage run on its own must be asked for by the scene (`run` skips it quietly instead).
    auto requireSection = [&](const char* section, bool requested) {
        if (stages.size() == 1 && !requested)
            throw InputError(fmt::format("ganache {0}: scene '{1}' ({2}) has no `{0}:` section\n  fix: add `{0}: {{}}` "
                                         "for the defaults (see scenes/README.md)",
                                         section, scene.name, scene.file.string()));
    };
    for (StageId id : stages) {
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
            try {
                runRender(scene, layout, frames, options.force, report);
            } catch (const InputError&) {
                report.write(layout.report());  // the frames that did render are in it
                throw;
            }
        }
    }
    report.write(layout.report());
    fmt::print(stderr, "{}", report.table());
    fmt::print(stderr, "outputs in {} (report: {})\n", layout.root.string(), layout.report().string());
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

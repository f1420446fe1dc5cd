// The surface stage: each frame's particles as a level set (surface/<scene>.NNNN.vdb) and a mesh
// (mesh/<scene>.NNNN.obj), frames in parallel as far as the free memory allows.

#include "pipeline/frame_stage.h"
#include "pipeline/stages.h"

#include "app/report.h"
#include "core/errors.h"
#include "io/particle_cache.h"
#include "surfacer/surfacer.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <mutex>

namespace ganache {

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
    FrameJobs jobs("surface", "surfaced", frames, force, [&](std::int64_t f) {
        return upToDate(layout.surface(f), layout.particles(f)) &&
               (!settings.mesh || upToDate(layout.mesh(f), layout.particles(f)));
    });
    const auto& todo = jobs.todo();
    // A cache that cannot be read is bad input, whatever the reader threw.
    auto readFrame = [&](std::int64_t f) {
        try {
            return readParticleCache(layout.particles(f));
        } catch (const std::exception& e) {
            throw InputError(e.what());
        }
    };
    std::mutex lock;
    std::vector<std::string> warnings;
    std::size_t particles = 0, triangles = 0;
    double frameSeconds = 0;
    // Frames in parallel, as many at once as the memory allows (each frame is itself parallel); a batch that
    // fails ends the stage.
    std::size_t batch = 1;
    for (std::size_t start = 0; start < todo.size() && !jobs.failed() && !jobs.stopped(); start += batch) {
        // The batch's first frame sizes the batch, and is then surfaced from this same read.
        std::optional<CacheContents> first;
        try {
            first = readFrame(todo[start]);
        } catch (const InputError& e) {
            throw InputError(fmt::format("surface: frame {}: {}", todo[start], e.what()));
        }
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
        jobs.run(start, std::min(todo.size(), start + batch), [&](std::int64_t f) {
            Stopwatch frameClock;
            const CacheContents cache = f == todo[start] ? std::move(*first) : readFrame(f);
            const FrameSurface surface = surfaceParticles(cache.fluid, scene.particleRadius, settings);
            std::filesystem::create_directories(layout.surface(f).parent_path());
            surface.writeVdb(layout.surface(f), scene.name, f);
            if (settings.mesh) {
                std::filesystem::create_directories(layout.mesh(f).parent_path());
                writeSurfaceMesh(layout.mesh(f), surface.mesh(),
                         fmt::format("ganache {} frame {} (t = {:.4f} s): {} particles\nunits: metres; y up{}",
                                     scene.name, f, cache.info.time, cache.fluid.size(),
                                     surface.mesh().temperature.empty() ? ""
                                     : settings.meshPly                  ? "; vertex property temperature [C]"
                                                                         : "; vt u = temperature [C] per vertex"));
            }
            const std::lock_guard<std::mutex> guard(lock);
            if (surface.activeVoxels() == 0 && !cache.fluid.empty())
                warnings.push_back(fmt::format(
                    "surface: frame {}: its {} fluid particle(s) gave an empty surface (no mesh, no level set): they "
                    "are too scattered for method {} (lone particles have no neighbours to share a surface with); "
                    "method: spheres keeps every particle, or sample the fluid at a finer --quality",
                    f, cache.fluid.size(), surfaceMethodName(settings.method)));
            particles += cache.fluid.size();
            triangles += surface.mesh().triangles.size();
            frameSeconds += frameClock.seconds();
        });
    }
    std::sort(warnings.begin(), warnings.end());
    for (const std::string& w : warnings) report.addWarning(w);
    for (std::int64_t f : todo)
        if (std::filesystem::exists(layout.surface(f))) {
            stage.outputs.push_back(layout.surface(f).string());
            if (settings.mesh) stage.outputs.push_back(layout.mesh(f).string());
        }
    jobs.finish();
    const std::size_t done = jobs.done();
    stage.seconds = clock.seconds();
    stage.frames = std::int64_t(done);
    stage.status = todo.empty() ? "skipped" : "done";
    stage.note = fmt::format("{} frames surfaced with method {}, voxel {} r{}{}", done, surfaceMethodName(settings.method),
                             formatNumber(settings.voxelFraction),
                             done ? fmt::format("; {:.1f} core-us per particle per frame, {:.0f} triangles per frame",
                                                1e6 * frameSeconds * threads / std::max<double>(1, double(particles)),
                                                double(triangles) / double(done))
                                  : std::string(),
                             jobs.skipped() ? fmt::format("; {} up to date, skipped (--force redoes them)", jobs.skipped())
                                            : std::string());
}

}  // namespace ganache

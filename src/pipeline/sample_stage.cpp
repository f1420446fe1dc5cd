// The sample stage: the scene's shapes as fluid and boundary particles in sample/<scene>.vdb, the mesh inputs
// cached in cache/.

#include "pipeline/stages.h"

#include "app/report.h"
#include "core/errors.h"
#include "io/particle_cache.h"
#include "sampler/sampler.h"

#include <fmt/format.h>

namespace ganache {

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

}  // namespace ganache

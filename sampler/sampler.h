#pragma once
// The sample stage: a scene's fluid shapes become lattice particles and its solids become boundary particles.

#include "core/kernels.h"
#include "core/particles.h"
#include "sampler/sample_cache.h"
#include "scene/scene.h"

#include <string>
#include <vector>

namespace ganache {

/// Initial density of the sample relative to each particle's rest density (rho / rho_0 - 1).
struct DensityCheck {
    Real maxCompression = 0;  ///< largest positive value: a compressed start pushes particles apart
    Real meanInterior = 0;    ///< mean over particles with a full neighbourhood (no free surface nearby)
    std::size_t interiorCount = 0;
};

struct Sample {
    ParticleSet fluid;
    std::vector<BoundaryBody> boundaries;
    std::vector<std::size_t> fluidCounts;  ///< particles per scene fluid, in scene order
    std::vector<std::size_t> fluidSites;   ///< lattice sites inside each fluid's shape, before carving
    std::vector<std::size_t> fluidCarvedByBoundaries;  ///< of those, inside a solid or too close to a boundary
    std::size_t carved = 0;                ///< lattice sites dropped because an earlier fluid holds them
    std::size_t carvedByBoundaries = 0;    ///< lattice sites dropped for lying closer than 2r to a boundary
    DensityCheck density;
    std::size_t cacheHits = 0, cacheMisses = 0;  ///< mesh inputs read from / written to the cache
};

/// Samples every fluid of the scene on a lattice of spacing 2r (r = scene.particleRadius), optionally jittered,
/// and every boundary on its surface with spacing <= r. Fluid inside a closed solid or closer than 2r to any
/// boundary is carved. Particle masses make the interior of the lattice exactly rest density.
/// With several sources of fluid (fluids and emitters), each particle carries the scalar attribute `fluid`: its
/// index in Scene::sourceMaterials().
/// With a cache, the sampled points of every mesh input are read from it when their key matches, and stored
/// otherwise.
Sample sampleScene(const Scene& scene, const SampleCache* cache = nullptr);

/// Densities of the fluid particles from the fluid and boundary neighbours, relative to rest: rho_i / rho0_i - 1.
/// rho0_i of each particle comes from its mass and the lattice (all fluids share one lattice spacing).
DensityCheck checkDensity(const ParticleSet& fluid, const std::vector<Real>& restDensity,
                          const std::vector<BoundaryBody>& boundaries, const CubicSpline& w);

}  // namespace ganache

#pragma once
// Shared set-up for solver tests: scenes written to a temporary folder and sampled in memory.

#include "sampler/sampler.h"
#include "scene/scene.h"
#include "physics/simulation.h"
#include "physics/viscosity/viscosity.h"

#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <random>
#include <string>

namespace ganache::testing {

/// A free block of 12^3 honey particles (r = 1 cm) in zero gravity: every particle near a free surface or corner.
inline const char* kFreeBlock = R"(particles: {radius: 0.01}
domain: {min: [-1, -1, -1], max: [1, 1, 1]}
fluids: [{material: honey, box: {min: [-0.12, -0.12, -0.12], max: [0.12, 0.12, 0.12]}}]
)";

/// Loads a scene from text (at final quality), written to the temporary folder under `name`.
inline Scene sceneFromText(const std::string& name, const std::string& body) {
    const std::filesystem::path dir = std::filesystem::temp_directory_path() / "ganache_solver_test";
    std::filesystem::create_directories(dir);
    std::ofstream(dir / (name + ".yaml")) << "ganache: 1\n" << body;
    return loadScene(dir / (name + ".yaml"), Quality::parse("final"));
}

/// Samples the scene and starts a simulation of it.
inline Simulation simulationOf(const Scene& scene) {
    Sample s = sampleScene(scene);
    return Simulation(scene, std::move(s.fluid), s.boundaries);
}

inline Real maxSpeed(const ParticleSet& p) {
    Real m = 0;
    for (const Vec3& v : p.v()) m = std::max(m, v.norm());
    return m;
}

inline Vec3 linearMomentum(const ParticleSet& p) {
    Vec3 s = Vec3::Zero();
    for (std::size_t i = 0; i < p.size(); ++i) s += p.mass()[i] * p.v()[i];
    return s;
}

inline Vec3 angularMomentum(const ParticleSet& p) {
    Vec3 s = Vec3::Zero();
    for (std::size_t i = 0; i < p.size(); ++i) s += p.mass()[i] * p.x()[i].cross(p.v()[i]);
    return s;
}

/// Samples the scene and starts a simulation with the velocity field `velocity(x)` instead of the scene's.
template <class F>
Simulation simulationWithVelocity(const Scene& scene, F&& velocity) {
    Sample s = sampleScene(scene);
    for (std::size_t i = 0; i < s.fluid.size(); ++i) s.fluid.v()[i] = velocity(s.fluid.x()[i]);
    return Simulation(scene, std::move(s.fluid), s.boundaries);
}

/// What one viscosity pass did to a random velocity field (normal, unit variance per component): the changes
/// of linear and angular momentum, each relative to its scale (total mass times a unit speed, times `size` for
/// angular momentum), the kinetic energy kept, and the stats.
struct SolveOutcome {
    Real momentumChange, angularChange, kineticKept;
    SolverStats stats;
};

/// One pass of the viscosity method `params` names on a random velocity field, with the neighbourhoods and
/// densities of the sampled scene (zero gravity), dt = 10 ms.
inline SolveOutcome solveRandomField(const ViscosityParams& params, const std::string& sceneBody, Real size = 0.12) {
    const Scene scene = sceneFromText("random_field", sceneBody);
    std::mt19937_64 rng(3);
    std::normal_distribution<Real> n(0, 1);
    Simulation sim = simulationWithVelocity(scene, [&](const Vec3&) { return Vec3(n(rng), n(rng), n(rng)); });
    SolveOutcome out{};
    BodyLoads loads;
    StepContext ctx{0.01, 0, 0, sim.kernel(), sim.fluidNeighbours(), sim.boundaryNeighbours(), sim.density(),
                    *sim.particles().findScalar("_rest_density"), sim.boundary(), out.stats, loads};
    ParticleSet particles = sim.particles();
    makeViscosity(params, scene, particles)->apply(ctx, particles);

    Real mass = 0, kinetic0 = 0, kinetic1 = 0;
    for (std::size_t i = 0; i < particles.size(); ++i) {
        mass += particles.mass()[i];
        kinetic0 += sim.particles().v()[i].squaredNorm();
        kinetic1 += particles.v()[i].squaredNorm();
    }
    out.momentumChange = (linearMomentum(particles) - linearMomentum(sim.particles())).norm() / mass;
    out.angularChange = (angularMomentum(particles) - angularMomentum(sim.particles())).norm() / (mass * size);
    out.kineticKept = kinetic1 / kinetic0;
    return out;
}

}  // namespace ganache::testing

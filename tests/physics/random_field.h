#pragma once
// One viscosity pass on a random velocity field: what it does to momentum, angular momentum and energy.

#include "physics/viscosity/viscosity.h"
#include "world.h"

#include <random>

namespace ganache::testing {

/// A free block of 12^3 honey particles (r = 1 cm) in zero gravity: every particle near a free surface or corner.
inline World freeBlock() {
    World w(0.01);
    w.block(Vec3::Constant(-0.12), Vec3::Constant(0.12), preset("honey"));
    return w;
}

/// What one viscosity pass did to a random velocity field (normal, unit variance per component): the changes
/// of linear and angular momentum, each relative to its scale (total mass times a unit speed, times `size` for
/// angular momentum), the kinetic energy kept, and the effect's counters.
struct SolveOutcome {
    Real momentumChange, angularChange, kineticKept;
    std::size_t iterations, capHits;
};

/// One pass of the viscosity method `params` names on a random velocity field, with the neighbourhoods and
/// densities of the free block, dt = 10 ms.
inline SolveOutcome solveRandomField(const ViscosityParams& params, Real size = 0.12) {
    const World world = freeBlock();
    std::mt19937_64 rng(3);
    std::normal_distribution<Real> n(0, 1);
    Simulation sim = world.simulation(withVelocity([&](const Vec3&) { return Vec3(n(rng), n(rng), n(rng)); }));
    SolverStats stats;
    BodyLoads loads;
    StepContext ctx{0.01, 0, 0, sim.kernel(), sim.fluidNeighbours(), sim.boundaryNeighbours(), sim.gradients(),
                    sim.positionRows(), sim.density(), sim.restDensity(), sim.boundary(), stats, loads};
    ParticleSet particles = sim.particles();
    const auto effect = makeViscosity(params, world.finalSetup(), particles);
    effect->apply(ctx, particles);

    SolveOutcome out{};
    Real mass = 0, kinetic0 = 0, kinetic1 = 0;
    for (std::size_t i = 0; i < particles.size(); ++i) {
        mass += particles.mass()[i];
        kinetic0 += sim.particles().v()[i].squaredNorm();
        kinetic1 += particles.v()[i].squaredNorm();
    }
    out.momentumChange = (linearMomentum(particles) - linearMomentum(sim.particles())).norm() / mass;
    out.angularChange = (angularMomentum(particles) - angularMomentum(sim.particles())).norm() / (mass * size);
    out.kineticKept = kinetic1 / kinetic0;
    for (const Counter& c : effect->counters(1)) {
        if (c.name == "iterations_per_solve") out.iterations = std::size_t(c.value);
        if (c.name == "cap_hits") out.capHits = std::size_t(c.value);
    }
    return out;
}

}  // namespace ganache::testing

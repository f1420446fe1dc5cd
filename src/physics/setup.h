#pragma once
// SimulationSetup: everything a simulation needs besides its particles, in typed values. The scene reader fills it
// (scene/scene.h: simulationSetup()); tests and tools may build one directly. No YAML, no render settings.

#include "physics/bodies.h"
#include "physics/effect.h"
#include "physics/emitter.h"
#include "physics/materials.h"

#include <memory>
#include <string_view>
#include <vector>

namespace ganache {

/// Time stepping: CFL-limited dt clamped to [dtMin, dtMax], or a fixed dt.
struct TimeStepSettings {
    Real cfl = 0.4;      ///< dt <= cfl * particle diameter / max speed
    Real dtMin = 1e-5;   ///< [s]
    Real dtMax = 5e-3;   ///< [s]
    Real fixedDt = 0;    ///< [s]; > 0 replaces the CFL rule (refinement studies)
};

/// DFSPH tolerances (Bender & Koschier 2017) and the solver that reaches them.
struct PressureSettings {
    /// mprgp: projected conjugate gradients (Dostal & Schoeberl 2005), ganache's; jacobi: DFSPH's relaxed Jacobi.
    /// Both stop at the same residual; Jacobi needs 5-7 times the iterations on a resting column.
    enum class Solver { Mprgp, Jacobi };
    Solver solver = Solver::Mprgp;
    Real densityError = 1e-4;     ///< mean relative compression allowed after the constant-density solve
    Real divergenceError = 1e-3;  ///< mean relative density rate dt Drho/Dt / rho_0 allowed after the divergence solve
    std::int64_t maxIterations = 100;
    /// Fewest iterations of the constant-density solve (DFSPH's 2). MPRGP measures the exact residual before each
    /// iteration and could stop at 0, but with both solves free to, a honey column at rest crept at 1.0 cm/s instead of
    /// 0.3 and the bunny's spread moved 5.3 % between 5 and 0.05 ms steps (tests).
    std::int64_t minIterations = 2;
    /// Fewest iterations of the divergence-free solve: DFSPH's 1, which is all the anchors' blocks need on most steps
    /// (2 always cost block8k 1.7 more iterations a step). Raised to 2 for the step after a constant-density solve of
    /// more than impactIterations: with 1 throughout, the 1M-particle impact of step_bench took 83 constant-density
    /// iterations a step instead of 25 (its divergence-free solve meets the mean residual in one iteration while the
    /// impact is a small part of the fluid, and the constant-density solve inherits what that left), and the buckling
    /// anchor's landing sheet ended 1.43 % compressed at its densest instead of 0.47. Calm steps take 2-4
    /// constant-density iterations, landings 5-100; at 6 the buckling sheet ends at 0.40 %, at 12 at 1.43 %.
    std::int64_t minDivergenceIterations = 1;
    std::int64_t impactIterations = 6;  ///< constant-density iterations past which a step counts as an impact
    /// The share of its compression that the constant-density solve removes in one step from a particle the viscosity
    /// moves as one body (attribute::kViscouslyRigid); 1 removes it all, as DFSPH does everywhere. A landing stiff body
    /// ends its step compressed where the linearised solve did not foresee it (its contact layer moves most of a
    /// radius a step), and removing that at once pushes the contact layer up at compression / dt, which the next
    /// viscosity solve spreads over the whole body: a 1e6 Pa s block rebounded at 9 cm/s (27,000 particles). Half a
    /// step's worth (Baumgarte's error reduction, as rigid-body contact solvers use) lets it land.
    Real rigidCorrection = 0.5;
    /// Fluid particles from which the projected CG solves also solve exactly for pressures constant over cells of
    /// about 4^3 particles, larger past 4,096 cells (PressureCoarseSpace): a pressure then crosses a body at once
    /// instead of a layer an iteration. It pays on bodies many layers thick: the 50k anchor block 7.5 -> 4.25 products
    /// a step, the step 10-15 % shorter (1 thread); a 1M-particle honey blob's impact 27.8 -> 9.5, the step half as
    /// long (2 threads). Where it pays less than its build: the 8k block 5.05 -> 4.05 products but the step 2-6 %
    /// longer, the 2.6k buckling sheet the same products and 5 % longer, the default scene at final quality (43k,
    /// melting into a puddle) 14.6 -> 13.9 and 3-6 % longer (docs/benchmarks.md). The default lies between the
    /// largest measured fluid it slowed (43k) and the smallest it sped up (50.6k).
    std::int64_t coarseFrom = 50000;
};

/// Where the viscosity solve sits in a step (see simulation.h).
struct ViscosityOrder {
    enum class Kind {
        Predicted,  ///< ganache's: after the forces and the pressure warm start, before the constant-density solve
        Paper,      ///< Algorithm 1 of Weiler et al. 2018: after the divergence-free solve
        Coupled     ///< alternating `passes` times with the constant-density solve before advection
    };
    Kind kind = Kind::Predicted;
    std::int64_t passes = 3;  ///< for Coupled
};

/// A source of fluid particles: a fluid present at t = 0 or an emitter.
struct FluidSource {
    Material material;
    Real temperature = 20;  ///< initial temperature [C], used with the heat effect
};

struct SimulationSetup {
    Real particleRadius = 0;  ///< [m]
    Vec3 domainMin = Vec3::Constant(-1), domainMax = Vec3::Constant(1);  ///< particles leaving it are removed [m]
    TimeStepSettings timeStep;
    PressureSettings pressure;
    ViscosityOrder viscosityOrder;
    /// The fluids present at t = 0, then the emitters: a particle's attribute::kFluid indexes this list.
    std::vector<FluidSource> sources;
    std::vector<BodySetup> bodies;      ///< every boundary body, by name
    std::vector<EmitterSpec> emitters;  ///< their sources are the last emitters.size() entries of `sources`
    std::vector<EffectSpec> effects;    ///< in the scene's order

    const EffectSpec* findEffect(std::string_view name) const {
        for (const auto& e : effects)
            if (e.name == name) return &e;
        return nullptr;
    }
    /// A private copy of the parameters of the effect `name`, for a study to change before the simulation is made;
    /// std::logic_error when the set-up has no such effect with parameters of type P.
    template <class P>
    P& editEffect(std::string_view name) {
        for (auto& e : effects)
            if (e.name == name)
                if (const auto* p = dynamic_cast<const P*>(e.params.get())) {
                    auto copy = std::make_shared<P>(*p);
                    e.params = copy;
                    return *copy;
                }
        throw std::logic_error("the set-up has no effect '" + std::string(name) + "' of that type");
    }
};

}  // namespace ganache

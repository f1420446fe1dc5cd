#pragma once
// One simulation step, filled with the effects a scene asks for. With simulation.viscosity_coupling = 0 it is
// Algorithm 1 of Weiler et al. 2018:
//   heat -> forces (gravity, ...) -> CFL time step -> constant-density solve [BK17] -> advection -> neighbour
//   search, densities, DFSPH factors -> divergence-free solve [BK17] -> viscosity [WKBB18] -> end of step
// With n > 0 (default 3) the constant-density solve and the viscosity solve alternate n times before advection
// and the divergence-free solve ends the step. Emitters (when the scene has any) add their layers right after
// advection, so the neighbour search, densities and factors that follow include the new particles. Just before
// advection, approaches to boundaries closer than one particle radius are taken out (keepOffBoundaries).

#include "physics/effect.h"
#include "physics/emitter.h"
#include "core/kernels.h"
#include "core/neighbour_search.h"
#include "core/particles.h"
#include "scene/scene.h"

#include <functional>
#include <limits>
#include <memory>
#include <string>
#include <vector>

namespace ganache {

class PressureDFSPH;

/// Every boundary particle of the scene in one set (Akinci et al. 2012).
struct BoundaryParticles {
    std::vector<Vec3> x;
    std::vector<Vec3> v;           ///< velocities of the bodies' particles (zero for static bodies) [m/s]
    std::vector<Vec3> x0;          ///< positions at t = 0 [m]
    std::vector<Real> volume;      ///< V_k; pseudo-mass Psi_k = rho_0 V_k [m^3]
    std::vector<std::uint32_t> body;
    std::vector<std::string> names;
    std::vector<BodyMotion> motion;  ///< per body
    bool anyMoving = false;
};

/// The fluid's push on each body during the current step, as impulses [N s] and angular impulses [N m s]
/// about the body's rotation centre at the step's end.
struct BodyLoads {
    std::vector<Vec3> impulse, angularImpulse;
    void clear(std::size_t bodies) {
        impulse.assign(bodies, Vec3::Zero());
        angularImpulse.assign(bodies, Vec3::Zero());
    }
};

/// Force and torque of the fluid on one body over a run.
struct BodyReport {
    Vec3 meanForce = Vec3::Zero();   ///< total impulse / time [N]
    Vec3 meanTorque = Vec3::Zero();  ///< [N m]
    Real peakForce = 0;              ///< largest |force| averaged over one step [N]
};

/// Wall time [s] spent in each part of the step, summed over the steps.
struct StageTimes {
    double heat = 0, forces = 0, pressure = 0, advect = 0, emit = 0, neighbours = 0, divergence = 0, viscosity = 0,
           endOfStep = 0;
    double total() const {
        return heat + forces + pressure + advect + emit + neighbours + divergence + viscosity + endOfStep;
    }
};

/// What the solvers did, summed over the steps, and what went wrong.
struct SolverStats {
    std::size_t steps = 0;
    std::size_t pressureIterations = 0, pressureCapHits = 0;
    std::size_t divergenceIterations = 0, divergenceCapHits = 0;
    std::size_t viscositySolves = 0, viscosityIterations = 0, viscosityCapHits = 0;
    Real viscosityWorstResidual = 0;  ///< largest relative residual a viscosity solve ended with
    std::size_t removedParticles = 0;  ///< left the domain
    std::size_t emittedParticles = 0;  ///< added by emitters
    std::size_t boundaryContacts = 0;  ///< approaches to a boundary stopped at one particle radius
    std::size_t heatSubsteps = 0, heatSubstepsMax = 0;  ///< conduction sub-steps, summed and the most in one step
    Real dtMin = std::numeric_limits<Real>::infinity(), dtMax = 0;
    StageTimes time;
    std::vector<std::string> warnings;  ///< the first kMaxWarnings, then only counted
    std::size_t warningCount = 0;
    static constexpr std::size_t kMaxWarnings = 50;
    void warn(std::string text);
};

/// What an effect may read in one step; nothing is global.
struct StepContext {
    Real dt = 0;
    Real time = 0;  ///< at the start of the step [s]
    std::size_t step = 0;
    const CubicSpline& kernel;
    const NeighbourList& fluidNeighbours;     ///< fluid-fluid, at the current positions
    const NeighbourList& boundaryNeighbours;  ///< fluid-boundary
    const std::vector<Real>& density;         ///< [kg/m^3], at the current positions
    const std::vector<Real>& restDensity;     ///< rho_0 of each particle [kg/m^3]
    const BoundaryParticles& boundary;
    SolverStats& stats;
    BodyLoads& loads;
};

/// Everything a simulation carries from one step to the next beyond what its scene and sample give: checkpoints
/// save it, and a simulation restored from it takes the same steps as the one it was saved from.
struct SimulationState {
    Real time = 0;
    std::uint64_t step = 0;
    std::uint64_t nextId = 0;  ///< id of the next emitted particle
    ParticleSet fluid;         ///< every attribute, the solvers' warm starts included, in the simulation's order
    std::vector<EmitterState> emitters;
    std::vector<Vec3> totalImpulse, totalAngular;  ///< per body, over the run
    std::vector<Real> peakForce;
    SolverStats stats;
};

/// A running simulation: fluid particles, boundaries and the effects of the scene.
class Simulation {
public:
    Simulation(const Scene& scene, ParticleSet fluid, const std::vector<BoundaryBody>& bodies);
    ~Simulation();

    /// Advances one step, no longer than maxDt. Throws std::runtime_error naming the stage and the particle at
    /// the first non-finite value.
    void step(Real maxDt = std::numeric_limits<Real>::infinity());
    /// Steps until the time reaches t exactly; the last two steps share what is left, so none is a sliver.
    /// Before each step it asks `keepGoing` (when given) and returns false as soon as that says no.
    bool advanceTo(Real t, const std::function<bool()>& keepGoing = {});

    /// The state to save, and the way back to it: restore() takes a simulation built from the same scene and
    /// sample to the saved moment; std::runtime_error when the state is not of this scene.
    SimulationState state() const;
    void restore(const SimulationState& state);

    Real time() const { return m_time; }
    const ParticleSet& particles() const { return m_fluid; }
    const BoundaryParticles& boundary() const { return m_boundary; }
    const std::vector<Real>& density() const { return m_density; }
    const SolverStats& stats() const { return m_stats; }
    const CubicSpline& kernel() const { return m_kernel; }
    const NeighbourList& fluidNeighbours() const { return m_fluidNeighbours; }
    const NeighbourList& boundaryNeighbours() const { return m_boundaryNeighbours; }
    /// Names of the effects the scene asked for, in stage order.
    const std::vector<std::string>& effectNames() const { return m_effectNames; }
    /// The fluid's force and torque on each body so far.
    std::vector<BodyReport> bodyReports() const;
    /// What each emitter added so far (empty when the scene has none).
    std::vector<EmitterReport> emitterReports() const;

private:
    StepContext context(Real dt);
    void updateNeighbours(bool mayReorder);
    void computeDensities();
    Real chooseDt(Real maxDt) const;
    void removeEscaped();
    void keepOffBoundaries(StepContext& ctx);
    void moveBoundaries(Real t);
    void checkFinite(const char* stage);

    Real m_particleRadius;
    CubicSpline m_kernel;
    Real m_latticeSum;  // sum of W over the sampling lattice: a lattice particle of mass m has density m times this
    Vec3 m_domainMin, m_domainMax;
    TimeStepSettings m_timeStep;
    PressureSettings m_pressureSettings;
    std::int64_t m_coupling;  // 0: viscosity after the divergence-free solve; n: n passes before advection

    ParticleSet m_fluid;
    BoundaryParticles m_boundary;
    UniformGrid m_fluidGrid, m_boundaryGrid;
    NeighbourList m_fluidNeighbours, m_boundaryNeighbours;
    std::vector<Real> m_density;
    std::vector<Vec3> m_contactChange;            // keepOffBoundaries' scratch, kept between steps
    std::vector<std::uint32_t> m_contactNearest;
    std::vector<Real>* m_restDensity;  // a particle attribute, so it moves with reordering and removal

    std::unique_ptr<PressureDFSPH> m_pressure;
    std::unique_ptr<Emitters> m_emitters;  // only when the scene has emitters
    std::uint64_t m_nextId = 0;            // id of the next emitted particle
    std::vector<std::vector<std::unique_ptr<Effect>>> m_effects;  // by Stage
    std::vector<std::string> m_effectNames;

    Real m_time = 0;
    std::size_t m_step = 0;
    SolverStats m_stats;
    BodyLoads m_loads;                                 // this step's
    std::vector<Vec3> m_totalImpulse, m_totalAngular;  // per body, over the run
    std::vector<Real> m_peakForce;
};

}  // namespace ganache

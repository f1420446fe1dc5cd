#pragma once
// One simulation step, filled with the effects a scene asks for. In ganache's order (ViscosityOrder::Predicted):
//   CFL time step -> Start effects (heat) -> divergence-free solve [BK17] -> Forces effects (gravity) -> the last
//   step's constant-density pressure as a warm start -> Viscosity effects [WKBB18] -> constant-density solve [BK17]
//   -> contact -> advection -> Emit effects (emitters) -> neighbour search, densities, DFSPH factors
// which is Algorithm 1 of Weiler et al. 2018 (ViscosityOrder::Paper) with the viscosity solve moved in front of the
// constant-density solve's iterations. Simulation owns this order and nothing else: the effects live in their own
// files, the bodies' motion and loads in bodies.h, the contact rule in contact.h.

#include "core/kernels.h"
#include "core/neighbour_search.h"
#include "core/particles.h"
#include "physics/bodies.h"
#include "physics/contact.h"
#include "physics/effect.h"
#include "physics/pair_sweeps.h"
#include "physics/setup.h"

#include <array>
#include <functional>
#include <limits>
#include <memory>
#include <string>
#include <vector>

namespace ganache {

class PressureDFSPH;

/// Wall time [s] of the step's own parts, summed over the steps (each effect's time is kept with the effect).
struct StageTimes {
    double pressure = 0, advect = 0, neighbours = 0, divergence = 0;
    double total() const { return pressure + advect + neighbours + divergence; }
};

/// What the step's own solvers did, summed over the steps, and what went wrong (effects keep their own counters).
struct SolverStats {
    std::size_t steps = 0;
    std::size_t pressureIterations = 0, pressureCapHits = 0;
    std::size_t lastPressureIterations = 0;  ///< of the latest constant-density solve (see impactIterations)
    std::size_t divergenceIterations = 0, divergenceCapHits = 0;
    std::size_t removedParticles = 0;  ///< left the domain
    std::size_t addedParticles = 0;    ///< added during the run (emitters)
    std::size_t boundaryContacts = 0;  ///< approaches to a boundary stopped at one particle radius
    std::size_t stepsPastCfl = 0;      ///< steps longer than the CFL condition allows (a fixed or minimum step)
    Real cflExcess = 0;                ///< the largest dt / CFL step among them
    Real dtMin = std::numeric_limits<Real>::infinity(), dtMax = 0;
    StageTimes time;
    std::vector<std::string> warnings;  ///< the first kMaxWarnings, then only counted
    std::size_t warningCount = 0;
    static constexpr std::size_t kMaxWarnings = 50;
    void warn(std::string text);
};

/// The kernel gradient of every neighbour pair at the current positions, as the factor g with grad W(x_ij) = g x_ij,
/// in the order of the neighbour lists (pair p of particle i is NeighbourList::first(i) + ...). Computed once after
/// each neighbour search, with the densities, and used by every sweep of the next step: no solver evaluates the
/// kernel again.
struct PairGradients {
    std::vector<Real> fluid;     ///< fluid-fluid pairs
    std::vector<Real> boundary;  ///< fluid-boundary pairs
};

/// What an effect may read in one step; nothing is global.
struct StepContext {
    Real dt = 0;
    Real time = 0;  ///< at the start of the step [s]
    std::size_t step = 0;
    const CubicSpline& kernel;
    const NeighbourList& fluidNeighbours;     ///< fluid-fluid, at the current positions
    const NeighbourList& boundaryNeighbours;  ///< fluid-boundary
    const PairGradients& gradients;           ///< of both lists' pairs
    const sweeps::Rows& positionRows;         ///< the fluid's positions as the pair sweeps read them
    const std::vector<Real>& density;         ///< [kg/m^3], at the current positions
    const std::vector<Real>& restDensity;     ///< rho_0 of each particle [kg/m^3]
    const BoundaryParticles& boundary;
    SolverStats& stats;
    BodyLoads& loads;
};

/// One effect's share of a run.
struct EffectSummary {
    std::string name;
    double seconds = 0;             ///< wall time in its stage, over the run
    std::vector<Counter> counters;  ///< what it reports
};

/// Everything a simulation carries from one step to the next beyond what its set-up and sample give: checkpoints
/// save it, and a simulation restored from it takes the same steps as the one it was saved from.
struct SimulationState {
    struct EffectState {
        std::string name;
        double seconds = 0;
        std::string bytes;  ///< what the effect saved (Effect::save)
    };
    Real time = 0;
    std::uint64_t step = 0;
    ParticleSet fluid;  ///< every attribute, the solvers' warm starts included, in the simulation's order
    std::vector<EffectState> effects;
    std::string pressure;  ///< what the pressure solver saved (PressureDFSPH::save)
    std::vector<Vec3> totalImpulse, totalAngular;  ///< per body, over the run
    std::vector<Real> peakForce;
    SolverStats stats;
};

/// A running simulation: fluid particles, boundaries and the effects of the set-up.
class Simulation {
public:
    Simulation(const SimulationSetup& setup, ParticleSet fluid, const std::vector<BoundaryBody>& bodies);
    ~Simulation();

    /// Advances one step, no longer than maxDt. Throws std::runtime_error naming the stage and the particle at
    /// the first non-finite value.
    void step(Real maxDt = std::numeric_limits<Real>::infinity());
    /// Steps until the time reaches t exactly; the last two steps share what is left, so none is a sliver.
    /// Before each step it asks `keepGoing` (when given) and returns false as soon as that says no.
    bool advanceTo(Real t, const std::function<bool()>& keepGoing = {});
    /// Steps until the time reaches t or has just passed it, each step as long as the time step settings allow, so
    /// that where frames fall changes no step; writeAt() gives the fluid at t. With the paper's or the coupled order
    /// the velocity at a step's end is not the one it moved with: those land on t as advanceTo() does.
    bool advancePast(Real t, const std::function<bool()>& keepGoing = {});
    /// Calls write with the fluid and the moving bodies as they were at time t within the last step: each particle
    /// on the straight path the step moved it along (x - (time() - t) v), every other attribute as at the step's end.
    using FrameWriter = std::function<void(const ParticleSet& fluid, const std::vector<BoundaryBody>& movingBodies)>;
    void writeAt(Real t, const FrameWriter& write);
    /// Whether the time has reached t (to round-off).
    bool reached(Real t) const { return t - m_time <= 1e-12 * std::max<Real>(1, std::abs(t)); }

    /// The state to save, and the way back to it: restore() takes a simulation built from the same set-up and
    /// sample to the saved moment; std::runtime_error when the state is not of this simulation.
    SimulationState state() const;
    void restore(const SimulationState& state);

    Real time() const { return m_time; }
    const ParticleSet& particles() const { return m_fluid; }
    const BoundaryParticles& boundary() const { return m_boundary; }
    const std::vector<Real>& density() const { return m_density; }
    const std::vector<Real>& restDensity() const { return *m_restDensity; }
    const SolverStats& stats() const { return m_stats; }
    const CubicSpline& kernel() const { return m_kernel; }
    const NeighbourList& fluidNeighbours() const { return m_fluidNeighbours; }
    const NeighbourList& boundaryNeighbours() const { return m_boundaryNeighbours; }
    const PairGradients& gradients() const { return m_gradients; }
    const sweeps::Rows& positionRows() const { return m_positionRows; }
    /// Names of the effects that run, in the order they were made (the scene's, then emitters).
    std::vector<std::string> effectNames() const;
    /// Every effect's time and counters.
    std::vector<EffectSummary> effectSummaries() const;
    /// One counter of one effect (see Effect::counters); 0 when the effect does not run.
    double counter(std::string_view effect, std::string_view name) const;
    /// The effect of type E, or null when none runs (for what a caller needs beyond counters).
    template <class E>
    const E* findEffect() const {
        for (const auto& e : m_effects)
            if (const auto* found = dynamic_cast<const E*>(e.effect.get())) return found;
        return nullptr;
    }
    /// The fluid's force and torque on each body so far.
    std::vector<BodyReport> bodyReports() const;

private:
    struct RunningEffect {
        std::string name;
        Stage stage;
        std::unique_ptr<Effect> effect;
        double seconds = 0;
    };

    StepContext context(Real dt);
    void runStage(Stage stage, StepContext& ctx, const char* checkName);
    void updateNeighbours(bool mayReorder);
    void computeDensities();
    /// The longest step the CFL condition allows at the current velocities (infinite at rest).
    Real cflStep() const;
    Real chooseDt(Real maxDt, Real cflStep) const;
    void removeEscaped();
    void divergenceFree(StepContext& ctx);
    void moveBoundaries(Real t);
    void checkFinite(const char* stage);

    Real m_particleRadius;
    CubicSpline m_kernel;
    Real m_latticeSum;  // sum of W over the sampling lattice: a lattice particle of mass m has density m times this
    Vec3 m_domainMin, m_domainMax;
    TimeStepSettings m_timeStep;
    PressureSettings m_pressureSettings;
    ViscosityOrder m_order;
    Real m_gravity = 0;  // |g| of the gravity effect [m/s^2]; 0 without it

    ParticleSet m_fluid;
    BoundaryParticles m_boundary;
    UniformGrid m_fluidGrid, m_boundaryGrid;
    NeighbourList m_fluidNeighbours, m_boundaryNeighbours;
    PairGradients m_gradients;
    sweeps::Rows m_positionRows;  // taken with the densities, after each neighbour search
    std::vector<Real> m_density;
    std::vector<Real>* m_restDensity;  // a particle attribute, so it moves with reordering and removal
    Contact m_contact;

    std::unique_ptr<PressureDFSPH> m_pressure;
    std::vector<RunningEffect> m_effects;                       // in the order they were made
    std::array<std::vector<std::size_t>, kStageCount> m_stages;  // indices into m_effects, by stage

    Real m_time = 0;
    std::size_t m_step = 0;
    SolverStats m_stats;
    BodyLoads m_loads;                                 // this step's
    std::vector<Vec3> m_totalImpulse, m_totalAngular;  // per body, over the run
    std::vector<Real> m_peakForce;
};

}  // namespace ganache

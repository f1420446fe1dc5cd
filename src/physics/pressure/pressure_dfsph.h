#pragma once
// Divergence-free SPH pressure solves (Bender & Koschier 2017, "Divergence-Free SPH for Incompressible and
// Viscous Fluids", IEEE TVCG 23(3)), with boundaries after Akinci et al. 2012.

#include "physics/pair_sweeps.h"
#include "physics/pressure/pressure_coarse.h"
#include "physics/simulation.h"

namespace ganache {

/// The constant-density and divergence-free solves. The constant-density pressure kappa / rho is kept per particle as
/// an uncached attribute to warm-start the next step. Pressures stay >= 0 (a fluid pushes, it never pulls): each solve
/// is a bound-constrained problem, solved by projected conjugate gradients (MPRGP) or DFSPH's relaxed Jacobi
/// (PressureSettings::solver). Every sweep reads the kernel gradients of the step's pairs (StepContext::gradients).
class PressureDFSPH {
public:
    PressureDFSPH(const PressureSettings& settings, ParticleSet& particles);

    /// DFSPH factors 1 / (|sum m grad W + kWall sum Psi grad W|^2 + sum |m grad W|^2) at the current
    /// positions [BK17 Eq. 11], and the coarse space of the pressure solves (PressureCoarseSpace) for bodies of many
    /// particles: rebuilt every few steps when mayRebuild, otherwise only the particles' cells are found anew.
    void computeFactors(const StepContext& ctx, const ParticleSet& particles, bool mayRebuild = true);
    /// The coarse space as last built, and when: a resumed run solves as the uninterrupted one did.
    void save(ByteWriter& out) const;
    void restore(ByteReader& in);
    /// Applies the previous step's constant-density pressure, times `scale`, to the velocities: the warm start of
    /// this step's constant-density solve. Its net push on the particles the viscosity moves as one body
    /// (attribute::kViscouslyRigid) is at most their weight over the step: their mass times `support` [m/s], the
    /// velocity change gravity gives in the step.
    void applyWarmStart(StepContext& ctx, ParticleSet& particles, Real scale, Real support);
    /// Constant-density solve on the predicted velocities, before advection, from the pressures applied so far
    /// (the warm start, and earlier passes of the step).
    void solveDensity(StepContext& ctx, ParticleSet& particles);
    /// Divergence-free solve on the velocities of the current positions.
    void solveDivergence(StepContext& ctx, ParticleSet& particles);

private:
    enum class Solve { Density, Divergence };
    // The solve shared by both: `target(i, Drho/Dt)` is the signed density error [kg/m^3] particle i must remove;
    // it stops when the mean complementarity residual relative to rho_0 is below the solve's tolerance. Returns the
    // iterations (products with the system).
    template <class Target>
    std::size_t solve(Solve which, StepContext& ctx, ParticleSet& particles, std::vector<Real>& pressure,
                      Target target);
    template <class Target>
    std::size_t solveMprgp(Solve which, StepContext& ctx, ParticleSet& particles, std::vector<Real>& pressure,
                           Target target);
    template <class Target>
    std::size_t solveJacobi(Solve which, StepContext& ctx, ParticleSet& particles, std::vector<Real>& pressure,
                            Target target);
    // Drho/Dt of every particle for the velocities u, with the bodies' own velocities when withBodies (the
    // system's product leaves them out); each fixed block of the sweep goes on to term(i) for its particles, and the
    // results join (deterministically: see deterministicBlockReduce) into what is returned.
    template <class T, class Term, class Join>
    T rates(const StepContext& ctx, const ParticleSet& particles, const std::vector<Vec3>& u, bool withBodies,
            std::vector<Real>& out, T zero, Term term, Join join);
    // The same for the velocities already in m_velocityRows.
    template <class T, class Term, class Join>
    T ratesOfRows(const StepContext& ctx, std::size_t n, bool withBodies, std::vector<Real>& out, T zero, Term term,
                  Join join) const;
    // -dt (sum_j m_j (s_i + s_j) grad W_ij + kWall sum_k Psi_k s_i grad W_ik): every particle's velocity change from
    // the pressures s (kappa / rho); the boundary mirrors the particle's own pressure [AIA+12, BK17]. With rows, also
    // into m_velocityRows, for ratesOfRows; with `velocities`, also added to them in the same pass.
    void velocityChanges(const StepContext& ctx, const ParticleSet& particles, const std::vector<Real>& s,
                         std::vector<Vec3>& out, bool rows = false, std::vector<Vec3>* velocities = nullptr);
    // Adds the impulse the pressures `s` gave through the boundary to each body's load.
    void addBoundaryLoads(StepContext& ctx, const ParticleSet& particles, const std::vector<Real>& s) const;
    // Whether a solve with this mean residual stops after `iteration` iterations (the tolerance reached and the
    // fewest done, or the cap); a stop at the cap above the tolerance is counted and warned of.
    bool finished(StepContext& ctx, Solve which, std::size_t iteration, Real error) const;

    PressureSettings m_settings;
    std::vector<Real> m_factor;     // 1 / A_ii, 0 where it vanishes (lone particles)
    // Per pair of the step: m_j g_ij for fluid pairs, kWall rho_0i V_k g_ik for boundary pairs (grad W = g x).
    sweeps::PairWeights m_weights;
    std::vector<Real> m_boundaryWeights;
    // Per particle of the step, the boundary summed once (it stands still during a solve): sum_k w_ik x_ik, and the
    // bodies' velocities' share of the density rate, sum_k w_ik v_k . x_ik.
    std::vector<Vec3> m_boundarySum;
    std::vector<Real> m_bodyRate;
    std::vector<Vec3> m_gradientSum;  // G_i: sum_j w_ij x_ij plus the boundary sum
    PressureCoarseSpace m_coarse;
    std::uint64_t m_coarseBuilt = 0;          // the step it was built in
    Eigen::VectorXd m_coarseRhs, m_coarseQ;  // per cell: the restricted gradient, then the cells' pressures; and q
    struct CoarseRun {
        std::uint32_t cell;
        Real gradient, q;
    };
    std::vector<std::vector<CoarseRun>> m_coarseRuns;  // per block of particles, its sums by cell
    std::vector<Real>* m_pressure;  // constant-density pressure, warm start of the next step
    std::vector<Real> m_pressureV;  // divergence-free pressure of this step
    std::vector<Real> m_start;      // pressures at the start of a solve
    // Scratch of the solvers, kept between steps.
    std::vector<Real> m_error, m_direction, m_product, m_change, m_rate;
    std::vector<Vec3> m_velocityChange;
    // A rate's velocities as the sweeps read them (the positions' rows come with the step context).
    sweeps::Rows m_velocityRows;
};

}  // namespace ganache

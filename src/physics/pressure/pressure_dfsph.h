#pragma once
// Divergence-free SPH pressure solves (Bender & Koschier 2017, "Divergence-Free SPH for Incompressible and
// Viscous Fluids", IEEE TVCG 23(3)), with boundaries after Akinci et al. 2012.

#include "physics/simulation.h"

namespace ganache {

/// The constant-density and divergence-free solves. The constant-density pressure kappa / rho is kept per
/// particle as an uncached attribute (kPressure in pressure_dfsph.cpp) to warm-start the next step. Pressures stay >= 0 (a fluid
/// pushes, it never pulls), so each solve is a projected, relaxed Jacobi iteration.
class PressureDFSPH {
public:
    PressureDFSPH(const PressureSettings& settings, ParticleSet& particles);

    /// DFSPH factors 1 / (|sum m grad W + kWall sum Psi grad W|^2 + sum |m grad W|^2) at the current
    /// positions [BK17 Eq. 11].
    void computeFactors(const StepContext& ctx, const ParticleSet& particles);
    /// Applies the previous step's constant-density pressure to the velocities: the warm start of this step's
    /// constant-density solve.
    void applyWarmStart(StepContext& ctx, ParticleSet& particles);
    /// Constant-density solve on the predicted velocities, before advection, from the pressures applied so far
    /// (the warm start, and earlier passes of the step).
    void solveDensity(StepContext& ctx, ParticleSet& particles);
    /// Divergence-free solve on the velocities after advection.
    void solveDivergence(StepContext& ctx, ParticleSet& particles);

private:
    enum class Solve { Density, Divergence };
    // The shared iteration: `target(i, Drho/Dt)` is the signed density error [kg/m^3] particle i must remove;
    // stops when the mean complementarity residual relative to rho_0 is below the solve's tolerance. Returns the
    // iterations.
    template <class Target>
    std::size_t solve(Solve which, StepContext& ctx, ParticleSet& particles, std::vector<Real>& pressure,
                      Target target);

    template <class Target>
    std::size_t solveMprgp(Solve which, StepContext& ctx, ParticleSet& particles, std::vector<Real>& pressure,
                           Target target);
    // v -= dt grad(s) / rho: the velocity change of pressures s (kappa / rho) [BK17].
    void applyPressure(const StepContext& ctx, ParticleSet& particles, const std::vector<Real>& s) const;
    // Adds the impulse the pressures `s` gave through the boundary to each body's load.
    void addBoundaryLoads(StepContext& ctx, const ParticleSet& particles, const std::vector<Real>& s) const;

    PressureSettings m_settings;
    std::vector<Real> m_factor;  // 1 / denominator, 0 where it vanishes (lone particles)
    std::vector<Real> m_rate;    // Drho/Dt of the current iteration
    std::vector<Real> m_step;    // this iteration's change of the pressure value
    std::vector<Real>* m_pressure;  // constant-density pressure, warm start of the next step
    std::vector<Real> m_pressureV;  // divergence-free pressure of this step
    std::vector<Real> m_start;      // pressures at the start of a solve that does not warm-start
};

}  // namespace ganache

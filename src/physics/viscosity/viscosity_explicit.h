#pragma once
// Explicit viscosity, for comparison with the implicit solver (effects.viscosity.method: explicit).

#include "physics/viscosity/viscosity.h"

namespace ganache {

/// The Laplacian of Eq. 7 [WKBB18] (and the boundary term of Eq. 12) integrated with forward Euler,
/// v += dt_s A v, in as many equal sub-steps dt_s as stability asks: forward Euler on a symmetric negative
/// semi-definite A is stable for dt_s < 2 / |lambda_min(A)|, and Gershgorin's circles bound |lambda_min(A)| by
/// the largest row sum of the block norms, sum_j 2 c_ij |grad W_ij| |x_ij| (+ the boundary's share). The cost of
/// a step grows with mu dt / (rho h^2): what the implicit solvers exist to avoid. max_iterations caps the
/// sub-steps of one step; a step that needs more stops the run with the number it needs.
class ViscosityExplicit final : public ViscosityMethod {
public:
    ViscosityExplicit(const ViscosityParams& params, const SimulationSetup& setup, ParticleSet& particles)
        : ViscosityMethod(params, setup, particles) {}

    /// The stable sub-step dt_s of the current particles [s] (infinite when nothing couples).
    Real stableStep(const StepContext& ctx, const ParticleSet& particles) const;

protected:
    ViscosityPass solve(StepContext& ctx, const ParticleSet& particles, std::vector<Vec3>& out) override;

private:
    std::vector<Vec3> m_acceleration;
};

}  // namespace ganache

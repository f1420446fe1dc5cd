#pragma once
// Implicit viscosity from the SPH strain rate, after Takahashi et al. 2015 ("Implicit formulation for SPH-based
// viscous fluids", CGF 34(2)) [TDF*15], for comparison with [WKBB18] (effects.viscosity.method: takahashi2015).

#include "physics/viscosity/viscosity.h"

namespace ganache {

/// The viscous force as the divergence of the stress 2 mu D, with the strain rate D taken from SPH first:
///   D_i = sym(sum_j V_j (v_j - v_i) grad W_ij^T),  F_i = sum_j (V_i S_j + V_j S_i) grad W_ij,  S_i = 2 mu_i V_i D_i
/// (V = m / rho). The divergence is the symmetric SPH form of [WKBB18 Eq. 19] with the density weighting that
/// makes it the exact adjoint of the strain rate, so F = -dPhi/dv for the dissipation Phi = sum_i V_i mu_i |D_i|^2
/// and the implicit step (M + dt d^2Phi/dv^2) v = M v_df is symmetric positive definite: CG solves it without
/// storing the matrix (each product makes two passes over the neighbours, which reaches the second ring).
/// What it shows: the SPH strain rate of a rigid rotation is not zero where a particle lacks neighbours, so the
/// free surface feels forces that brake rigid motion [WKBB18 Sec. 6, Fig. 3, 5]. Linear momentum is kept exactly.
/// Boundaries couple through the same term as the main solver (Eq. 12), so comparisons differ only in the fluid.
/// Preconditioners: block Jacobi (the exact 3x3 diagonal blocks of the system) or none (the mass only).
class ViscosityTakahashi2015 final : public ViscosityMethod {
public:
    ViscosityTakahashi2015(const ViscosityParams& params, const SimulationSetup& setup, ParticleSet& particles)
        : ViscosityMethod(params, setup, particles) {}

    /// The SPH strain rate D_i of the velocity field `in`, for every particle.
    static void strainRate(const StepContext& ctx, const ParticleSet& particles, const std::vector<Vec3>& in,
                           std::vector<Mat3>& out);

protected:
    ViscosityPass solve(StepContext& ctx, const ParticleSet& particles, std::vector<Vec3>& out) override;

private:
    void multiply(const StepContext& ctx, const ParticleSet& particles, const std::vector<Vec3>& in,
                  std::vector<Vec3>& out);

    std::vector<Mat3> m_stress;  // S_i of the latest product
    std::vector<Vec3> m_b;
    std::vector<Mat3> m_inverseDiagonal, m_boundaryBlock;
    ConjugateGradient m_cg;
};

}  // namespace ganache

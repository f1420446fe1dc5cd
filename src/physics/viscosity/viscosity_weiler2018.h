#pragma once
// Implicit viscosity of Weiler, Koschier, Brand, Bender 2018: "A Physically Consistent Implicit Viscosity
// Solver for SPH Fluids", Computer Graphics Forum 37(2). [WKBB18]

#include "physics/pair_sweeps.h"
#include "physics/viscosity/coarse_space.h"
#include "physics/viscosity/viscosity.h"

namespace ganache {

/// The viscous Laplacian of Eq. 7 for every fluid particle (fluid neighbours only) [1/s]:
/// lap v_i = 2(d+2) sum_j (m_j / rho_j) (v_ij . x_ij) / (|x_ij|^2 + 0.01 h^2) grad W_ij, with the weights' scale for
/// 2(d+2) and their shape on each pair.
std::vector<Vec3> viscousLaplacian(const LaplacianWeights& weights, const ParticleSet& particles,
                                   const std::vector<Real>& density,
                                   const NeighbourList& neighbours, const CubicSpline& kernel);

/// Solves (I - dt A) v = b for the velocities after the divergence-free solve [WKBB18 Eq. 8-12] with
/// matrix-free preconditioned conjugate gradients. Per pair, mass and viscosity are averaged, so the system is
/// symmetric positive definite.
class ViscosityWeiler2018 final : public ViscosityMethod {
public:
    ViscosityWeiler2018(const ViscosityParams& params, const SimulationSetup& setup, ParticleSet& particles);

protected:
    ViscosityPass solve(StepContext& ctx, const ParticleSet& particles, std::vector<Vec3>& out) override;

private:
    /// out = (I - dt A) in, in's rows already in m_inputRows; returns in . out.
    Real multiplyRows(const StepContext& ctx, const ParticleSet& particles, const std::vector<Vec3>& in,
                      std::vector<Vec3>& out);
    /// The rigid motions the preconditioner solves for exactly, besides the block diagonal.
    enum class Coarse { None, WholeFluid, Clusters };
    /// CG's iterations from m_cg.start() on, preconditioned by the block diagonal and the rigid motions of `coarse`,
    /// in two vector passes an iteration, three with clusters (see the definition).
    ViscosityPass iterate(const StepContext& ctx, const ParticleSet& particles, Coarse coarse, std::vector<Vec3>& out,
                          Real tolerance, std::size_t maxIterations, ViscosityPass pass);
    sweeps::BoundaryBlocks boundaryBlocks() const {
        return {m_nearBoundary.data(), m_nearBlocks.data(), m_nearBlocks.size()};
    }

    std::vector<Real>* m_rigidFlag;  // attribute::kViscouslyRigid
    std::vector<Vec3> m_b;
    ConjugateGradient m_cg;
    std::vector<Mat3> m_inverseDiagonal;
    std::vector<Mat3> m_boundaryBlock;  // -dt times the boundary part of each diagonal block, with boundary_mu > 0
    std::vector<std::uint32_t> m_nearBoundary;  // the particles with a boundary part
    std::vector<Mat3> m_nearBlocks;             // their m_boundaryBlock, in that order (boundaryBlocks())
    std::vector<Vec3> m_start, m_guess;         // M v and M out before CG
    std::vector<Vec3> m_lastProduct, m_earlierProduct;  // M lastChange() and M earlierChange() for the warm start
    sweeps::Rows m_inputRows, m_inputRows2, m_inputRows3;  // the sweeps' rows of the products' inputs
    RigidModes m_rigid;
    ClusterModes m_clusters;
    std::vector<std::uint8_t> m_group;  // each particle's group of clusters (see solve())
};

}  // namespace ganache

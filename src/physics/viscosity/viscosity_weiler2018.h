#pragma once
// Implicit viscosity of Weiler, Koschier, Brand, Bender 2018: "A Physically Consistent Implicit Viscosity
// Solver for SPH Fluids", Computer Graphics Forum 37(2). [WKBB18]

#include "physics/viscosity/viscosity.h"

namespace ganache {

/// The viscous Laplacian of Eq. 7 for every fluid particle (fluid neighbours only) [1/s]:
/// lap v_i = 2(d+2) sum_j (m_j / rho_j) (v_ij . x_ij) / (|x_ij|^2 + 0.01 h^2) grad W_ij.
std::vector<Vec3> viscousLaplacian(const ParticleSet& particles, const std::vector<Real>& density,
                                   const NeighbourList& neighbours, const CubicSpline& kernel);

using Vec6 = Eigen::Matrix<Real, 6, 1>;
using Mat6 = Eigen::Matrix<Real, 6, 6>;

/// The rigid motions of all fluid particles together (three translations, three rotations about their centroid)
/// as a coarse space for the viscosity solve. The viscous coupling between fluid particles leaves rigid motion
/// alone, so within this space the system is the identity plus the (block-diagonal) boundary part.
class RigidModes {
public:
    /// extra: the boundary part of each particle's diagonal block of the system, or null when there is none;
    /// withExtra: the particles whose part is not zero.
    void build(const std::vector<Vec3>& x, const std::vector<Mat3>* extra, const std::vector<std::uint32_t>& withExtra,
               Real minScale);
    /// Z^T r: the total of r and its moment about the centroid.
    Vec6 project(const std::vector<Vec3>& x, const std::vector<Vec3>& r) const;
    /// (Z^T M Z)^+ y: the rigid motion whose image under the system has the projection y.
    Vec6 solve(const Vec6& y) const { return m_inverse * y; }
    /// The velocity of the rigid motion y at position xi.
    Vec3 velocity(const Vec6& y, const Vec3& xi) const { return y.head<3>() + y.tail<3>().cross(arm(xi)); }

private:
    Vec3 arm(const Vec3& xi) const { return (xi - m_centre) / m_scale; }  // scaled to keep Z^T M Z balanced

    Vec3 m_centre = Vec3::Zero();
    Real m_scale = 1;
    Mat6 m_inverse = Mat6::Zero();
};

/// Solves (I - dt A) v = b for the velocities after the divergence-free solve [WKBB18 Eq. 8-12] with
/// matrix-free preconditioned conjugate gradients. Per pair, mass and viscosity are averaged, so the system is
/// symmetric positive definite.
class ViscosityWeiler2018 final : public ViscosityMethod {
public:
    ViscosityWeiler2018(const ViscosityParams& params, const SimulationSetup& setup, ParticleSet& particles)
        : ViscosityMethod(params, setup, particles) {}

protected:
    ViscosityPass solve(StepContext& ctx, const ParticleSet& particles, std::vector<Vec3>& out) override;

private:
    void multiply(const StepContext& ctx, const ParticleSet& particles, const std::vector<Vec3>& in,
                  std::vector<Vec3>& out) const;

    std::vector<Vec3> m_b;
    ConjugateGradient m_cg;
    std::vector<Mat3> m_inverseDiagonal;
    std::vector<Mat3> m_boundaryBlock;  // -dt times the boundary part of each diagonal block, with boundary_mu > 0
    std::vector<std::uint32_t> m_nearBoundary;  // the particles with a boundary part
    std::vector<Vec3> m_start, m_guess;         // M v and M out before CG
    RigidModes m_rigid;
};

}  // namespace ganache

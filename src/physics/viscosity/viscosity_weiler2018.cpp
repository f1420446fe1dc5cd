#include "physics/viscosity/viscosity_weiler2018.h"

#include "core/parallel.h"
#include "physics/pair_sweeps.h"

namespace ganache {

namespace {

constexpr Real kTwoDPlus4 = 10;  // 2 (d + 2) with d = 3
// The side of a cluster of the coarse space in kernel supports, about 6^3 = 216 particles (support 4 r, spacing
// 2 r). Measured on a 43k-particle chocolate bunny (5e6 Pa s): 2 supports cut CG to 21 iterations a solve but
// factoring the coarse system cost more than it saved; 3: 28 iterations and half the viscosity time of the
// fluid-wide rigid modes (94 iterations); 4: 34.
constexpr Real kClusterSize = 3;
// At most this many clusters (24,576 unknowns): above it the sparse factorisation would outgrow the CG iterations.
constexpr std::size_t kMaxClusters = 4096;

}  // namespace

std::vector<Vec3> viscousLaplacian(const ParticleSet& particles, const std::vector<Real>& density,
                                   const NeighbourList& neighbours, const CubicSpline& kernel) {
    const auto& x = particles.x();
    const auto& v = particles.v();
    const auto& m = particles.mass();
    const Real eps = 0.01 * kernel.supportRadius() * kernel.supportRadius();
    std::vector<Vec3> lap(particles.size(), Vec3::Zero());
    forEachParticle(particles.size(), [&](std::size_t i) {
        for (std::uint32_t j : neighbours.of(i)) {
            const Vec3 xij = x[i] - x[j];
            lap[i] += (m[j] / density[j]) * (v[i] - v[j]).dot(xij) / (xij.squaredNorm() + eps) * kernel.gradW(xij);
        }
        lap[i] *= kTwoDPlus4;
    });
    return lap;
}

void ViscosityWeiler2018::multiply(const StepContext& ctx, const ParticleSet& particles, const std::vector<Vec3>& in,
                                   std::vector<Vec3>& out) const {
    // (I - dt A) in, with the bodies' velocities on the right-hand side
    forEachBlock(particles.size(), [&](std::size_t begin, std::size_t end) {
        sweeps::viscousProduct(begin, end, {&ctx.fluidNeighbours, pairs().data()},
                               {&ctx.boundaryNeighbours, sticky() ? boundaryPairs().data() : nullptr},
                               particles.x().data(), ctx.boundary.x.data(), in.data(), ctx.dt, out.data());
    });
}

ViscosityPass ViscosityWeiler2018::solve(StepContext& ctx, const ParticleSet& particles, std::vector<Vec3>& out) {
    const std::size_t n = particles.size();
    const auto& x = particles.x();
    const auto& v = particles.v();
    const Real dt = ctx.dt;
    m_b.resize(n);
    m_inverseDiagonal.resize(n);

    // Right-hand side [Eq. 12] and block-diagonal preconditioner [Eq. 11].
    if (sticky()) m_boundaryBlock.resize(n);
    forEachParticle(n, [&](std::size_t i) {
        Mat3 aii = fluidBlock(i);
        Vec3 bodies = Vec3::Zero();
        if (sticky()) {
            const Mat3 aik = boundaryBlock(ctx, particles, i, bodies);
            m_boundaryBlock[i] = -dt * aik;
            aii += aik;
        }
        m_b[i] = v[i] - dt * bodies;
        m_inverseDiagonal[i] = m_params.preconditioner == ViscosityParams::Preconditioner::None
                                   ? Mat3(Mat3::Identity())
                                   : Mat3(Mat3(Mat3::Identity() - dt * aii).inverse());
    });
    m_nearBoundary.clear();
    if (sticky())
        for (std::size_t i = 0; i < n; ++i)
            if (ctx.boundaryNeighbours.first(i) != ctx.boundaryNeighbours.last(i)) m_nearBoundary.push_back(std::uint32_t(i));
    m_rigid.build(x, sticky() ? &m_boundaryBlock : nullptr, m_nearBoundary, ctx.kernel.supportRadius());
    using P = ViscosityParams::Preconditioner;
    if (m_params.preconditioner == P::Clusters)
        m_clusters.build(x, kClusterSize * ctx.kernel.supportRadius(), kMaxClusters, ctx.fluidNeighbours, pairs(), dt,
                         sticky() ? &m_boundaryBlock : nullptr, m_nearBoundary);
    // z = P r: the block diagonal, plus (two-level) the exact answer within the rigid motions of the fluid or of
    // its clusters, which the block diagonal of a stiff fluid barely moves (their eigenvalue is 1 against up to
    // dt mu / (rho h^2) for the rest).
    auto precondition = [&](const std::vector<Vec3>& r, std::vector<Vec3>& z) {
        const bool rigid = m_params.preconditioner == P::Rigid;
        const Vec6 coarse = rigid ? Vec6(m_rigid.solve(m_rigid.project(x, r))) : Vec6::Zero();
        forEachParticle(n, [&](std::size_t i) {
            z[i] = m_inverseDiagonal[i] * r[i];
            if (rigid) z[i] += m_rigid.velocity(coarse, x[i]);
        });
        if (m_params.preconditioner == P::Clusters) m_clusters.addCorrection(x, r, z);
    };

    const auto system = [&](const std::vector<Vec3>& in, std::vector<Vec3>& result) {
        multiply(ctx, particles, in, result);
    };
    // The correction the solve has to make, b - M v, and the warm start's residual b - M out, from one sweep.
    m_start.resize(n);
    m_guess.resize(n);
    forEachBlock(n, [&](std::size_t begin, std::size_t end) {
        sweeps::viscousProducts(begin, end, {&ctx.fluidNeighbours, pairs().data()},
                                {&ctx.boundaryNeighbours, sticky() ? boundaryPairs().data() : nullptr}, x.data(),
                                ctx.boundary.x.data(), v.data(), out.data(), dt, m_start.data(), m_guess.data());
    });
    ViscosityPass pass = m_cg.solve(system, precondition, m_b, v, m_start, m_guess, out, m_params.tolerance,
                                    std::size_t(m_params.maxIterations));
    if (m_cg.scale == 0) return pass;  // v_df already solves the system
    // Whatever CG left, the rigid part of the residual is solved exactly: the fluid's viscous forces then
    // change its total momentum and angular momentum only through the boundary, as viscosity must. Left to
    // CG, a stiff bunny on a slipping floor (5e6 Pa s) gained angular momentum about the vertical from each
    // capped solve and spun itself apart within half a second. M Z is local, so the residual stays exact.
    std::vector<Vec3>& r = m_cg.r;
    const Vec6 rigid = m_rigid.solve(m_rigid.project(x, r));
    forEachParticle(n, [&](std::size_t i) {
        const Vec3 u = m_rigid.velocity(rigid, x[i]);
        out[i] += u;
        r[i] -= sticky() ? Vec3(u + m_boundaryBlock[i] * u) : u;
    });
    pass.residual = std::sqrt(fieldDot(r, r)) / m_cg.scale;
    return pass;
}

}  // namespace ganache

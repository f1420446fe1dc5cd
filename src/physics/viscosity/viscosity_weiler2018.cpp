#include "physics/viscosity/viscosity_weiler2018.h"

#include "core/attributes.h"
#include "core/parallel.h"

#include <algorithm>
#include <cmath>

namespace ganache {

namespace {

// The coarse space's clusters: cells of two kernel supports (about 4^3 = 64 particles at support 4 r, spacing 2 r),
// larger where that would make more than 6 n^0.4 clusters. Factoring the coarse system grows faster than the fine
// products (measured with a scalar sparse Cholesky: 2 ms for 120 clusters, 200 ms for 750; the block LDL^T that
// replaced it took the default scene's viscosity a quarter to a third lower), so the cap keeps it to a few CG
// iterations' worth: 43k particles of chocolate, 360 clusters, 29 CG iterations a solve (cells of two supports: 23.5
// iterations but 200 ms a factorisation; the fluid-wide rigid modes: 94). Cells of three supports left some melting
// steps of the default scene at the 100-iteration cap; two left none.
constexpr Real kClusterSize = 2;
std::size_t maxClusters(std::size_t particles) {
    return std::size_t(std::clamp(6 * std::pow(Real(particles), 0.4), 64.0, 4096.0));
}
// The stiffness (dt A against the identity, about dt mu / (rho h^2)) from which a particle joins a cluster; below it
// the fluid-wide rigid motions serve. Clusters pay where the solve struggles: the default scene's chocolate (stiffness
// 30 molten to 7e6 solid) stopped at the 100-iteration cap 222 times without them (tolerance 1e-4). Below a few
// thousand they cost more than they save: on the 50k block of the anchors (1,000 Pa s, stiffness 560-630, tolerance
// 1e-3) they cut CG from 25 to 17 iterations a solve but took the viscosity from 196 to 315 ms a step (1 thread); the
// default scene, with 300 / 1,000 / 3,000 here, takes 6.9 / 7.3 / 8.6 iterations a solve, 7.8 / 7.1 / 6.5 ms a step
// (2 threads), never at the cap. Measured with the paper's weights; the lattice weights' diagonal is 0.84 of theirs, so
// the same fluid reads 0.84 as stiff (the 56k bunny of Table 2 at 0.5 ms fell below the threshold). The threshold stays
// in units of dt A: the conditioning is what it was chosen on.
constexpr Real kStiff = 3000;

}  // namespace

std::vector<Vec3> viscousLaplacian(const LaplacianWeights& weights, const ParticleSet& particles,
                                   const std::vector<Real>& density,
                                   const NeighbourList& neighbours, const CubicSpline& kernel) {
    const auto& x = particles.x();
    const auto& v = particles.v();
    const auto& m = particles.mass();
    const Real eps = 0.01 * kernel.supportRadius() * kernel.supportRadius();
    std::vector<Vec3> lap(particles.size(), Vec3::Zero());
    forEachParticle(particles.size(), [&](std::size_t i) {
        for (std::uint32_t j : neighbours.of(i)) {
            const Vec3 xij = x[i] - x[j];
            const Real d2 = xij.squaredNorm();
            lap[i] += (m[j] / density[j]) * weights.shape(d2) * (v[i] - v[j]).dot(xij) / (d2 + eps) * kernel.gradW(xij);
        }
        lap[i] *= weights.scale();
    });
    return lap;
}

ViscosityWeiler2018::ViscosityWeiler2018(const ViscosityParams& params, const SimulationSetup& setup,
                                         ParticleSet& particles)
    : ViscosityMethod(params, setup, particles), m_rigidFlag(&particles.add(attribute::kViscouslyRigid)) {}

Real ViscosityWeiler2018::multiplyRows(const StepContext& ctx, const ParticleSet& particles,
                                       const std::vector<Vec3>& in, std::vector<Vec3>& out) {
    return deterministicBlockSum(particles.size(), [&](std::size_t begin, std::size_t end) {
        sweeps::viscousProduct(begin, end, {&ctx.fluidNeighbours, pairs().data()}, boundaryBlocks(),
                               ctx.positionRows.data(), m_inputRows.data(), ctx.dt, out.data());
        Real s = 0;
        for (std::size_t i = begin; i < end; ++i) s += in[i].dot(out[i]);
        return s;
    });
}

ViscosityPass ViscosityWeiler2018::solve(StepContext& ctx, const ParticleSet& particles, std::vector<Vec3>& out) {
    const std::size_t n = particles.size();
    const auto& x = particles.x();
    const auto& v = particles.v();
    const Real dt = ctx.dt;
    m_b.resize(n);
    m_inverseDiagonal.resize(n);

    // Right-hand side [Eq. 12], block-diagonal preconditioner [Eq. 11] and which particles are stiff (dt A against the
    // identity, about dt mu / (rho h^2), from kStiff: they join clusters and tighten the tolerance), in one pass.
    if (sticky()) m_boundaryBlock.resize(n);
    auto& rigidFlag = *m_rigidFlag;
    const bool stiff = deterministicSum<std::size_t>(n, [&](std::size_t i) {
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
        rigidFlag[i] = -dt * fluidBlock(i).trace() / 3 >= kStiff;
        return std::size_t(rigidFlag[i]);
    }) > 0;
    m_nearBoundary.clear();
    m_nearBlocks.clear();
    if (sticky())
        for (std::size_t i = 0; i < n; ++i)
            if (ctx.boundaryNeighbours.first(i) != ctx.boundaryNeighbours.last(i)) {
                m_nearBoundary.push_back(std::uint32_t(i));
                m_nearBlocks.push_back(m_boundaryBlock[i]);
            }
    m_rigid.build(x, boundaryBlocks(), ctx.kernel.supportRadius());
    using P = ViscosityParams::Preconditioner;
    // Where viscosities differ (melting, several fluids), the correction the solve has to make is far larger at a few
    // particles than at the rest, and a residual small against the whole correction still leaves the runny particles'
    // velocities wrong: at 1e-2, particles of the default scene's molten film left it at up to 0.7 m/s once no particle
    // was stiff any more, the time step shrank to follow them, and the run took 1,042 steps instead of 875 (154 s
    // instead of 114 at final quality). So those solves, too, aim at the stiff tolerance.
    const bool tight = stiff || m_mu.varies();
    const Real tolerance = tight ? std::min(m_params.tolerance, m_params.stiffTolerance) : m_params.tolerance;
    bool clusters = false;
    if (m_params.preconditioner == P::Clusters && stiff) {
        // Only stiff particles join clusters. Where viscosities differ (melting), a cluster holds one decade of them:
        // a rigid motion of solid and molten particles together is no slow mode of the system, and such clusters
        // left CG at its cap.
        m_group.resize(n);
        forEachParticle(n, [&](std::size_t i) {
            m_group[i] = rigidFlag[i] == 0 ? ClusterModes::kNoCluster
                         : m_mu.varies()
                             ? std::uint8_t(std::min(std::floor(std::log10(std::max(m_mu(i), Real(1)))), 254.0))
                             : std::uint8_t(0);
        });
        m_clusters.build(x, &m_group, kClusterSize * ctx.kernel.supportRadius(), maxClusters(n), ctx.fluidNeighbours,
                         pairs(), dt, boundaryBlocks());
        clusters = m_clusters.clusters() > 0;
    }
    // The preconditioner: the block diagonal, plus (two-level) the exact answer within the rigid motions of its
    // clusters or, without clusters, of the whole fluid, which the block diagonal of a stiff fluid barely moves
    // (their eigenvalue is 1 against up to dt mu / (rho h^2) for the rest).
    const Coarse coarse = clusters ? Coarse::Clusters
                          : m_params.preconditioner == P::Rigid || m_params.preconditioner == P::Clusters
                              ? Coarse::WholeFluid
                              : Coarse::None;
    // The correction the solve has to make, b - M v, and the warm start's residual b - M out, from one sweep. A loose
    // solve's warm start is, of the guesses v + a dv_last + c dv_earlier, the one nearest the solution in M's norm,
    // from the products of v and of both changes in that sweep (otherwise of v and apply()'s guess). The
    // fixed extrapolation that apply() guessed lags where the viscous change keeps growing, and a loose solve keeps
    // part of its start: at 1e-2 the buckling anchor's sheet stood 9.8 % too high at 1 s, 1.1 % with this guess, in
    // fewer CG iterations. Solves to the stiff tolerance keep little of their start, and there the fixed extrapolation
    // took fewer iterations (the impacts of Table 2's rows: 18-27 CG iterations a solve against 22-30 with this guess).
    const std::vector<Vec3>* last = tight ? nullptr : lastChange();
    const std::vector<Vec3>* earlier = earlierChange();
    m_start.resize(n);
    m_guess.resize(n);
    for (auto* rows : {&m_inputRows, &m_inputRows2}) rows->resize(n);
    if (last) m_inputRows3.resize(n), m_lastProduct.resize(n), m_earlierProduct.resize(n);
    forEachBlock(n, [&](std::size_t begin, std::size_t end) {
        sweeps::toRows(begin, end, v.data(), m_inputRows.data());
        sweeps::toRows(begin, end, last ? last->data() : out.data(), m_inputRows2.data());
        if (last) sweeps::toRows(begin, end, earlier->data(), m_inputRows3.data());
    });
    const sweeps::Pairs fluidPairs{&ctx.fluidNeighbours, pairs().data()};
    const sweeps::BoundaryBlocks boundary = boundaryBlocks();
    // The products, and with the two changes what the least-energy guess decides on, from the same pass.
    const GuessSums sums = deterministicBlockSum<GuessSums>(n, [&](std::size_t begin, std::size_t end) {
        GuessSums s = GuessSums::Zero();
        if (!last) {
            sweeps::viscousProducts(begin, end, fluidPairs, boundary, ctx.positionRows.data(), m_inputRows.data(),
                                    m_inputRows2.data(), dt, m_start.data(), m_guess.data());
            return s;
        }
        sweeps::viscousProducts(begin, end, fluidPairs, boundary, ctx.positionRows.data(), m_inputRows.data(),
                                m_inputRows2.data(), m_inputRows3.data(), dt, m_start.data(), m_lastProduct.data(),
                                m_earlierProduct.data());
        for (std::size_t i = begin; i < end; ++i)
            s += guessTerms(m_b[i], m_start[i], (*last)[i], m_lastProduct[i], (*earlier)[i], m_earlierProduct[i]);
        return s;
    }, GuessSums::Zero());
    if (last) leastEnergyGuess(sums, v, m_start, *last, m_lastProduct, *earlier, m_earlierProduct, out, m_guess);
    const std::size_t maxIterations = std::size_t(m_params.maxIterations);
    ViscosityPass pass;
    if (m_cg.start(m_b, v, m_start, m_guess, out, tolerance, maxIterations, pass))
        pass = iterate(ctx, particles, coarse, out, tolerance, maxIterations, pass);
    if (m_cg.scale == 0) return pass;  // v_df already solves the system
    // Whatever CG left, the rigid part of the residual is solved exactly: the fluid's viscous forces then
    // change its total momentum and angular momentum only through the boundary, as viscosity must. Left to
    // CG, a stiff bunny on a slipping floor (5e6 Pa s) gained angular momentum about the vertical from each
    // capped solve and spun itself apart within half a second. M Z is local, so the residual stays exact.
    std::vector<Vec3>& r = m_cg.r;
    const Vec6 rigid = m_rigid.solve(m_rigid.project(x, r));
    pass.residual = std::sqrt(deterministicSum(n, [&](std::size_t i) {
        const Vec3 u = m_rigid.velocity(rigid, x[i]);
        out[i] += u;
        r[i] -= sticky() ? Vec3(u + m_boundaryBlock[i] * u) : u;
        return r[i].squaredNorm();
    })) / m_cg.scale;
    return pass;
}

ViscosityPass ViscosityWeiler2018::iterate(const StepContext& ctx, const ParticleSet& particles, Coarse coarse,
                                           std::vector<Vec3>& out, Real tolerance, std::size_t maxIterations,
                                           ViscosityPass pass) {
    // z = D^-1 r + Z c with c = (Z^T M Z)^-1 Z^T r, so r . z = r . D^-1 r + (Z^T r) . c: the pass that updates r also
    // takes r . D^-1 r (and, for the whole fluid's motions, Z^T r; the clusters gather theirs over their members), and
    // z is needed only in the pass that makes the next direction p, which also writes p's rows for the next product.
    // Two vector passes an iteration (three with the clusters' gather) where the generic CG takes five or more (the
    // copy to rows, the update, z, the clusters' share of z, r . z and p): each costs a few microseconds on 2 threads
    // even at buckling's 2,618 particles, and at a million each streams the particles' vectors once more.
    const std::size_t n = particles.size();
    const auto& x = particles.x();
    auto& r = m_cg.r;
    auto& p = m_cg.p;
    auto& q = m_cg.q;
    const bool rigid = coarse == Coarse::WholeFluid;
    // |r|^2, r . D^-1 r and Z^T r over a block, after moving it by alpha along p and q (none at first), kept in
    // registers as RigidModes::project keeps its sums.
    using Vec8 = Eigen::Matrix<Real, 8, 1>;
    auto update = [&](Real alpha, bool move) {
        return deterministicBlockSum<Vec8>(n, [&](std::size_t begin, std::size_t end) {
            Real rr = 0, rDr = 0;
            Vec3 total = Vec3::Zero(), moment = Vec3::Zero();
            for (std::size_t i = begin; i < end; ++i) {
                if (move) {
                    out[i] += alpha * p[i];
                    r[i] -= alpha * q[i];
                }
                const Vec3 ri = r[i];
                rr += ri.squaredNorm();
                rDr += ri.dot(m_inverseDiagonal[i] * ri);
                if (rigid) total += ri, moment += m_rigid.moment(x[i], ri);
            }
            Vec8 s;
            s << rr, rDr, total, moment;
            return s;
        }, Vec8::Zero());
    };
    Vec6 motion = Vec6::Zero();  // the whole fluid's
    auto rz = [&](const Vec8& sums) {
        if (coarse == Coarse::Clusters) return sums[1] + m_clusters.solveFor(x, r);
        if (rigid) motion = m_rigid.solve(sums.tail<6>());
        return sums[1] + sums.tail<6>().dot(motion);
    };
    // p = z + beta p (p = z at first), and its rows.
    m_inputRows.resize(n);
    auto direction = [&](bool first, Real beta) {
        forEachBlock(n, [&](std::size_t begin, std::size_t end) {
            for (std::size_t i = begin; i < end; ++i) {
                Vec3 z = m_inverseDiagonal[i] * r[i];
                if (rigid) z += m_rigid.velocity(motion, x[i]);
                if (coarse == Coarse::Clusters) z += m_clusters.velocity(i, x[i]);
                p[i] = first ? z : Vec3(z + beta * p[i]);
            }
            sweeps::toRows(begin, end, p.data(), m_inputRows.data());
        });
    };
    Real rzLast = rz(update(0, false));
    direction(true, 0);
    for (;;) {
        const Real alpha = rzLast / multiplyRows(ctx, particles, p, q);
        const Vec8 sums = update(alpha, true);
        pass.residual = std::sqrt(sums[0]) / m_cg.scale;
        if (++pass.iterations >= maxIterations || pass.residual <= tolerance) return pass;
        const Real rzNext = rz(sums);
        direction(false, rzNext / rzLast);
        rzLast = rzNext;
    }
}

}  // namespace ganache

#include "viscosity_weiler2018.h"

#include "parallel.h"
#include "scene.h"

#include <Eigen/Eigenvalues>
#include <fmt/format.h>
#include <set>

namespace ganache {

namespace {

constexpr Real kTwoDPlus4 = 10;  // 2 (d + 2) with d = 3

// Dot product of two vector fields; deterministic, so every run takes the same CG iterations.
Real dot(const std::vector<Vec3>& a, const std::vector<Vec3>& b) {
    return deterministicSum(a.size(), [&](std::size_t i) { return a[i].dot(b[i]); });
}

Mat3 cross(const Vec3& a) {
    Mat3 m;
    m << 0, -a.z(), a.y(), a.z(), 0, -a.x(), -a.y(), a.x(), 0;
    return m;
}

}  // namespace

void RigidModes::build(const std::vector<Vec3>& x, const std::vector<Mat3>* extra, Real minScale) {
    const std::size_t n = x.size();
    m_centre = deterministicSum<Vec3>(n, [&](std::size_t i) { return x[i]; }, Vec3::Zero()) / Real(n);
    const Real spread = deterministicSum(n, [&](std::size_t i) { return (x[i] - m_centre).squaredNorm(); });
    m_scale = std::max(std::sqrt(spread / Real(n)), minScale);
    // E = Z^T M Z = sum_i Z_i^T (I + extra_i) Z_i: the fluid's own coupling has the rigid motions in its null
    // space, so only the block-diagonal boundary part (when there is one) adds to the identity.
    const Mat6 e = deterministicSum<Mat6>(n, [&](std::size_t i) -> Mat6 {
        Eigen::Matrix<Real, 3, 6> z;
        z << Mat3::Identity(), -cross(arm(x[i]));
        return extra ? Mat6(z.transpose() * (Mat3::Identity() + (*extra)[i]) * z) : Mat6(z.transpose() * z);
    }, Mat6::Zero());
    // Pseudo-inverse: a lone particle has no rotations, particles on a line none about that line.
    const Eigen::SelfAdjointEigenSolver<Mat6> eigen(e);
    const Vec6 values = eigen.eigenvalues();
    Vec6 inverted = Vec6::Zero();
    for (int k = 0; k < 6; ++k)
        if (values[k] > 1e-10 * values.maxCoeff()) inverted[k] = 1 / values[k];
    m_inverse = eigen.eigenvectors() * inverted.asDiagonal() * eigen.eigenvectors().transpose();
}

Vec6 RigidModes::project(const std::vector<Vec3>& x, const std::vector<Vec3>& r) const {
    return deterministicSum<Vec6>(x.size(), [&](std::size_t i) -> Vec6 {
        Vec6 out;
        out << r[i], arm(x[i]).cross(r[i]);
        return out;
    }, Vec6::Zero());
}

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

ViscosityWeiler2018::ViscosityWeiler2018(const ViscosityParams& params, const Scene& scene, ParticleSet& particles)
    : m_params(params), m_dv(&particles.addVector("_viscosity_dv", Vec3::Zero(), false)) {
    if (params.mu) {
        m_mu = *params.mu;
        return;
    }
    const std::vector<Material> sources = scene.sourceMaterials();
    std::set<Real> distinct;
    bool laws = false;
    for (const auto& m : sources) {
        distinct.insert(m.mu);
        laws |= m.law.has_value();
    }
    // Laws of viscosity over temperature apply where particles have a temperature, i.e. with the heat effect.
    laws = laws && scene.findEffect("heat");
    m_mu = sources.front().mu;
    if (distinct.size() == 1 && !laws) return;
    // Viscosity varies: each particle carries its own, from its source's material (and temperature).
    if (sources.size() > 1 && !particles.findScalar("fluid"))
        throw std::runtime_error("viscosity: the particles do not say which fluid they belong to; sample the scene "
                                 "again with this version of ganache");
    for (const auto& m : sources) {
        m_sourceMu.push_back(m.mu);
        m_sourceLaw.push_back(laws ? m.law : std::nullopt);
    }
    m_muPerParticle = &particles.addScalar("viscosity");
    refreshViscosity(particles);
}

void ViscosityWeiler2018::refreshViscosity(const ParticleSet& particles) {
    const std::vector<Real>* source = particles.findScalar("fluid");
    const std::vector<Real>* temperature = particles.findScalar("temperature");
    auto& mu = *m_muPerParticle;
    forEachParticle(particles.size(), [&](std::size_t i) {
        const std::size_t s = sourceIndex(source, i);
        const auto& law = m_sourceLaw[s];
        mu[i] = law && temperature ? law->at((*temperature)[i]) : m_sourceMu[s];
    }, 4096);
}

Real ViscosityWeiler2018::pairCoefficient(const StepContext& ctx, const ParticleSet& p, std::size_t i, std::size_t j,
                                          const Vec3& xij) const {
    // 2(d+2) mu_ij m_ij / (rho_i rho_j (|x_ij|^2 + 0.01 h^2)), averaged mu and m keep A symmetric [Eq. 9]
    const Real h = ctx.kernel.supportRadius();
    return kTwoDPlus4 * 0.5 * (mu(i) + mu(j)) * 0.5 * (p.mass()[i] + p.mass()[j]) /
           (ctx.density[i] * ctx.density[j]) / (xij.squaredNorm() + 0.01 * h * h);
}

Real ViscosityWeiler2018::boundaryCoefficient(const StepContext& ctx, std::size_t i, std::size_t k,
                                              const Vec3& xik) const {
    // 2(d+2) mu_b Psi_k / (rho_i^2 (|x_ik|^2 + 0.01 h^2)) [Eq. 11-12]
    const Real h = ctx.kernel.supportRadius();
    return kTwoDPlus4 * m_params.boundaryMu * ctx.restDensity[i] * ctx.boundary.volume[k] /
           (ctx.density[i] * ctx.density[i]) / (xik.squaredNorm() + 0.01 * h * h);
}

void ViscosityWeiler2018::multiply(const StepContext& ctx, const ParticleSet& particles, const std::vector<Vec3>& in,
                                   std::vector<Vec3>& out) const {
    const auto& x = particles.x();
    const Real dt = ctx.dt;
    const bool sticky = m_params.boundaryMu > 0;
    forEachParticle(particles.size(), [&](std::size_t i) {
        // (A v)_i = sum_j c_ij (x_ij . (v_i - v_j)) grad W_ij + sum_k c_ik (x_ik . v_i) grad W_ik
        Vec3 av = Vec3::Zero();
        for (std::uint32_t j : ctx.fluidNeighbours.of(i)) {
            const Vec3 xij = x[i] - x[j];
            av += pairCoefficient(ctx, particles, i, j, xij) * xij.dot(in[i] - in[j]) * ctx.kernel.gradW(xij);
        }
        if (sticky)
            for (std::uint32_t k : ctx.boundaryNeighbours.of(i)) {
                const Vec3 xik = x[i] - ctx.boundary.x[k];
                av += boundaryCoefficient(ctx, i, k, xik) * xik.dot(in[i]) * ctx.kernel.gradW(xik);
            }
        out[i] = in[i] - dt * av;
    });
}

void ViscosityWeiler2018::apply(StepContext& ctx, ParticleSet& particles) {
    const std::size_t n = particles.size();
    if (n == 0) return;
    const auto& x = particles.x();
    auto& v = particles.v();
    auto& dv = *m_dv;
    const Real dt = ctx.dt;
    const bool sticky = m_params.boundaryMu > 0;
    for (auto* a : {&m_b, &m_x, &m_r, &m_z, &m_p, &m_q}) a->resize(n);
    // Temperatures change every step, and emitters may have added particles since the last solve.
    if (m_muPerParticle) refreshViscosity(particles);
    // With coupled passes the solve runs several times a step, each on the velocity the latest pressure solve
    // left. A later pass first takes back the previous pass's change dv (a pass replaces it, it does not add a
    // second dt of viscosity) and starts from v + dv, which is the current velocity. The first pass of a step
    // starts from v + dv with dv the previous step's change: the paper's warm start.
    const bool firstPass = !m_hasSolved || ctx.step != m_lastStep;
    m_hasSolved = true;
    m_lastStep = ctx.step;
    if (!firstPass) forEachParticle(n, [&](std::size_t i) { v[i] -= dv[i]; });
    const bool guessWithChange = m_params.warmStart || !firstPass;
    m_inverseDiagonal.resize(n);

    // Right-hand side [Eq. 12], block-diagonal preconditioner [Eq. 11] and initial guess v_df + dv.
    if (sticky) m_boundaryBlock.resize(n);
    forEachParticle(n, [&](std::size_t i) {
        Mat3 aii = Mat3::Zero();
        for (std::uint32_t j : ctx.fluidNeighbours.of(i)) {
            const Vec3 xij = x[i] - x[j];
            aii += pairCoefficient(ctx, particles, i, j, xij) * ctx.kernel.gradW(xij) * xij.transpose();
        }
        Vec3 b = v[i];
        if (sticky) {
            Mat3 aik = Mat3::Zero();
            for (std::uint32_t k : ctx.boundaryNeighbours.of(i)) {
                const Vec3 xik = x[i] - ctx.boundary.x[k];
                const Real c = boundaryCoefficient(ctx, i, k, xik);
                const Vec3 g = ctx.kernel.gradW(xik);
                aik += c * g * xik.transpose();
                b -= dt * c * ctx.boundary.v[k].dot(xik) * g;
            }
            m_boundaryBlock[i] = -dt * aik;
            aii += aik;
        }
        m_b[i] = b;
        m_inverseDiagonal[i] = m_params.preconditioner == ViscosityParams::Preconditioner::None
                                   ? Mat3(Mat3::Identity())
                                   : Mat3(Mat3(Mat3::Identity() - dt * aii).inverse());
        m_x[i] = guessWithChange ? Vec3(v[i] + dv[i]) : v[i];
    });
    m_rigid.build(x, sticky ? &m_boundaryBlock : nullptr, ctx.kernel.supportRadius());
    const bool twoLevel = m_params.preconditioner == ViscosityParams::Preconditioner::Rigid;
    // z = P r: the block diagonal, plus (two-level) the exact answer within the rigid motions, which the block
    // diagonal of a stiff fluid barely moves (their eigenvalue is 1 against up to dt mu / (rho h^2) for the rest).
    auto precondition = [&] {
        const Vec6 coarse = twoLevel ? Vec6(m_rigid.solve(m_rigid.project(x, m_r))) : Vec6::Zero();
        forEachParticle(n, [&](std::size_t i) {
            m_z[i] = m_inverseDiagonal[i] * m_r[i];
            if (twoLevel) m_z[i] += m_rigid.velocity(coarse, x[i]);
        });
    };

    // The tolerance is relative to the correction viscosity has to make, |b - (I - dt A) v_df|, not to |b|:
    // at small dt that correction is a tiny fraction of the velocity, and a residual relative to |b| let a
    // warm-started guess pass untouched step after step (0.1 CG iterations per solve at dt = 0.05 ms).
    multiply(ctx, particles, v, m_q);
    forEachParticle(n, [&](std::size_t i) { m_r[i] = m_b[i] - m_q[i]; });
    const Real bNorm = std::sqrt(dot(m_r, m_r));
    std::size_t iteration = 0;
    Real residual = 0;
    if (bNorm > 0) {
        multiply(ctx, particles, m_x, m_q);
        forEachParticle(n, [&](std::size_t i) { m_r[i] = m_b[i] - m_q[i]; });
        precondition();
        std::copy(m_z.begin(), m_z.end(), m_p.begin());
        Real rz = dot(m_r, m_z);
        residual = std::sqrt(dot(m_r, m_r)) / bNorm;
        while (residual > m_params.tolerance && iteration < std::size_t(m_params.maxIterations)) {
            multiply(ctx, particles, m_p, m_q);
            const Real alpha = rz / dot(m_p, m_q);
            forEachParticle(n, [&](std::size_t i) {
                m_x[i] += alpha * m_p[i];
                m_r[i] -= alpha * m_q[i];
            });
            precondition();
            const Real rzNext = dot(m_r, m_z);
            const Real beta = rzNext / rz;
            rz = rzNext;
            forEachParticle(n, [&](std::size_t i) { m_p[i] = m_z[i] + beta * m_p[i]; });
            residual = std::sqrt(dot(m_r, m_r)) / bNorm;
            ++iteration;
        }
        // Whatever CG left, the rigid part of the residual is solved exactly: the fluid's viscous forces then
        // change its total momentum and angular momentum only through the boundary, as viscosity must. Left to
        // CG, a stiff bunny on a slipping floor (5e6 Pa s) gained angular momentum about the vertical from each
        // capped solve and spun itself apart within half a second. M Z is local, so the residual stays exact.
        const Vec6 rigid = m_rigid.solve(m_rigid.project(x, m_r));
        forEachParticle(n, [&](std::size_t i) {
            const Vec3 u = m_rigid.velocity(rigid, x[i]);
            m_x[i] += u;
            m_r[i] -= sticky ? Vec3(u + m_boundaryBlock[i] * u) : u;
        });
        residual = std::sqrt(dot(m_r, m_r)) / bNorm;
    } else {
        std::copy(v.begin(), v.end(), m_x.begin());  // v_df already solves the system
    }
    if (!std::isfinite(residual))
        throw std::runtime_error(fmt::format("step {}: the viscosity solve produced a non-finite residual; lower "
                                             "simulation.time_step.max",
                                             ctx.step));

    forEachParticle(n, [&](std::size_t i) {
        dv[i] = m_x[i] - v[i];
        v[i] = m_x[i];
    });
    if (sticky) addBoundaryLoads(ctx, particles, firstPass);
    m_lastIterations = iteration;
    m_lastResidual = residual;
    ctx.stats.viscositySolves += 1;
    ctx.stats.viscosityIterations += iteration;
    ctx.stats.viscosityWorstResidual = std::max(ctx.stats.viscosityWorstResidual, residual);
    if (residual > m_params.tolerance) {
        ++ctx.stats.viscosityCapHits;
        ctx.stats.warn(fmt::format("step {}: viscosity CG stopped at {} iterations (residual {:.3g} > {:.3g}); lower "
                                   "simulation.time_step.max or raise effects.viscosity.max_iterations",
                                   ctx.step, iteration, residual, m_params.tolerance));
    }
}

void ViscosityWeiler2018::addBoundaryLoads(StepContext& ctx, const ParticleSet& particles, bool firstPass) {
    // The viscous push of the boundary on particle i over the step, dt c_ik (x_ik . (v_i - v_k)) grad W_ik per
    // unit mass with the new velocities; the body receives the opposite. Sequential: a deterministic sum.
    // A later coupling pass replaces the earlier one's change of velocity, so it replaces its loads too;
    // counting every pass put a floor's mean force at 2.4 times the weight of the chocolate bunny on it.
    if (!firstPass)
        for (std::size_t b = 0; b < m_passLoads.impulse.size(); ++b) {
            ctx.loads.impulse[b] -= m_passLoads.impulse[b];
            ctx.loads.angularImpulse[b] -= m_passLoads.angularImpulse[b];
        }
    m_passLoads.clear(ctx.loads.impulse.size());
    const auto& x = particles.x();
    const auto& v = particles.v();
    const auto& m = particles.mass();
    for (std::size_t i = 0; i < particles.size(); ++i)
        for (std::uint32_t k : ctx.boundaryNeighbours.of(i)) {
            const Vec3 xik = x[i] - ctx.boundary.x[k];
            const Vec3 j = -ctx.dt * m[i] * boundaryCoefficient(ctx, i, k, xik) * xik.dot(v[i] - ctx.boundary.v[k]) *
                           ctx.kernel.gradW(xik);
            const std::uint32_t b = ctx.boundary.body[k];
            const BodyMotion& motion = ctx.boundary.motion[b];
            m_passLoads.impulse[b] += j;
            m_passLoads.angularImpulse[b] +=
                (ctx.boundary.x[k] - (motion.centre + motion.offset(ctx.time + ctx.dt))).cross(j);
        }
    for (std::size_t b = 0; b < m_passLoads.impulse.size(); ++b) {
        ctx.loads.impulse[b] += m_passLoads.impulse[b];
        ctx.loads.angularImpulse[b] += m_passLoads.angularImpulse[b];
    }
}

std::unique_ptr<Effect> makeViscosityWeiler2018(const EffectParams& params, const Scene& scene, ParticleSet& particles) {
    return std::make_unique<ViscosityWeiler2018>(dynamic_cast<const ViscosityParams&>(params), scene, particles);
}

}  // namespace ganache

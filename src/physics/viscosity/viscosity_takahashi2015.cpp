#include "physics/viscosity/viscosity_takahashi2015.h"

#include "core/parallel.h"

namespace ganache {

void ViscosityTakahashi2015::strainRate(const StepContext& ctx, const ParticleSet& particles,
                                        const std::vector<Vec3>& in, std::vector<Mat3>& out) {
    const auto& x = particles.x();
    const auto& m = particles.mass();
    out.resize(particles.size());
    forEachParticle(particles.size(), [&](std::size_t i) {
        Mat3 grad = Mat3::Zero();
        for (std::uint32_t j : ctx.fluidNeighbours.of(i))
            grad += (m[j] / ctx.density[j]) * (in[j] - in[i]) * ctx.kernel.gradW(x[i] - x[j]).transpose();
        out[i] = 0.5 * (grad + grad.transpose());
    });
}

void ViscosityTakahashi2015::multiply(const StepContext& ctx, const ParticleSet& particles,
                                      const std::vector<Vec3>& in, std::vector<Vec3>& out) {
    // K in = M in - dt F(in) + the boundary blocks: the strain rate and stress first, then their divergence.
    const auto& x = particles.x();
    const auto& m = particles.mass();
    strainRate(ctx, particles, in, m_stress);
    forEachParticle(particles.size(),
                    [&](std::size_t i) { m_stress[i] *= 2 * m_mu(i) * m[i] / ctx.density[i]; });
    forEachParticle(particles.size(), [&](std::size_t i) {
        const Real vi = m[i] / ctx.density[i];
        Vec3 force = Vec3::Zero();
        for (std::uint32_t j : ctx.fluidNeighbours.of(i))
            force += (vi * m_stress[j] + (m[j] / ctx.density[j]) * m_stress[i]) * ctx.kernel.gradW(x[i] - x[j]);
        out[i] = m[i] * in[i] - ctx.dt * force;
        if (sticky()) out[i] += m_boundaryBlock[i] * in[i];
    });
}

ViscosityPass ViscosityTakahashi2015::solve(StepContext& ctx, const ParticleSet& particles, std::vector<Vec3>& out) {
    const std::size_t n = particles.size();
    const auto& x = particles.x();
    const auto& v = particles.v();
    const auto& m = particles.mass();
    const Real dt = ctx.dt;
    m_b.resize(n);
    m_inverseDiagonal.resize(n);
    if (sticky()) m_boundaryBlock.resize(n);
    const bool jacobi = m_params.preconditioner != ViscosityParams::Preconditioner::None;
    forEachParticle(n, [&](std::size_t i) {
        // Diagonal block of dt d^2Phi/dv_i^2: through D_i itself (u -> sym(-u s_i^T), s_i = sum_j V_j grad W_ij)
        // and through each neighbour's D_j (u -> sym(V_i u grad W_ji^T)); a map u -> sym(u g^T) has the Gram
        // matrix (|g|^2 I + g g^T) / 2.
        const Real vi = m[i] / ctx.density[i];
        Mat3 block = Mat3::Zero();
        Vec3 s = Vec3::Zero();
        for (std::uint32_t j : ctx.fluidNeighbours.of(i)) {
            const Real vj = m[j] / ctx.density[j];
            const Vec3 g = ctx.kernel.gradW(x[i] - x[j]);
            s += vj * g;
            block += vj * m_mu(j) * vi * vi * (g.squaredNorm() * Mat3::Identity() + g * g.transpose());
        }
        block += vi * m_mu(i) * (s.squaredNorm() * Mat3::Identity() + s * s.transpose());
        // The boundary term of Eq. 12 per unit mass, times the mass: on the diagonal, and the bodies' velocities on
        // the right-hand side.
        Vec3 bodies = Vec3::Zero();
        block *= dt;
        if (sticky()) {
            m_boundaryBlock[i] = -dt * m[i] * boundaryBlock(ctx, particles, i, bodies);
            block += m_boundaryBlock[i];
        }
        m_b[i] = m[i] * (v[i] - dt * bodies);
        const Mat3 diagonal = m[i] * Mat3::Identity() + block;
        m_inverseDiagonal[i] = jacobi ? Mat3(diagonal.inverse()) : Mat3(Mat3::Identity() / m[i]);
    });
    const auto system = [&](const std::vector<Vec3>& in, std::vector<Vec3>& result) {
        multiply(ctx, particles, in, result);
        return fieldDot(in, result);
    };
    const auto precondition = [&](const std::vector<Vec3>& r, std::vector<Vec3>& z) {
        return deterministicSum(n, [&](std::size_t i) {
            z[i] = m_inverseDiagonal[i] * r[i];
            return r[i].dot(z[i]);
        });
    };
    // As in the main solver, the tolerance is relative to the correction the solve has to make.
    return m_cg.solve(system, precondition, m_b, v, out, m_params.tolerance, std::size_t(m_params.maxIterations));
}

}  // namespace ganache

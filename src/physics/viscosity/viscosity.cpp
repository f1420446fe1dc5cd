#include "physics/viscosity/viscosity.h"

#include "core/parallel.h"
#include "scene/scene.h"
#include "physics/viscosity/viscosity_explicit.h"
#include "physics/viscosity/viscosity_takahashi2015.h"
#include "physics/viscosity/viscosity_weiler2018.h"

#include <fmt/format.h>
#include <set>

namespace ganache {

namespace {
constexpr Real kTwoDPlus4 = 10;  // 2 (d + 2) with d = 3
}  // namespace

Real fieldDot(const std::vector<Vec3>& a, const std::vector<Vec3>& b) {
    return deterministicSum(a.size(), [&](std::size_t i) { return a[i].dot(b[i]); });
}

ViscosityPass ConjugateGradient::solve(const Apply& multiply, const Apply& precondition, const std::vector<Vec3>& b,
                                       const std::vector<Vec3>& v, std::vector<Vec3>& x, Real tolerance,
                                       std::size_t maxIterations) {
    const std::size_t n = b.size();
    for (auto* a : {&r, &z, &p, &q}) a->resize(n);
    multiply(v, q);
    forEachParticle(n, [&](std::size_t i) { r[i] = b[i] - q[i]; });
    scale = std::sqrt(fieldDot(r, r));
    if (scale == 0) {
        std::copy(v.begin(), v.end(), x.begin());
        return {};
    }
    multiply(x, q);
    forEachParticle(n, [&](std::size_t i) { r[i] = b[i] - q[i]; });
    precondition(r, z);
    std::copy(z.begin(), z.end(), p.begin());
    Real rz = fieldDot(r, z);
    ViscosityPass pass;
    pass.residual = std::sqrt(fieldDot(r, r)) / scale;
    while (pass.residual > tolerance && pass.iterations < maxIterations) {
        multiply(p, q);
        const Real alpha = rz / fieldDot(p, q);
        forEachParticle(n, [&](std::size_t i) {
            x[i] += alpha * p[i];
            r[i] -= alpha * q[i];
        });
        precondition(r, z);
        const Real rzNext = fieldDot(r, z);
        const Real beta = rzNext / rz;
        rz = rzNext;
        forEachParticle(n, [&](std::size_t i) { p[i] = z[i] + beta * p[i]; });
        pass.residual = std::sqrt(fieldDot(r, r)) / scale;
        ++pass.iterations;
    }
    return pass;
}

ParticleViscosity::ParticleViscosity(const ViscosityParams& params, const Scene& scene, ParticleSet& particles) {
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
    m_perParticle = &particles.addScalar("viscosity");
    refresh(particles);
}

void ParticleViscosity::refresh(const ParticleSet& particles) {
    if (!m_perParticle) return;
    const std::vector<Real>* source = particles.findScalar("fluid");
    const std::vector<Real>* temperature = particles.findScalar("temperature");
    auto& mu = *m_perParticle;
    forEachParticle(particles.size(), [&](std::size_t i) {
        const std::size_t s = sourceIndex(source, i);
        const auto& law = m_sourceLaw[s];
        mu[i] = law && temperature ? law->at((*temperature)[i]) : m_sourceMu[s];
    }, 4096);
}

ViscosityMethod::ViscosityMethod(const ViscosityParams& params, const Scene& scene, ParticleSet& particles)
    : m_params(params), m_mu(params, scene, particles),
      m_dv(&particles.addVector("_viscosity_dv", Vec3::Zero(), false)) {}

Real ViscosityMethod::pairCoefficient(const StepContext& ctx, const ParticleSet& p, std::size_t i, std::size_t j,
                                      const Vec3& xij) const {
    const Real h = ctx.kernel.supportRadius();
    return kTwoDPlus4 * 0.5 * (m_mu(i) + m_mu(j)) * 0.5 * (p.mass()[i] + p.mass()[j]) /
           (ctx.density[i] * ctx.density[j]) / (xij.squaredNorm() + 0.01 * h * h);
}

Real ViscosityMethod::boundaryCoefficient(const StepContext& ctx, std::size_t i, std::size_t k,
                                          const Vec3& xik) const {
    const Real h = ctx.kernel.supportRadius();
    return kTwoDPlus4 * m_params.boundaryMu * ctx.restDensity[i] * ctx.boundary.volume[k] /
           (ctx.density[i] * ctx.density[i]) / (xik.squaredNorm() + 0.01 * h * h);
}

Vec3 ViscosityMethod::laplacian(const StepContext& ctx, const ParticleSet& particles, const std::vector<Vec3>& in,
                                std::size_t i, bool withBodyVelocity) const {
    const auto& x = particles.x();
    Vec3 a = Vec3::Zero();
    for (std::uint32_t j : ctx.fluidNeighbours.of(i)) {
        const Vec3 xij = x[i] - x[j];
        a += pairCoefficient(ctx, particles, i, j, xij) * xij.dot(in[i] - in[j]) * ctx.kernel.gradW(xij);
    }
    if (sticky())
        for (std::uint32_t k : ctx.boundaryNeighbours.of(i)) {
            const Vec3 xik = x[i] - ctx.boundary.x[k];
            const Vec3 relative = withBodyVelocity ? Vec3(in[i] - ctx.boundary.v[k]) : in[i];
            a += boundaryCoefficient(ctx, i, k, xik) * xik.dot(relative) * ctx.kernel.gradW(xik);
        }
    return a;
}

Mat3 ViscosityMethod::boundaryBlock(const StepContext& ctx, const ParticleSet& particles, std::size_t i,
                                    Vec3& bodyTerm) const {
    Mat3 block = Mat3::Zero();
    for (std::uint32_t k : ctx.boundaryNeighbours.of(i)) {
        const Vec3 xik = particles.x()[i] - ctx.boundary.x[k];
        const Real c = boundaryCoefficient(ctx, i, k, xik);
        const Vec3 g = ctx.kernel.gradW(xik);
        block += c * g * xik.transpose();
        bodyTerm += c * ctx.boundary.v[k].dot(xik) * g;
    }
    return block;
}

std::string ViscosityMethod::capMessage(const StepContext& ctx, const ViscosityPass& pass) const {
    return fmt::format("step {}: viscosity CG stopped at {} iterations (residual {:.3g} > {:.3g}); lower "
                       "simulation.time_step.max or raise effects.viscosity.max_iterations",
                       ctx.step, pass.iterations, pass.residual, m_params.tolerance);
}

void ViscosityMethod::apply(StepContext& ctx, ParticleSet& particles) {
    const std::size_t n = particles.size();
    if (n == 0) return;
    auto& v = particles.v();
    auto& dv = *m_dv;
    // Temperatures change every step, and emitters may have added particles since the last pass.
    m_mu.refresh(particles);
    // With coupled passes the solve runs several times a step, each on the velocity the latest pressure solve
    // left. A later pass first takes back the previous pass's change dv (a pass replaces it, it does not add a
    // second dt of viscosity) and starts from v + dv, which is the current velocity. The first pass of a step
    // starts from v + dv with dv the previous step's change: the paper's warm start.
    const bool firstPass = !m_hasSolved || ctx.step != m_lastStep;
    m_hasSolved = true;
    m_lastStep = ctx.step;
    if (!firstPass) forEachParticle(n, [&](std::size_t i) { v[i] -= dv[i]; });
    const bool guessWithChange = m_params.warmStart || !firstPass;
    m_out.resize(n);
    forEachParticle(n, [&](std::size_t i) { m_out[i] = guessWithChange ? Vec3(v[i] + dv[i]) : v[i]; });

    m_last = solve(ctx, particles, m_out);
    if (!std::isfinite(m_last.residual))
        throw std::runtime_error(fmt::format("step {}: the viscosity solve produced a non-finite residual; lower "
                                             "simulation.time_step.max",
                                             ctx.step));
    forEachParticle(n, [&](std::size_t i) {
        dv[i] = m_out[i] - v[i];
        v[i] = m_out[i];
    });
    if (sticky()) addBoundaryLoads(ctx, particles, firstPass);
    ctx.stats.viscositySolves += 1;
    ctx.stats.viscosityIterations += m_last.iterations;
    ctx.stats.viscosityWorstResidual = std::max(ctx.stats.viscosityWorstResidual, m_last.residual);
    if (m_last.residual > m_params.tolerance) {
        ++ctx.stats.viscosityCapHits;
        ctx.stats.warn(capMessage(ctx, m_last));
    }
}

void ViscosityMethod::addBoundaryLoads(StepContext& ctx, const ParticleSet& particles, bool firstPass) {
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

std::unique_ptr<Effect> makeViscosity(const EffectParams& params, const Scene& scene, ParticleSet& particles) {
    const auto& p = dynamic_cast<const ViscosityParams&>(params);
    switch (p.method) {
    case ViscosityParams::Method::Explicit: return std::make_unique<ViscosityExplicit>(p, scene, particles);
    case ViscosityParams::Method::Takahashi2015: return std::make_unique<ViscosityTakahashi2015>(p, scene, particles);
    case ViscosityParams::Method::Weiler2018: break;
    }
    return std::make_unique<ViscosityWeiler2018>(p, scene, particles);
}

}  // namespace ganache

#include "physics/viscosity/viscosity.h"

#include "core/attributes.h"
#include "core/byte_stream.h"
#include "core/memory.h"
#include "core/parallel.h"
#include "physics/setup.h"
#include "physics/viscosity/viscosity_explicit.h"
#include "physics/viscosity/viscosity_takahashi2015.h"
#include "physics/viscosity/viscosity_weiler2018.h"
#include "scene/section.h"

#include <fmt/format.h>
#include <set>

namespace ganache {

namespace {

constexpr Real kTwoDPlus4 = 10;  // 2 (d + 2) with d = 3: the paper's scale

// The change of velocity of the latest pass: the warm start of the next step, and what a later coupled pass of the
// same step takes back.
constexpr Attribute<Vec3> kChange{"_viscosity_dv", false};
// The step before's change: the warm start extrapolates from the two.
constexpr Attribute<Vec3> kEarlierChange{"_viscosity_dv_earlier", false};

}  // namespace

LaplacianWeights::LaplacianWeights(ViscosityParams::Laplacian kind, Real spacing, const CubicSpline& kernel)
    : m_reshaped(kind == ViscosityParams::Laplacian::Lattice), m_inverseSpacing2(1 / (spacing * spacing)),
      m_scale(kTwoDPlus4) {
    if (!m_reshaped) return;
    // The scale that makes the reshaped sum exact on the lattice the sampler lays out (each particle's volume
    // 1 / latticeKernelSum, as its mass says): the x component of the Laplacian of v = y^2 / 2 e_x, which is 1, at
    // a lattice point, with the pairs' weights unscaled.
    const Real h = kernel.supportRadius(), eps = 0.01 * h * h, volume = 1 / latticeKernelSum(spacing, kernel);
    const int reach = int(std::ceil(h / spacing));
    Real sum = 0;
    for (int i = -reach; i <= reach; ++i)
        for (int j = -reach; j <= reach; ++j)
            for (int k = -reach; k <= reach; ++k) {
                const Vec3 xij = -spacing * Vec3(i, j, k);  // x_i at the origin
                const Real d2 = xij.squaredNorm();
                if (d2 == 0 || d2 >= h * h) continue;
                const Real vij = -0.5 * xij.y() * xij.y();  // (v_i - v_j) . e_x
                sum += volume * shape(d2) * vij * xij.x() / (d2 + eps) * kernel.gradW(xij).x();
            }
    m_scale = 1 / sum;
}

Real fieldDot(const std::vector<Vec3>& a, const std::vector<Vec3>& b) {
    return deterministicSum(a.size(), [&](std::size_t i) { return a[i].dot(b[i]); });
}

ViscosityPass ConjugateGradient::solve(const Apply& multiply, const Apply& precondition, const std::vector<Vec3>& b,
                                       const std::vector<Vec3>& v, std::vector<Vec3>& x, Real tolerance,
                                       std::size_t maxIterations) {
    const std::size_t n = b.size();
    std::vector<Vec3> mv(n), mx(n);
    multiply(v, mv);
    multiply(x, mx);
    ViscosityPass pass;
    if (!start(b, v, mv, mx, x, tolerance, maxIterations, pass)) return pass;
    Real rz = precondition(r, z);
    std::copy(z.begin(), z.end(), p.begin());
    for (;;) {
        const Real alpha = rz / multiply(p, q);
        const Real rrNext = deterministicSum(n, [&](std::size_t i) {
            x[i] += alpha * p[i];
            r[i] -= alpha * q[i];
            return r[i].squaredNorm();
        });
        pass.residual = std::sqrt(rrNext) / scale;
        if (++pass.iterations >= maxIterations || pass.residual <= tolerance) return pass;
        const Real rzNext = precondition(r, z);
        const Real beta = rzNext / rz;
        rz = rzNext;
        forEachParticle(n, [&](std::size_t i) { p[i] = z[i] + beta * p[i]; });
    }
}

bool ConjugateGradient::start(const std::vector<Vec3>& b, const std::vector<Vec3>& v, const std::vector<Vec3>& mv,
                              const std::vector<Vec3>& mx, std::vector<Vec3>& x, Real tolerance,
                              std::size_t maxIterations, ViscosityPass& pass) {
    const std::size_t n = b.size();
    for (auto* a : {&r, &z, &p, &q}) a->resize(n);
    // |b - M v|^2 and |r|^2 with r = b - M x, in one pass.
    using Vec2 = Eigen::Matrix<Real, 2, 1>;
    const Vec2 squares = deterministicSum<Vec2>(n, [&](std::size_t i) {
        r[i] = b[i] - mx[i];
        return Vec2((b[i] - mv[i]).squaredNorm(), r[i].squaredNorm());
    }, Vec2::Zero());
    scale = std::sqrt(squares[0]);
    pass = {0, 0, tolerance};
    if (scale == 0) {
        std::copy(v.begin(), v.end(), x.begin());
        return false;
    }
    pass.residual = std::sqrt(squares[1]) / scale;
    return pass.residual > tolerance && maxIterations > 0;
}

void leastEnergyGuess(const std::vector<Vec3>& b, const std::vector<Vec3>& v, const std::vector<Vec3>& mv,
                      const std::vector<Vec3>& d1, const std::vector<Vec3>& md1, const std::vector<Vec3>& d2,
                      const std::vector<Vec3>& md2, std::vector<Vec3>& x, std::vector<Vec3>& mx) {
    const GuessSums sums = deterministicSum<GuessSums>(b.size(), [&](std::size_t i) {
        return guessTerms(b[i], mv[i], d1[i], md1[i], d2[i], md2[i]);
    }, GuessSums::Zero());
    leastEnergyGuess(sums, v, mv, d1, md1, d2, md2, x, mx);
}

void leastEnergyGuess(const GuessSums& s, const std::vector<Vec3>& v, const std::vector<Vec3>& mv,
                      const std::vector<Vec3>& d1, const std::vector<Vec3>& md1, const std::vector<Vec3>& d2,
                      const std::vector<Vec3>& md2, std::vector<Vec3>& x, std::vector<Vec3>& mx) {
    // Zero gradient along d1 and d2: [d1.Md1 d1.Md2; d2.Md1 d2.Md2] (a, c) = (d1.(b - Mv), d2.(b - Mv)).
    Real a = 0, c = 0;
    const Real det = s[0] * s[2] - s[1] * s[1];  // >= 0 (Cauchy-Schwarz in M's inner product)
    if (s[0] > 0 && s[2] > 0 && det > 1e-9 * s[0] * s[2]) {
        a = (s[3] * s[2] - s[1] * s[4]) / det;
        c = (s[0] * s[4] - s[1] * s[3]) / det;
    } else if (s[0] > 0) {
        a = s[3] / s[0];
    }
    forEachParticle(v.size(), [&](std::size_t i) {
        x[i] = v[i] + a * d1[i] + c * d2[i];
        mx[i] = mv[i] + a * md1[i] + c * md2[i];
    });
}

ParticleViscosity::ParticleViscosity(const ViscosityParams& params, const SimulationSetup& setup,
                                     ParticleSet& particles) {
    if (params.mu) {
        m_mu = *params.mu;
        return;
    }
    std::vector<Material> sources;
    for (const FluidSource& s : setup.sources) sources.push_back(s.material);
    std::set<Real> distinct;
    bool laws = false;
    for (const auto& m : sources) {
        distinct.insert(m.mu);
        laws |= m.law.has_value();
    }
    // Laws of viscosity over temperature apply where particles have a temperature, i.e. with the heat effect.
    laws = laws && setup.findEffect("heat");
    m_mu = sources.front().mu;
    if (distinct.size() == 1 && !laws) return;
    // Viscosity varies: each particle carries its own, from its source's material (and temperature).
    if (sources.size() > 1 && !particles.find(attribute::kFluid))
        throw std::runtime_error("viscosity: the particles do not say which fluid they belong to; sample the scene "
                                 "again with this version of ganache");
    for (const auto& m : sources) {
        m_sourceMu.push_back(m.mu);
        m_sourceLaw.push_back(laws ? m.law : std::nullopt);
    }
    m_perParticle = &particles.add(attribute::kViscosity);
    refresh(particles);
}

void ParticleViscosity::refresh(const ParticleSet& particles) {
    if (!m_perParticle) return;
    const std::vector<Real>* source = particles.find(attribute::kFluid);
    const std::vector<Real>* temperature = particles.find(attribute::kTemperature);
    auto& mu = *m_perParticle;
    forEachParticle(particles.size(), [&](std::size_t i) {
        const std::size_t s = sourceIndex(source, i);
        const auto& law = m_sourceLaw[s];
        mu[i] = law && temperature ? law->at((*temperature)[i]) : m_sourceMu[s];
    });
}

ViscosityMethod::ViscosityMethod(const ViscosityParams& params, const SimulationSetup& setup, ParticleSet& particles)
    : m_params(params), m_mu(params, setup, particles),
      m_weights(params.laplacian, 2 * setup.particleRadius, CubicSpline(supportRadiusFor(setup.particleRadius))),
      m_dv(&particles.add(kChange)),
      m_earlierDv(&particles.add(kEarlierChange)) {}

std::vector<Counter> ViscosityMethod::counters(std::size_t) const {
    return {{"solves", double(m_solves)},
            {"iterations_per_solve", m_solves ? double(m_iterations) / double(m_solves) : 0.0},
            {"cap_hits", double(m_capHits)},
            {"worst_residual", m_worstResidual}};
}

void ViscosityMethod::save(ByteWriter& out) const {
    out(m_solves), out(m_iterations), out(m_capHits), out(m_worstResidual), out(m_lastDt), out(m_earlierDt);
}

void ViscosityMethod::restore(ByteReader& in) {
    in(m_solves), in(m_iterations), in(m_capHits), in(m_worstResidual), in(m_lastDt), in(m_earlierDt);
}

void ViscosityMethod::computeCoefficients(const StepContext& ctx, const ParticleSet& particles) {
    const auto& x = particles.x();
    const auto& m = particles.mass();
    const auto& f = ctx.fluidNeighbours;
    const auto& b = ctx.boundaryNeighbours;
    const Real h = ctx.kernel.supportRadius(), eps = 0.01 * h * h;
    resizeForRefill(m_pairs, f.pairs());
    resizeForRefill(m_boundaryPairs, sticky() ? b.pairs() : 0);
    m_fluidBlocks.resize(particles.size());
    const Real scale = m_weights.scale();
    // 2(d+2) mu_ij m_ij / (rho_i rho_j (|x_ij|^2 + 0.01 h^2)) g_ij, mu and m averaged over the pair so that the
    // operator is symmetric [Eq. 9], with LaplacianWeights' scale for 2(d+2) and its shape; the diagonal blocks in the
    // same pass (taken in three, the distances, the weights and the blocks, they cost twice as much on buckling).
    sweeps::ViscousWeightTerms terms;
    terms.gradient = ctx.gradients.fluid.data();
    terms.mass = m.data();
    terms.inverseDensity = m_inverseDensity.data();
    terms.mu = m_mu.values();
    terms.muConstant = m_mu(0);
    terms.c = 0.25 * scale;
    terms.eps = eps;
    terms.inverseSpacing2 = m_weights.inverseSpacing2();
    terms.linear = m_weights.linear();
    terms.quadratic = m_weights.quadratic();
    forEachBlock(particles.size(), [&](std::size_t begin, std::size_t end) {
        sweeps::viscousWeights(begin, end, f, ctx.positionRows.data(), terms, m_pairs.data(), m_fluidBlocks.data());
        if (!sticky()) return;
        // 2(d+2) mu_b Psi_k / (rho_i^2 (|x_ik|^2 + 0.01 h^2)) g_ik [Eq. 11-12], weighted as the fluid's pairs: the
        // wall's particles stand in for fluid moving with it
        for (std::size_t i = begin; i < end; ++i) {
            const Real ri = m_inverseDensity[i], cb = scale * m_params.boundaryMu * ctx.restDensity[i] * (ri * ri);
            for (std::size_t p = b.first(i); p < b.last(i); ++p) {
                const std::uint32_t kb = b.indices[p];
                const Real d2 = (x[i] - ctx.boundary.x[kb]).squaredNorm();
                m_boundaryPairs[p] =
                    cb * ctx.boundary.volume[kb] * ctx.gradients.boundary[p] * m_weights.shape(d2) / (d2 + eps);
            }
        }
    });
}

Vec3 ViscosityMethod::laplacian(const StepContext& ctx, const ParticleSet& particles, const std::vector<Vec3>& in,
                                std::size_t i, bool withBodyVelocity) const {
    const auto& x = particles.x();
    const auto& f = ctx.fluidNeighbours;
    Vec3 a = Vec3::Zero();
    for (std::size_t p = f.first(i); p < f.last(i); ++p) {
        const std::uint32_t j = f.indices[p];
        const Vec3 xij = x[i] - x[j];
        a += (Real(m_pairs[p]) * xij.dot(in[i] - in[j])) * xij;
    }
    if (sticky()) {
        const auto& b = ctx.boundaryNeighbours;
        for (std::size_t p = b.first(i); p < b.last(i); ++p) {
            const std::uint32_t k = b.indices[p];
            const Vec3 xik = x[i] - ctx.boundary.x[k];
            const Vec3 relative = withBodyVelocity ? Vec3(in[i] - ctx.boundary.v[k]) : in[i];
            a += (m_boundaryPairs[p] * xik.dot(relative)) * xik;
        }
    }
    return a;
}

Mat3 ViscosityMethod::boundaryBlock(const StepContext& ctx, const ParticleSet& particles, std::size_t i,
                                    Vec3& bodyTerm) const {
    Mat3 block = Mat3::Zero();
    const auto& b = ctx.boundaryNeighbours;
    for (std::size_t p = b.first(i); p < b.last(i); ++p) {
        const std::uint32_t k = b.indices[p];
        const Vec3 xik = particles.x()[i] - ctx.boundary.x[k];
        block += m_boundaryPairs[p] * xik * xik.transpose();
        bodyTerm += (m_boundaryPairs[p] * ctx.boundary.v[k].dot(xik)) * xik;
    }
    return block;
}

std::string ViscosityMethod::capMessage(const StepContext& ctx, const ViscosityPass& pass) const {
    return fmt::format("step {}: viscosity CG stopped at {} iterations (residual {:.3g} > {:.3g}); lower "
                       "simulation.time_step.max or raise effects.viscosity.max_iterations",
                       ctx.step, pass.iterations, pass.residual, pass.tolerance);
}

void ViscosityMethod::apply(StepContext& ctx, ParticleSet& particles) {
    const std::size_t n = particles.size();
    if (n == 0) return;
    auto& v = particles.v();
    auto& dv = *m_dv;
    auto& earlier = *m_earlierDv;
    // Temperatures change every step, and emitters may have added particles since the last pass.
    m_mu.refresh(particles);
    // With coupled passes the solve runs several times a step, each on the velocity the latest pressure solve
    // left. A later pass first takes back the previous pass's change dv (a pass replaces it, it does not add a
    // second dt of viscosity) and starts from v + dv, which is the current velocity. The first pass of a step
    // starts from the paper's warm start v + dv, dv the previous step's change, improved twice: dv is taken per unit
    // time (the viscous change grows with dt; unscaled, the default scene took 29 % more CG iterations) and half
    // way extrapolated from the change of the step before (a full extrapolation overshoots where the fluid
    // melts: default scene +19 %; half way saves 4-13 % of the iterations on the default scene and the anchors).
    // weiler2018 replaces the fixed extrapolation, in solves at its loose tolerance, by the best combination of the
    // two changes (lastChange()).
    const bool firstPass = !m_hasSolved || ctx.step != m_lastStep;
    m_hasSolved = true;
    m_lastStep = ctx.step;
    m_warmPass = firstPass && m_params.warmStart;
    if (!firstPass) forEachParticle(n, [&](std::size_t i) { v[i] -= dv[i]; });
    m_out.resize(n);
    m_inverseDensity.resize(n);
    // Rates dv / dt of the last two steps, r1 and r0: the warm start's guess is dt (r1 + (r1 - r0) / 2).
    const Real scale = m_lastDt > 0 ? ctx.dt / m_lastDt : 1;
    const Real ratio = m_earlierDt > 0 ? m_lastDt / m_earlierDt : 0;
    forEachParticle(n, [&](std::size_t i) {
        m_inverseDensity[i] = 1 / ctx.density[i];  // for computeCoefficients
        if (m_warmPass)
            m_out[i] = v[i] + scale * (ratio > 0 ? Vec3(1.5 * dv[i] - 0.5 * ratio * earlier[i]) : dv[i]);
        else
            m_out[i] = firstPass ? v[i] : Vec3(v[i] + dv[i]);
    });
    if (m_warmPass) {
        m_earlierDt = m_lastDt;
        m_lastDt = ctx.dt;
    }
    computeCoefficients(ctx, particles);

    m_last = solve(ctx, particles, m_out);
    if (!std::isfinite(m_last.residual))
        throw std::runtime_error(fmt::format("step {}: the viscosity solve produced a non-finite residual; lower "
                                             "simulation.time_step.max",
                                             ctx.step));
    forEachParticle(n, [&](std::size_t i) {
        if (m_warmPass) earlier[i] = dv[i];
        dv[i] = m_out[i] - v[i];
        v[i] = m_out[i];
    });
    if (sticky()) addBoundaryLoads(ctx, particles, firstPass);
    m_solves += 1;
    m_iterations += m_last.iterations;
    m_worstResidual = std::max(m_worstResidual, m_last.residual);
    // A cap hit is a solve that ran out of iterations above its tolerance; the exact rigid step after CG may move a
    // converged residual a little either way, which is no reason to warn.
    if (m_last.iterations >= std::size_t(m_params.maxIterations) && m_last.residual > m_last.tolerance) {
        ++m_capHits;
        ctx.stats.warn(capMessage(ctx, m_last));
    }
}

void ViscosityMethod::addBoundaryLoads(StepContext& ctx, const ParticleSet& particles, bool firstPass) {
    // The viscous push of the boundary on particle i over the step, dt c_ik (x_ik . (v_i - v_k)) grad W_ik per
    // unit mass with the new velocities; the body receives the opposite. Sequential: a deterministic sum.
    // A later coupling pass replaces the earlier one's change of velocity, so it replaces its loads too;
    // counting every pass put a floor's mean force at 2.4 times the weight of the chocolate bunny on it.
    if (!firstPass) ctx.loads.subtract(m_passLoads);
    m_passLoads.clear(ctx.loads.impulse.size());
    // The pushes, each along its pair's line, are summed by particle in parallel; a particle whose boundary
    // neighbours are all of one body then adds their sum at its position (BodyLoads::addPushes).
    const auto& x = particles.x();
    const auto& v = particles.v();
    const auto& m = particles.mass();
    const auto& b = ctx.boundaryNeighbours;
    const Real t = ctx.time + ctx.dt;
    auto push = [&](std::size_t i, std::size_t p) {
        const std::uint32_t k = b.indices[p];
        const Vec3 xik = x[i] - ctx.boundary.x[k];
        return Vec3((-ctx.dt * m[i] * m_boundaryPairs[p] * xik.dot(v[i] - ctx.boundary.v[k])) * xik);
    };
    m_wallImpulse.resize(particles.size());
    forEachParticle(particles.size(), [&](std::size_t i) {
        Vec3 j = Vec3::Zero();
        for (std::size_t p = b.first(i); p < b.last(i); ++p) j += push(i, p);
        m_wallImpulse[i] = j;
    });
    for (std::size_t i = 0; i < particles.size(); ++i)
        m_passLoads.addPushes(ctx.boundary, b.indices.data() + b.first(i), b.indices.data() + b.last(i), x[i],
                              m_wallImpulse[i], t, [&](std::size_t n) { return push(i, b.first(i) + n); });
    ctx.loads.add(m_passLoads);
}

std::shared_ptr<const EffectParams> readViscosity(Section& s) {
    using Method = ViscosityParams::Method;
    using Preconditioner = ViscosityParams::Preconditioner;
    auto p = std::make_shared<ViscosityParams>();
    const std::string method = s.choice("method", "weiler2018", {"weiler2018", "explicit", "takahashi2015"});
    p->method = method == "explicit" ? Method::Explicit : method == "takahashi2015" ? Method::Takahashi2015
                                                                                     : Method::Weiler2018;
    if (s.has("mu")) p->mu = s.number("mu", std::nullopt, "Pa s", Bounds::closed(0, limits::kViscosity));
    p->boundaryMu = s.number("boundary_mu", p->boundaryMu, "Pa s", Bounds::closed(0, limits::kViscosity));
    p->laplacian = s.choice("laplacian", "lattice", {"lattice", "paper"}) == "paper" ? ViscosityParams::Laplacian::Paper
                                                                                    : ViscosityParams::Laplacian::Lattice;
    if (p->method == Method::Explicit) {
        // Forward Euler has no solve: its only setting is how many sub-steps one step may take.
        for (const char* key : {"tolerance", "stiff_tolerance", "preconditioner", "warm_start"})
            if (s.has(key))
                s.failAtKey(key, fmt::format("{}.{} is a setting of the implicit solvers; method 'explicit' has no "
                                             "solve",
                                             s.path(), key),
                            "remove it, or choose method: weiler2018");
        p->maxIterations = s.integer("max_iterations", 10000, 1, 100000000);
        return p;
    }
    p->tolerance = s.number("tolerance", p->tolerance, "relative residual", Bounds{0, 1, true, true});
    if (p->method == Method::Weiler2018)
        p->stiffTolerance = s.number("stiff_tolerance", p->stiffTolerance, "relative residual", Bounds{0, 1, true, true});
    else if (s.has("stiff_tolerance"))
        s.failAtKey("stiff_tolerance",
                    fmt::format("{}.stiff_tolerance is a setting of weiler2018, whose clusters measure stiffness; "
                                "{} has one tolerance",
                                s.path(), method),
                    "remove it, or use tolerance");
    p->maxIterations = s.integer("max_iterations", p->maxIterations, 1, 100000);
    const bool weiler = p->method == Method::Weiler2018;
    const std::string preconditioner =
        s.choice("preconditioner", weiler ? "clusters" : "block_jacobi", {"clusters", "rigid", "block_jacobi", "none"});
    if ((preconditioner == "rigid" || preconditioner == "clusters") && !weiler)
        s.fail("preconditioner",
               fmt::format("{}.preconditioner '{}' works on the system of weiler2018 only: the rigid motions are "
                           "not free of viscous forces in {}'s",
                           s.path(), preconditioner, method),
               "use block_jacobi or none");
    p->preconditioner = preconditioner == "none"           ? Preconditioner::None
                        : preconditioner == "block_jacobi" ? Preconditioner::BlockJacobi
                        : preconditioner == "rigid"        ? Preconditioner::Rigid
                                                           : Preconditioner::Clusters;
    p->warmStart = s.boolean("warm_start", p->warmStart);
    return p;
}

std::unique_ptr<Effect> makeViscosity(const EffectParams& params, const SimulationSetup& setup, ParticleSet& particles) {
    const auto& p = static_cast<const ViscosityParams&>(params);
    switch (p.method) {
    case ViscosityParams::Method::Explicit: return std::make_unique<ViscosityExplicit>(p, setup, particles);
    case ViscosityParams::Method::Takahashi2015: return std::make_unique<ViscosityTakahashi2015>(p, setup, particles);
    case ViscosityParams::Method::Weiler2018: break;
    }
    return std::make_unique<ViscosityWeiler2018>(p, setup, particles);
}

}  // namespace ganache

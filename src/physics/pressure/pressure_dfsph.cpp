#include "physics/pressure/pressure_dfsph.h"

#include "core/parallel.h"

#include <fmt/format.h>

#include <limits>

namespace ganache {

namespace {

// Weight of a boundary particle in the pressure coupling (density rate and push alike; the density itself counts
// it once). Counted once, as in [AIA+12], walls leaked 8 of 1000 particles of an inviscid block splashing in a
// closed tank and a resting viscous column needed 125 iterations a step. Doubling only the push (the symmetric
// pair form with the mirrored pressure) stopped the leak, but the push was then no longer the adjoint of the
// rate and an inviscid column gained energy. Doubling both keeps the solve a projection: no leak, no energy
// gain, 10 iterations a step for the column.
constexpr Real kWall = 2;

// Jacobi relaxation. The DFSPH diagonal leaves out how neighbours' pressures feed back, so the unrelaxed
// iteration can overshoot in an alternating pattern and diverge (seen on a column resting on a wall); half
// steps, as in IISPH (Ihmsen et al. 2014), converge.
constexpr Real kRelaxation = 0.5;

// The constant-density pressure kappa / rho of the last step: the next step's warm start.
constexpr Attribute<Real> kPressure{"_pressure", false};

}  // namespace

PressureDFSPH::PressureDFSPH(const PressureSettings& settings, ParticleSet& particles)
    : m_settings(settings),
      m_pressure(&particles.add(kPressure)) {}

void PressureDFSPH::computeFactors(const StepContext& ctx, const ParticleSet& particles) {
    const std::size_t n = particles.size();
    m_factor.resize(n);
    const auto& x = particles.x();
    const auto& m = particles.mass();
    const Real h4 = std::pow(ctx.kernel.supportRadius(), 4);
    forEachParticle(n, [&](std::size_t i) {
        Vec3 sum = Vec3::Zero();
        Real squares = 0;
        for (std::uint32_t j : ctx.fluidNeighbours.of(i)) {
            const Vec3 g = m[j] * ctx.kernel.gradW(x[i] - x[j]);
            sum += g;
            squares += g.squaredNorm();
        }
        for (std::uint32_t k : ctx.boundaryNeighbours.of(i))
            sum += kWall * ctx.restDensity[i] * ctx.boundary.volume[k] * ctx.kernel.gradW(x[i] - ctx.boundary.x[k]);
        const Real denominator = sum.squaredNorm() + squares;
        // Particles with (almost) no neighbours get no pressure: a lone particle cannot be compressed.
        const Real scale = m[i] / h4;
        m_factor[i] = denominator > 1e-8 * scale * scale ? 1 / denominator : 0;
    });
}

template <class Target>
std::size_t PressureDFSPH::solve(Solve which, StepContext& ctx, ParticleSet& particles, std::vector<Real>& pressure,
                                 Target target) {
    if (m_settings.solver == PressureSettings::Solver::Mprgp) return solveMprgp(which, ctx, particles, pressure, target);
    const bool density = which == Solve::Density;
    const Real tolerance = density ? m_settings.densityError : m_settings.divergenceError;
    const std::size_t n = particles.size();
    if (n == 0) return 0;
    const Real dt = ctx.dt;
    const auto& x = particles.x();
    const auto& m = particles.mass();
    auto& v = particles.v();
    m_rate.resize(n);
    m_step.resize(n);
    std::vector<Real> error(n);

    m_start = pressure;
    std::size_t iteration = 0;
    for (;; ++iteration) {
        forEachParticle(n, [&](std::size_t i) {
            Real rate = 0;  // Drho/Dt
            for (std::uint32_t j : ctx.fluidNeighbours.of(i)) rate += m[j] * (v[i] - v[j]).dot(ctx.kernel.gradW(x[i] - x[j]));
            for (std::uint32_t k : ctx.boundaryNeighbours.of(i))
                rate += kWall * ctx.restDensity[i] * ctx.boundary.volume[k] *
                        (v[i] - ctx.boundary.v[k]).dot(ctx.kernel.gradW(x[i] - ctx.boundary.x[k]));
            m_rate[i] = target(i, rate);  // signed density error to remove [kg/m^3]
            // Complementarity residual: a particle under pressure must sit at rest density (an expanding one
            // is pushed too hard, e.g. by a warm start from another neighbourhood); one without pressure may
            // only be too light.
            error[i] = (pressure[i] > 0 ? std::abs(m_rate[i]) : std::max<Real>(m_rate[i], 0)) / ctx.restDensity[i];
        });
        const Real meanError = deterministicSum(n, [&](std::size_t i) { return error[i]; }) / Real(n);
        const bool converged = meanError <= tolerance;
        if ((converged && iteration >= std::size_t(m_settings.minIterations)) ||
            iteration >= std::size_t(m_settings.maxIterations)) {
            if (!converged) {
                ++(density ? ctx.stats.pressureCapHits : ctx.stats.divergenceCapHits);
                ctx.stats.warn(fmt::format("step {}: {} solve stopped at {} iterations (mean error {:.3g} > {:.3g}); "
                                           "lower simulation.time_step.max or raise simulation.pressure.max_iterations",
                                           ctx.step, density ? "constant-density" : "divergence-free",
                                           iteration, meanError, tolerance));
            }
            break;
        }
        // Projected Jacobi step: the pressure of a particle never goes below zero.
        forEachParticle(n, [&](std::size_t i) {
            const Real next = std::max<Real>(pressure[i] + kRelaxation * m_rate[i] * m_factor[i] / (dt * dt), 0);
            m_step[i] = next - pressure[i];
            pressure[i] = next;
        });
        applyPressure(ctx, particles, m_step);
    }
    // What this solve added to the pressures applied before it.
    for (std::size_t i = 0; i < n; ++i) m_start[i] = pressure[i] - m_start[i];
    addBoundaryLoads(ctx, particles, m_start);
    return iteration;
}

template <class Target>
std::size_t PressureDFSPH::solveMprgp(Solve which, StepContext& ctx, ParticleSet& particles,
                                      std::vector<Real>& pressure, Target target) {
    // The solve as a bound-constrained quadratic program: with e(s) = b - dt^2 A s the density error to remove
    // (A = J J^T, J the density rate of a velocity field, J^T the velocity change of pressures), find s >= 0 with
    // e <= 0 and s_i e_i = 0. Its gradient is G = -e. MPRGP (Dostal & Schoeberl 2005): conjugate gradient steps on the
    // particles under pressure, gradient projection when a step would make a pressure negative, and proportioning
    // steps that release particles whose neighbours compress them. Diagonally preconditioned by the DFSPH factor
    // (1 / A_ii). Each iteration costs one product with A, as a Jacobi sweep does.
    const bool density = which == Solve::Density;
    const Real tolerance = density ? m_settings.densityError : m_settings.divergenceError;
    const std::size_t n = particles.size();
    if (n == 0) return 0;
    const Real dt = ctx.dt;
    const auto& x = particles.x();
    const auto& m = particles.mass();
    auto& v = particles.v();
    const auto& rho0 = ctx.restDensity;
    m_start = pressure;
    std::vector<Real> e(n), dir(n), q(n), z(n);
    std::vector<Vec3> dv(n);
    // The density rate of a velocity field: with the bodies' velocities (withBodies) for the error, without for A.
    auto rate = [&](const std::vector<Vec3>& u, std::size_t i, bool withBodies) {
        Real r = 0;
        for (std::uint32_t j : ctx.fluidNeighbours.of(i)) r += m[j] * (u[i] - u[j]).dot(ctx.kernel.gradW(x[i] - x[j]));
        for (std::uint32_t k : ctx.boundaryNeighbours.of(i))
            r += kWall * rho0[i] * ctx.boundary.volume[k] *
                 (withBodies ? Vec3(u[i] - ctx.boundary.v[k]) : u[i]).dot(ctx.kernel.gradW(x[i] - ctx.boundary.x[k]));
        return r;
    };
    auto errors = [&] { forEachParticle(n, [&](std::size_t i) { e[i] = target(i, rate(v, i, true)); }); };
    // q = dt^2 A d, and dv = -dt J^T d, the velocity change of the pressures d.
    auto product = [&](const std::vector<Real>& d) {
        forEachParticle(n, [&](std::size_t i) {
            Vec3 a = Vec3::Zero();
            for (std::uint32_t j : ctx.fluidNeighbours.of(i)) a += m[j] * (d[i] + d[j]) * ctx.kernel.gradW(x[i] - x[j]);
            for (std::uint32_t k : ctx.boundaryNeighbours.of(i))
                a += kWall * rho0[i] * ctx.boundary.volume[k] * d[i] * ctx.kernel.gradW(x[i] - ctx.boundary.x[k]);
            dv[i] = -dt * a;
        });
        forEachParticle(n, [&](std::size_t i) { q[i] = -dt * rate(dv, i, false); });
    };
    auto sum = [&](auto term) { return deterministicSum(n, term); };
    const Real dt2 = dt * dt;
    // D_i = dt^2 A_ii; particles without neighbours (factor 0) take no pressure.
    auto inverseD = [&](std::size_t i) { return m_factor[i] / dt2; };
    // Moves the pressures by -alpha d (the direction whose product is in q, dv).
    auto move = [&](Real alpha, const std::vector<Real>& d) {
        forEachParticle(n, [&](std::size_t i) {
            pressure[i] -= alpha * d[i];
            if (pressure[i] < 0) pressure[i] = 0;  // round-off at the bound
            e[i] += alpha * q[i];
            v[i] -= alpha * dv[i];
        }, 4096);
    };
    // Free gradient (particles under pressure) and chopped gradient (particles at zero pressure that want some).
    auto free = [&](std::size_t i) { return pressure[i] > 0 ? -e[i] : 0.0; };
    auto chopped = [&](std::size_t i) { return pressure[i] > 0 || m_factor[i] == 0 ? 0.0 : std::min<Real>(-e[i], 0); };
    auto meanError = [&] {
        return sum([&](std::size_t i) { return std::abs(free(i) + chopped(i)) / rho0[i]; }) / Real(n);
    };
    constexpr Real kStep = 0.5;   // expansion step length in the scaled variables (the stable Jacobi relaxation)
    constexpr Real kGamma = 1;    // proportioning threshold
    errors();
    std::size_t iteration = 0;
    bool restart = true;
    Real error = meanError();
    while (true) {
        const bool converged = error <= tolerance;
        if ((converged && iteration >= std::size_t(m_settings.minIterations)) ||
            iteration >= std::size_t(m_settings.maxIterations)) {
            if (!converged) {
                ++(density ? ctx.stats.pressureCapHits : ctx.stats.divergenceCapHits);
                ctx.stats.warn(fmt::format("step {}: {} solve stopped at {} iterations (mean error {:.3g} > {:.3g}); "
                                           "lower simulation.time_step.max or raise simulation.pressure.max_iterations",
                                           ctx.step, density ? "constant-density" : "divergence-free", iteration,
                                           error, tolerance));
            }
            break;
        }
        ++iteration;
        const Real chopNorm = sum([&](std::size_t i) { return chopped(i) * chopped(i) * inverseD(i); });
        const Real reducedFree = sum([&](std::size_t i) {
            if (pressure[i] <= 0 || m_factor[i] == 0) return 0.0;
            const Real scaled = std::min(pressure[i] / (kStep * inverseD(i)), free(i));  // in gradient units
            return scaled * free(i) * inverseD(i);
        });
        if (chopNorm <= kGamma * kGamma * reducedFree) {
            if (restart) forEachParticle(n, [&](std::size_t i) { dir[i] = inverseD(i) * free(i); }, 4096);
            restart = false;
            product(dir);
            const Real dq = sum([&](std::size_t i) { return dir[i] * q[i]; });
            if (dq <= 0) break;  // nothing left to move
            const Real cg = sum([&](std::size_t i) { return free(i) * dir[i]; }) / dq;
            Real feasible = std::numeric_limits<Real>::infinity();
            for (std::size_t i = 0; i < n; ++i)
                if (dir[i] > 0) feasible = std::min(feasible, pressure[i] / dir[i]);
            if (cg <= feasible) {
                move(cg, dir);
                forEachParticle(n, [&](std::size_t i) { z[i] = inverseD(i) * free(i); }, 4096);
                const Real beta = sum([&](std::size_t i) { return z[i] * q[i]; }) / dq;
                forEachParticle(n, [&](std::size_t i) { dir[i] = z[i] - beta * dir[i]; }, 4096);
            } else {
                // Expansion: to the bound, then a projected gradient step, and CG starts again.
                move(feasible, dir);
                forEachParticle(n, [&](std::size_t i) {
                    const Real next = std::max<Real>(pressure[i] - kStep * inverseD(i) * free(i), 0);
                    z[i] = pressure[i] - next;
                }, 4096);
                product(z);
                move(1, z);
                restart = true;
            }
        } else {
            // Proportioning: release the particles at zero pressure that their neighbours compress.
            forEachParticle(n, [&](std::size_t i) { z[i] = inverseD(i) * chopped(i); }, 4096);
            product(z);
            const Real dq = sum([&](std::size_t i) { return z[i] * q[i]; });
            if (dq <= 0) break;
            const Real alpha = sum([&](std::size_t i) { return chopped(i) * z[i]; }) / dq;
            move(alpha, z);
            restart = true;
        }
        error = meanError();
    }
    for (std::size_t i = 0; i < n; ++i) m_start[i] = pressure[i] - m_start[i];
    addBoundaryLoads(ctx, particles, m_start);
    return iteration;
}

void PressureDFSPH::applyPressure(const StepContext& ctx, ParticleSet& particles, const std::vector<Real>& s) const {
    // v_i -= dt (sum_j m_j (s_i + s_j) grad W_ij + kWall sum_k Psi_k s_i grad W_ik): the boundary mirrors the
    // particle's own pressure [AIA+12].
    const Real dt = ctx.dt;
    const auto& x = particles.x();
    const auto& m = particles.mass();
    auto& v = particles.v();
    forEachParticle(particles.size(), [&](std::size_t i) {
        Vec3 a = Vec3::Zero();
        for (std::uint32_t j : ctx.fluidNeighbours.of(i)) a += m[j] * (s[i] + s[j]) * ctx.kernel.gradW(x[i] - x[j]);
        for (std::uint32_t k : ctx.boundaryNeighbours.of(i))
            a += kWall * ctx.restDensity[i] * ctx.boundary.volume[k] * s[i] * ctx.kernel.gradW(x[i] - ctx.boundary.x[k]);
        v[i] -= dt * a;
    });
}

void PressureDFSPH::applyWarmStart(StepContext& ctx, ParticleSet& particles) {
    if (particles.size() == 0) return;
    applyPressure(ctx, particles, *m_pressure);
    addBoundaryLoads(ctx, particles, *m_pressure);
}

void PressureDFSPH::addBoundaryLoads(StepContext& ctx, const ParticleSet& particles, const std::vector<Real>& s) const {
    // The solve is linear in the pressures and the positions do not move during it, so the impulse the
    // boundaries gave the fluid follows from the final pressures. Sequential: a deterministic sum.
    const auto& x = particles.x();
    const auto& m = particles.mass();
    const Real dt = ctx.dt;
    for (std::size_t i = 0; i < particles.size(); ++i) {
        if (s[i] == 0) continue;
        for (std::uint32_t k : ctx.boundaryNeighbours.of(i)) {
            // Impulse on the body: the opposite of what the body gave particle i.
            const Vec3 j = dt * m[i] * kWall * ctx.restDensity[i] * ctx.boundary.volume[k] * s[i] *
                           ctx.kernel.gradW(x[i] - ctx.boundary.x[k]);
            ctx.loads.add(ctx.boundary, k, j, ctx.time + dt);
        }
    }
}

void PressureDFSPH::solveDensity(StepContext& ctx, ParticleSet& particles) {
    const Real dt = ctx.dt;
    // rho* - rho_0 = rho + dt Drho/Dt - rho_0 [BK17 Eq. 8]
    ctx.stats.pressureIterations += solve(Solve::Density, ctx, particles, *m_pressure,
                                          [&](std::size_t i, Real rate) {
                                              return ctx.density[i] + dt * rate - ctx.restDensity[i];
                                          });
}

void PressureDFSPH::solveDivergence(StepContext& ctx, ParticleSet& particles) {
    const Real dt = ctx.dt;
    // No warm start here: last step's divergence pressure belongs to last step's neighbourhood. Reapplied to
    // a particle that has just reached a wall it kicked a lone falling particle (1.8 m/s) back up at 30 m/s,
    // and at 3.8 m/s with the complementarity residual; starting from zero it comes to rest.
    m_pressureV.assign(particles.size(), 0);
    // dt Drho/Dt: the density change the rate would cause over one step [BK17 Eq. 9]
    ctx.stats.divergenceIterations += solve(Solve::Divergence, ctx, particles, m_pressureV,
                                            [&](std::size_t, Real rate) { return dt * rate; });
}

}  // namespace ganache

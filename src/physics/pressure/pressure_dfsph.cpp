#include "physics/pressure/pressure_dfsph.h"

#include "core/attributes.h"
#include "core/memory.h"
#include "core/parallel.h"

#include <fmt/format.h>

#include <functional>
#include <limits>

namespace ganache {

namespace {

// Weight of a boundary particle in the pressure coupling (density rate and push alike; the density itself counts
// it once). Counted once, as in [AIA+12], walls leaked 8 of 1000 particles of an inviscid block splashing in a
// closed tank. Doubling only the push (the symmetric pair form with the mirrored pressure) stopped the leak, but the
// push was then no longer the adjoint of the rate and an inviscid column gained energy. Doubling both keeps the
// solve a projection: no leak, no energy gain.
constexpr Real kWall = 2;

// Jacobi relaxation. The DFSPH diagonal leaves out how neighbours' pressures feed back, so the unrelaxed
// iteration can overshoot in an alternating pattern and diverge (seen on a column resting on a wall); half
// steps, as in IISPH (Ihmsen et al. 2014), converge. MPRGP's gradient-projection steps use the same length.
constexpr Real kRelaxation = 0.5;

// How far below its rest density a particle is taken to have come apart from its neighbours (a free surface, a film
// tearing), so that the pressure it held last step is not applied again. Reapplied, that pressure pushed its neighbours
// away every step, and the constant-density solve, whose stopping test is the mean over all particles, never took it
// back: in the default scene at final quality a molten film's particles left the plate at up to 1 m/s (with this rule
// the fastest is a drip falling at 0.24 m/s). 1 % is a hundred times the default density tolerance, so the warm start
// of a body's supporting pressure, within it, stays whole; below rest density at all (SPlisHSPlasH's rule) the 8k
// anchor block took 7.8 constant-density iterations a step instead of 3.0.
constexpr Real kSeparated = 0.01;

// A solve's mean residual below this share of its tolerance is round-off: see finished().
constexpr Real kRoundOff = 1e-6;

// The coarse space (PressureSettings::coarseFrom): cells of two kernel supports, about 4^3 particles, the smallest its
// build allows. The build costs several pressure products, so it is repeated only every few steps: a preconditioner
// decides how fast a solve converges, not where it ends. On the 50k anchor block, rebuilt every 8 steps: 3.50 + 0.75
// constant-density and divergence-free products a step; rebuilt every step, about as many, but the build cost what
// they saved.
constexpr Real kCoarseCell = 2;
// At most this many cells: the factorisation's cost grows about as their square. On a 1M-particle honey blob's impact
// (2 threads), 16,000 cells of two supports: 4.0 + 1.0 products a step, the step 1,526 ms, a fifth of it factoring;
// at most 8,192 / 4,096 / 2,048 cells: 7.4 + 1.2 / 8.4 + 1.1 / 20.9 + 1.3 products, 1,699 / 1,148 / 1,625 ms.
constexpr std::size_t kCoarseMaxCells = 4096;
constexpr std::uint64_t kCoarseRebuild = 8;

// When the bound stops a conjugate gradient step before this share of its length, the expansion takes the whole step
// with every pressure it would make negative set to zero, instead of stopping at the first such particle and taking
// a projected gradient step from there (see solveMprgp). At a landing's wavefront many particles reach zero in one
// step, and stopping at the first gave up nearly all of the step for one particle's bound: step_bench's 1M-particle
// honey blob took 34.5 constant-density products a step over its first ten steps of contact, now 7-8. Taking the
// whole step whenever the bound stops it at all was slower where the bound stops it late (the buckling anchor 1,067
// products against 891 at 0.1, 955 before). At 0.03 Table 2's rows took about as many as at 0.1 and the 1M blob
// nearly twice as many; at 0.3 the rows took 5-15 % more.
constexpr Real kProjectedStep = 0.1;
constexpr std::size_t kCoarseBlock = 4096;  // particles a block of the sums by cell

}  // namespace

PressureDFSPH::PressureDFSPH(const PressureSettings& settings, ParticleSet& particles)
    : m_settings(settings), m_pressure(&particles.add(attribute::kPressureWarmStart)) {}

template <class T, class Term, class Join>
T PressureDFSPH::rates(const StepContext& ctx, const ParticleSet& particles, const std::vector<Vec3>& u,
                       bool withBodies, std::vector<Real>& out, T zero, Term term, Join join) {
    const std::size_t n = particles.size();
    m_velocityRows.resize(n);
    forEachBlock(n, [&](std::size_t begin, std::size_t end) {
        sweeps::toRows(begin, end, u.data(), m_velocityRows.data());
    });
    return ratesOfRows(ctx, n, withBodies, out, zero, term, join);
}

template <class T, class Term, class Join>
T PressureDFSPH::ratesOfRows(const StepContext& ctx, std::size_t n, bool withBodies, std::vector<Real>& out, T zero,
                             Term term, Join join) const {
    out.resize(n);
    return deterministicBlockReduce<T>(n, [&](std::size_t begin, std::size_t end) {
        sweeps::densityRate(begin, end, {&ctx.fluidNeighbours, m_weights.data()}, m_boundarySum.data(),
                            withBodies ? m_bodyRate.data() : nullptr, ctx.positionRows.data(), m_velocityRows.data(),
                            out.data());
        T s = zero;
        for (std::size_t i = begin; i < end; ++i) s = join(s, term(i));
        return s;
    }, zero, join);
}

void PressureDFSPH::velocityChanges(const StepContext& ctx, const ParticleSet& particles, const std::vector<Real>& s,
                                    std::vector<Vec3>& out, bool rows, std::vector<Vec3>* velocities) {
    out.resize(particles.size());
    if (rows) m_velocityRows.resize(particles.size());
    forEachBlock(particles.size(), [&](std::size_t begin, std::size_t end) {
        sweeps::pressureChange(begin, end, {&ctx.fluidNeighbours, m_weights.data()}, m_boundarySum.data(),
                               ctx.positionRows.data(), s.data(), ctx.dt, out.data(),
                               rows ? m_velocityRows.data() : nullptr);
        if (velocities)
            for (std::size_t i = begin; i < end; ++i) (*velocities)[i] += out[i];
    });
}

void PressureDFSPH::computeFactors(const StepContext& ctx, const ParticleSet& particles, bool mayRebuild) {
    const std::size_t n = particles.size();
    m_factor.resize(n);
    const auto& x = particles.x();
    const auto& m = particles.mass();
    const auto& f = ctx.fluidNeighbours;
    const auto& b = ctx.boundaryNeighbours;
    const Real h4 = std::pow(ctx.kernel.supportRadius(), 4);
    resizeForRefill(m_weights, f.pairs());
    resizeForRefill(m_boundaryWeights, b.pairs());
    m_boundarySum.resize(n);
    m_bodyRate.resize(n);
    m_gradientSum.resize(n);
    forEachBlock(n, [&](std::size_t begin, std::size_t end) {
        thread_local sweeps::Rows fluidSums;
        fluidSums.resize(end - begin);
        sweeps::pressureWeights(begin, end, f, ctx.positionRows.data(), ctx.gradients.fluid.data(), m.data(),
                                m_weights.data(), fluidSums.data());
        for (std::size_t i = begin; i < end; ++i) {
            Vec3 sum = fluidSums[i - begin].head<3>();
            const Real squares = fluidSums[i - begin][3];
            Vec3 boundary = Vec3::Zero();
            Real bodies = 0;
            for (std::size_t p = b.first(i); p < b.last(i); ++p) {
                const std::uint32_t k = b.indices[p];
                m_boundaryWeights[p] = kWall * ctx.restDensity[i] * ctx.boundary.volume[k] * ctx.gradients.boundary[p];
                const Vec3 g = m_boundaryWeights[p] * (x[i] - ctx.boundary.x[k]);
                boundary += g;
                bodies += ctx.boundary.v[k].dot(g);
            }
            m_boundarySum[i] = boundary;
            m_bodyRate[i] = bodies;
            sum += boundary;
            m_gradientSum[i] = sum;
            const Real denominator = sum.squaredNorm() + squares;
            // Particles with (almost) no neighbours get no pressure: a lone particle cannot be compressed.
            const Real scale = m[i] / h4;
            m_factor[i] = denominator > 1e-8 * scale * scale ? 1 / denominator : 0;
        }
    });
    if (m_settings.solver != PressureSettings::Solver::Mprgp || std::int64_t(n) < m_settings.coarseFrom) {
        m_coarse.clear();
    } else if (mayRebuild && (!m_coarse.active() || ctx.step >= m_coarseBuilt + kCoarseRebuild)) {
        const Real h = ctx.kernel.supportRadius();
        m_coarse.build(x, m, f, m_weights, ctx.positionRows, m_gradientSum, kCoarseCell * h, h, kCoarseMaxCells);
        m_coarseBuilt = ctx.step;
    } else {
        m_coarse.assign(x);
    }
}

void PressureDFSPH::save(ByteWriter& out) const {
    out(m_coarseBuilt);
    m_coarse.save(out);
}

void PressureDFSPH::restore(ByteReader& in) {
    in(m_coarseBuilt);
    m_coarse.restore(in);
}

void PressureDFSPH::applyWarmStart(StepContext& ctx, ParticleSet& particles, Real scale, Real support) {
    auto& s = *m_pressure;
    auto& v = particles.v();
    // A particle well below its rest density has come apart from its neighbours, and the pressure it held last step
    // can only push them further apart: see kSeparated. The same pass counts the particles that move as one body.
    const std::vector<Real>* rigid = particles.find(attribute::kViscouslyRigid);
    const std::size_t rigidCount = deterministicSum<std::size_t>(particles.size(), [&](std::size_t i) {
        s[i] = ctx.density[i] < (1 - kSeparated) * ctx.restDensity[i] ? 0 : s[i] * scale;
        return std::size_t(rigid && (*rigid)[i] != 0);
    });
    // On a body the viscosity solve moves as one, the warm start's push is spread over the whole body before the
    // constant-density solve can revise it, and that solve, acting after viscosity, can take it back only where
    // particles touch. Reapplied whole after a landing, it bounced a 1e6 Pa s block off the floor at 0.40 m/s
    // (0.68 at 8x the particles) after it landed at 0.93. There the warm start is scaled so that its net push on
    // those particles is at most their weight over the step, what holds a resting body up: the block lands and stays
    // (at twice the weight it still rocked at up to 7 cm/s; capping each particle's own push instead let the block
    // sink at 1-3 cm/s, since a rigid body's support sits in its contact layer).
    if (rigidCount == 0) {
        velocityChanges(ctx, particles, s, m_velocityChange, false, &v);
    } else {
        velocityChanges(ctx, particles, s, m_velocityChange);
        // The net push on those particles (pressures between them cancel: what is left is the walls' and the other
        // particles' push) against their weight.
        using Vec4 = Eigen::Matrix<Real, 4, 1>;
        const auto& m = particles.mass();
        const Vec4 sums = deterministicSum<Vec4>(particles.size(), [&](std::size_t i) {
            if ((*rigid)[i] == 0) return Vec4(Vec4::Zero());
            const Vec3 p = m[i] * m_velocityChange[i];
            return Vec4(p.x(), p.y(), p.z(), m[i] * support);
        }, Vec4::Zero());
        const Real push = sums.head<3>().norm(), limit = sums[3];
        if (push > limit) {
            const Real alpha = limit / push;
            forEachParticle(particles.size(), [&](std::size_t i) { if ((*rigid)[i] != 0) s[i] *= alpha; });
            velocityChanges(ctx, particles, s, m_velocityChange);
        }
        forEachParticle(particles.size(), [&](std::size_t i) { v[i] += m_velocityChange[i]; });
    }
    addBoundaryLoads(ctx, particles, s);
}

bool PressureDFSPH::finished(StepContext& ctx, Solve which, std::size_t iteration, Real error) const {
    const bool density = which == Solve::Density;
    const Real tolerance = density ? m_settings.densityError : m_settings.divergenceError;
    // After an impact's constant-density solve the divergence-free solve takes at least two (impactIterations).
    const bool impact = ctx.stats.lastPressureIterations > std::size_t(m_settings.impactIterations);
    const std::int64_t fewest = density ? m_settings.minIterations
                                        : std::max<std::int64_t>(m_settings.minDivergenceIterations, impact ? 2 : 0);
    const bool converged = error <= tolerance;
    // A residual at round-off (a falling body, particles apart from each other) leaves nothing to solve; the fewest
    // iterations are for residuals that the tolerance only just admits. Free-falling anchor blocks spent three to four
    // products a step on residuals of 1e-16.
    if (error <= kRoundOff * tolerance) return true;
    if (converged && iteration >= std::size_t(fewest)) return true;
    if (iteration < std::size_t(m_settings.maxIterations)) return false;
    if (!converged) {
        ++(density ? ctx.stats.pressureCapHits : ctx.stats.divergenceCapHits);
        ctx.stats.warn(fmt::format("step {}: {} solve stopped at {} iterations (mean error {:.3g} > {:.3g}); lower "
                                   "simulation.time_step.max or raise simulation.pressure.max_iterations",
                                   ctx.step, density ? "constant-density" : "divergence-free", iteration, error,
                                   tolerance));
    }
    return true;
}

template <class Target>
std::size_t PressureDFSPH::solveJacobi(Solve which, StepContext& ctx, ParticleSet& particles,
                                       std::vector<Real>& pressure, Target target) {
    const std::size_t n = particles.size();
    const Real dt = ctx.dt;
    auto& v = particles.v();
    m_error.resize(n);
    m_change.resize(n);
    std::size_t iteration = 0;
    for (;; ++iteration) {
        const Real error = rates(ctx, particles, v, true, m_rate, Real(0), [&](std::size_t i) {
            m_error[i] = target(i, m_rate[i]);  // signed density error to remove [kg/m^3]
            // Complementarity residual: a particle under pressure must sit at rest density (an expanding one
            // is pushed too hard); one without pressure may only be too light.
            return (pressure[i] > 0 ? std::abs(m_error[i]) : std::max<Real>(m_error[i], 0)) / ctx.restDensity[i];
        }, std::plus<Real>()) / Real(n);
        if (finished(ctx, which, iteration, error)) return iteration;
        // Projected Jacobi step: the pressure of a particle never goes below zero.
        forEachParticle(n, [&](std::size_t i) {
            const Real next = std::max<Real>(pressure[i] + kRelaxation * m_error[i] * m_factor[i] / (dt * dt), 0);
            m_change[i] = next - pressure[i];
            pressure[i] = next;
        });
        velocityChanges(ctx, particles, m_change, m_velocityChange, false, &v);
    }
}

template <class Target>
std::size_t PressureDFSPH::solveMprgp(Solve which, StepContext& ctx, ParticleSet& particles,
                                      std::vector<Real>& pressure, Target target) {
    // The solve as a bound-constrained quadratic program: with e(s) = b - dt^2 A s the density error to remove
    // (A = J J^T, J the density rate of a velocity field, -dt J^T the velocity change of pressures), find s >= 0
    // with e <= 0 and s_i e_i = 0; its gradient is G = -e. MPRGP (Dostal & Schoeberl 2005, "Minimizing quadratic
    // functions subject to bound constraints with the rate of convergence and finite termination"): conjugate
    // gradient steps on the particles under pressure, a projected step when a step would make a pressure negative
    // (the gradient's, or the conjugate step's own where the bound stops it early: kProjectedStep), and proportioning
    // steps that give pressure to particles their neighbours compress (in a fluid, projected gradient steps over
    // every particle: see the proportioning branch). The conjugate gradient steps are preconditioned by the DFSPH
    // factor (1 / A_ii) plus, on bodies of many particles, the exact answer within the coarse space's cell-wise
    // constant pressures, both on the particles under pressure. Every product with A costs what one Jacobi sweep does.
    const std::size_t n = particles.size();
    const Real dt2 = ctx.dt * ctx.dt;
    const auto& rho0 = ctx.restDensity;
    auto& v = particles.v();
    auto& e = m_error;
    auto& dir = m_direction;
    auto& q = m_product;
    auto& z = m_change;
    auto& dv = m_velocityChange;
    for (auto* a : {&e, &dir, &q, &z}) a->resize(n);  // each is written in full before it is read
    dv.resize(n);
    std::size_t products = 0;
    // dt^2 A d = -dt J dv with dv = -dt J^T d the velocity change of the pressures d: the sweeps leave J dv in q, and
    // the rate sweep's blocks scale it and go on to term(i), joined into what the next decision needs. Every pass over
    // the particles takes what it can: at 8k particles the vector passes around the sweeps cost about as much as the
    // sweeps when each had its own loop.
    auto multiplyAnd = [&](const std::vector<Real>& d, auto zero, auto term, auto join) {
        velocityChanges(ctx, particles, d, dv, true);
        ++products;
        return ratesOfRows(ctx, n, false, q, zero, [&](std::size_t i) {
            q[i] *= -ctx.dt;
            return term(i);
        }, join);
    };
    // D_i = dt^2 A_ii; particles without neighbours (factor 0) take no pressure.
    auto inverseD = [&](std::size_t i) { return m_factor[i] / dt2; };
    // Moves particle i's pressure by -alpha d_i, d being the direction whose product is in q and dv.
    auto moveOne = [&](std::size_t i, Real alpha, const std::vector<Real>& d) {
        pressure[i] = std::max<Real>(pressure[i] - alpha * d[i], 0);  // the max: round-off at the bound
        e[i] += alpha * q[i];
        v[i] -= alpha * dv[i];
    };
    // Gradient on the particles under pressure (free), and on those at zero pressure that want some (chopped).
    auto free = [&](std::size_t i) { return pressure[i] > 0 ? -e[i] : Real(0); };
    auto chopped = [&](std::size_t i) {
        return pressure[i] > 0 || m_factor[i] == 0 ? Real(0) : std::min<Real>(-e[i], 0);
    };
    // Particle i's share of what the next iteration decides on: the complementarity residual of the Jacobi solver
    // (|projected gradient| relative to rho_0; counting only compression, SPlisHSPlasH's test, takes 37 % fewer
    // iterations on the 50k anchor block, but a honey column at rest then jitters at 1.9 cm/s instead of 0.3 and
    // sits 6x more compressed at the same 0.01 %), the chopped gradient's energy, and how far the free particles
    // can still move.
    auto measure = [&](std::size_t i) {
        const Real f = free(i), c = chopped(i), d = inverseD(i);
        const Real room = pressure[i] > 0 ? std::min(pressure[i] / (kRelaxation * d), f) * f * d : Real(0);
        return Vec3(std::abs(f + c) / rho0[i], c * c * d, room);
    };
    // Whether some particles move as one viscous body (see the proportioning below), counted at a solve's first
    // proportioning rather than in every solve.
    int bodies = -1;
    auto anyBodies = [&] {
        if (bodies < 0) {
            const std::vector<Real>* rigid = particles.find(attribute::kViscouslyRigid);
            bodies = rigid && deterministicSum<std::size_t>(n, [&](std::size_t i) {
                return std::size_t((*rigid)[i] != 0);
            }) > 0;
        }
        return bodies == 1;
    };
    // Particle i's change in a projected gradient step along the gradient g: the step Jacobi takes, kept >= 0.
    auto gradientStep = [&](std::size_t i, Real g) {
        return pressure[i] - std::max<Real>(pressure[i] - kRelaxation * inverseD(i) * g, 0);
    };
    // Moves every pressure by z (the pressures' change) and measures after it: one product.
    auto moveByZ = [&] {
        return multiplyAnd(z, Vec3(Vec3::Zero()), [&](std::size_t i) {
            moveOne(i, 1, z);
            return measure(i);
        }, std::plus<Vec3>());
    };
    // Proportioning threshold Gamma, by how far the mean residual is from the tolerance. The test weighs the chopped
    // gradient's energy against the whole fluid's, so at Gamma 1 a particle that its neighbours squeeze while it holds
    // no pressure was not released until the fluid's free gradient had fallen about sqrt(n) times below that
    // particle's: the 50k anchor block's landing left one particle near each bottom edge 0.94 % compressed (the rest
    // at most 0.12 %) while the mean met the 0.01 % tolerance, the 8k block one at 0.55 %. At 0.1 those end at
    // 0.06-0.08 % for the same constant-density iterations. Far from the tolerance conjugate steps must lead: at 0.1
    // throughout, 5 ms steps at high viscosity and 27k particles (Stability.FiveMillisecondStepsAtHighViscosity at
    // GANACHE_STABILITY_REFINE=3) spent their iterations proportioning and reached 715 % compression (3.7 % at 1).
    auto gamma = [&](Real meanResidual) {
        const Real tolerance = which == Solve::Density ? m_settings.densityError : m_settings.divergenceError;
        return meanResidual <= 10 * tolerance ? Real(0.1) : Real(1);
    };

    // The coarse space's part of the preconditioner on the free particles: the free gradient summed by cell over the
    // particles under pressure (q too, with withQ), solved for the cells' pressures. Its directions move whole cells,
    // and where an impact keeps changing which particles hold pressure they run into the bound more often than the
    // diagonal's. With expansions that stopped at the first particle's bound, a honey block landing at 1 m/s took 576
    // products with it against 481 without, so a solve dropped it at its second expansion (435); with the projected
    // steps of kProjectedStep it stays: 372 products against 424 without, 433 when dropped as before (test
    // PressureCoarseSpace.ALandingEndsNearTheConvergedOneInFewerProducts).
    const bool coarse = m_coarse.active();
    // The sums by cell: each fixed block of particles sums the runs of particles from one cell (they lie in the
    // grid's cell order, so a cell's come in a few runs), and the runs are added up in the blocks' order, the same on
    // any thread count.
    const std::size_t blocks = (n + kCoarseBlock - 1) / kCoarseBlock;
    m_coarseRuns.resize(blocks);
    auto coarseSolve = [&](bool withQ) {
        forEachBlock(blocks, [&](std::size_t first, std::size_t last) {
            for (std::size_t b = first; b < last; ++b) {
                auto& runs = m_coarseRuns[b];
                runs.clear();
                for (std::size_t i = b * kCoarseBlock; i < std::min(n, (b + 1) * kCoarseBlock); ++i) {
                    const std::uint32_t c = m_coarse.cellOf(i);
                    if (c == PressureCoarseSpace::kNone || !(pressure[i] > 0)) continue;
                    if (runs.empty() || runs.back().cell != c) runs.push_back({c, 0, 0});
                    runs.back().gradient += free(i);
                    if (withQ) runs.back().q += q[i];
                }
            }
        }, 1);
        m_coarseRhs.setZero(Eigen::Index(m_coarse.cells()));
        if (withQ) m_coarseQ.setZero(Eigen::Index(m_coarse.cells()));
        for (const auto& runs : m_coarseRuns)
            for (const CoarseRun& r : runs) {
                m_coarseRhs[r.cell] += r.gradient;
                if (withQ) m_coarseQ[r.cell] += r.q;
            }
        m_coarse.solve(m_coarseRhs);
        m_coarseRhs /= dt2;
    };
    auto coarseAt = [&](std::size_t i) {
        if (!coarse) return Real(0);
        const std::uint32_t c = m_coarse.cellOf(i);
        return c != PressureCoarseSpace::kNone && pressure[i] > 0 ? m_coarseRhs[c] : Real(0);
    };

    Vec3 measured = rates(ctx, particles, v, true, m_rate, Vec3(Vec3::Zero()), [&](std::size_t i) {
        e[i] = target(i, m_rate[i]);
        return measure(i);
    }, std::plus<Vec3>());
    bool restart = true;
    std::size_t iteration = 0;
    for (;;) {
        const Real error = measured[0] / Real(n);
        if (finished(ctx, which, iteration, error)) break;
        ++iteration;
        // Proportional: the chopped gradient is small against what the free particles can still move.
        const Real g = gamma(error);
        if (measured[1] > g * g * measured[2]) {
            // Proportioning: release the particles at zero pressure that their neighbours compress. In a fluid, by a
            // projected gradient step over every particle (Jacobi's), which also moves the particles under pressure
            // in the same product. MPRGP's own step moves only the released ones (along the chopped gradient, to the
            // line's minimum) and leaves the rest to the conjugate steps after it, which a free surface's changing
            // contacts then stop at the bound: the buckling anchor took 3.9 constant-density products a step that
            // way, 3.2 this way, and the landing of PressureCoarseSpace.ALandingEndsNearTheConvergedOneInFewerProducts
            // 14-21 % fewer at each tolerance from 1e-4 to 2e-5 (5-24 % with the coarse space), ending as near the
            // converged one. Where particles move as one viscous body MPRGP's own step stays: the gradient steps
            // leave a rougher pressure where the solve stops, which a stiff body shows as creep (the study's stiff_arm
            // deformed at 0.076 / 0.0057 mm/s against 0.062 / 0.0030 at stiff_tolerance 1e-4 / 1e-5, where its figure
            // does not move with round-off as it does at the default tolerances; docs/benchmarks.md).
            if (!anyBodies()) {
                forEachParticle(n, [&](std::size_t i) { z[i] = gradientStep(i, free(i) + chopped(i)); });
                measured = moveByZ();
            } else {
                forEachParticle(n, [&](std::size_t i) { z[i] = inverseD(i) * chopped(i); });
                using Vec2 = Eigen::Matrix<Real, 2, 1>;
                const Vec2 zq = multiplyAnd(z, Vec2(Vec2::Zero()), [&](std::size_t i) {
                    return Vec2(z[i] * q[i], chopped(i) * z[i]);
                }, std::plus<Vec2>());
                if (!(zq[0] > 0)) break;
                measured = deterministicSum<Vec3>(n, [&](std::size_t i) {
                    moveOne(i, zq[1] / zq[0], z);
                    return measure(i);
                }, Vec3::Zero());
            }
            restart = true;
            continue;
        }
        if (restart) {
            if (coarse) coarseSolve(false);
            forEachParticle(n, [&](std::size_t i) { dir[i] = inverseD(i) * free(i) + coarseAt(i); });
        }
        restart = false;
        // d . q, free . d, and the longest step that keeps every pressure >= 0.
        struct Sums {
            Real dq = 0, fd = 0, feasible = std::numeric_limits<Real>::infinity();
        };
        const Sums sums = multiplyAnd(
            dir, Sums{},
            [&](std::size_t i) {
                return Sums{dir[i] * q[i], free(i) * dir[i],
                            dir[i] > 0 ? pressure[i] / dir[i] : std::numeric_limits<Real>::infinity()};
            },
            [](const Sums& a, const Sums& b) {
                return Sums{a.dq + b.dq, a.fd + b.fd, std::min(a.feasible, b.feasible)};
            });
        if (!(sums.dq > 0)) break;  // nothing left to move
        const Real step = sums.fd / sums.dq;
        if (step <= sums.feasible) {
            // z = D^-1 free after the move, and beta = z . q / d . q for the next conjugate direction; what the next
            // iteration decides on does not depend on the direction, so it is measured in the same pass.
            using Vec4 = Eigen::Matrix<Real, 4, 1>;
            const Vec4 zqMeasured = deterministicSum<Vec4>(n, [&](std::size_t i) {
                moveOne(i, step, dir);
                z[i] = inverseD(i) * free(i);
                const Vec3 m = measure(i);
                return Vec4(z[i] * q[i], m[0], m[1], m[2]);
            }, Vec4::Zero());
            Real zq = zqMeasured[0];
            if (coarse) {
                coarseSolve(true);
                zq += m_coarseRhs.dot(m_coarseQ);
            }
            const Real beta = zq / sums.dq;
            measured = zqMeasured.tail<3>();
            forEachParticle(n, [&](std::size_t i) { dir[i] = z[i] + coarseAt(i) - beta * dir[i]; });
        } else {
            // Expansion; conjugate directions start again. Where the bound stops the step early, the whole step with
            // the pressures it would make negative set to zero (kProjectedStep); otherwise up to the bound, then a
            // projected gradient step. Either way z is the pressures' change, and its product updates e and v.
            // Unlike the gradient step, the projected conjugate one is not proven to lower the solve's energy; it did
            // in every one of the 1,800 taken in Table 2's rows and step_bench's 1M blob (e.z + z.q / 2 < 0).
            if (sums.feasible < kProjectedStep * step) {
                forEachParticle(n, [&](std::size_t i) {
                    z[i] = pressure[i] - std::max<Real>(pressure[i] - step * dir[i], 0);
                });
            } else {
                forEachParticle(n, [&](std::size_t i) {
                    moveOne(i, sums.feasible, dir);
                    z[i] = gradientStep(i, free(i));
                });
            }
            measured = moveByZ();
            restart = true;
        }
    }
    return products;
}

template <class Target>
std::size_t PressureDFSPH::solve(Solve which, StepContext& ctx, ParticleSet& particles, std::vector<Real>& pressure,
                                 Target target) {
    if (particles.size() == 0) return 0;
    m_start = pressure;
    const std::size_t iterations = m_settings.solver == PressureSettings::Solver::Jacobi
                                       ? solveJacobi(which, ctx, particles, pressure, target)
                                       : solveMprgp(which, ctx, particles, pressure, target);
    // What this solve added to the pressures applied before it.
    forEachParticle(particles.size(), [&](std::size_t i) { m_start[i] = pressure[i] - m_start[i]; });
    addBoundaryLoads(ctx, particles, m_start);
    return iterations;
}

void PressureDFSPH::addBoundaryLoads(StepContext& ctx, const ParticleSet& particles, const std::vector<Real>& s) const {
    // The solve is linear in the pressures and the positions do not move during it, so the impulse the
    // boundaries gave the fluid follows from the final pressures. Sequential: a deterministic sum. A particle whose
    // boundary neighbours are all of one body gives it dt m_i s_i S_i, S_i its pairs' pushes summed once a step.
    const auto& x = particles.x();
    const auto& m = particles.mass();
    const auto& b = ctx.boundaryNeighbours;
    const Real dt = ctx.dt;
    for (std::size_t i = 0; i < particles.size(); ++i) {
        if (s[i] == 0) continue;
        const std::size_t first = b.first(i);
        // Impulse on the body: the opposite of what the body gave particle i.
        ctx.loads.addPushes(ctx.boundary, b.indices.data() + first, b.indices.data() + b.last(i), x[i],
                            (dt * m[i] * s[i]) * m_boundarySum[i], ctx.time + dt, [&](std::size_t n) {
            const std::size_t p = first + n;
            return Vec3((dt * m[i] * s[i] * m_boundaryWeights[p]) * (x[i] - ctx.boundary.x[b.indices[p]]));
        });
    }
}

void PressureDFSPH::solveDensity(StepContext& ctx, ParticleSet& particles) {
    const Real dt = ctx.dt;
    // rho* - rho_0 = rho + dt Drho/Dt - rho_0 [BK17 Eq. 8], of which a rigid particle's compression counts only its
    // share PressureSettings::rigidCorrection.
    const std::vector<Real>* rigid = particles.find(attribute::kViscouslyRigid);
    const Real share = m_settings.rigidCorrection;
    const std::size_t iterations = solve(Solve::Density, ctx, particles, *m_pressure, [&](std::size_t i, Real rate) {
        const Real excess = ctx.density[i] - ctx.restDensity[i];
        if (excess > 0 && rigid && (*rigid)[i] != 0) return share * excess + dt * rate;
        return ctx.density[i] + dt * rate - ctx.restDensity[i];  // summed in this order, runny fluids' bytes stay
    });
    ctx.stats.pressureIterations += iterations;
    ctx.stats.lastPressureIterations = iterations;
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

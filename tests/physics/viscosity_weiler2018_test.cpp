#include "physics/viscosity/viscosity_weiler2018.h"

#include "physics/gravity.h"
#include "random_field.h"

#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <random>
#include <tuple>

using namespace ganache;
using namespace ganache::testing;

namespace {

// SPH strain rate D_i = sym(sum_j (m_j / rho_j) (v_j - v_i) grad W_ij^T), the quantity strain-rate based
// viscosity solvers build on [WKBB18 Sec. 6]; it is not part of ganache's solver.
std::vector<Real> strainRateNorms(const Simulation& sim) {
    const auto& p = sim.particles();
    std::vector<Real> out(p.size());
    for (std::size_t i = 0; i < p.size(); ++i) {
        Mat3 grad = Mat3::Zero();
        for (std::uint32_t j : sim.fluidNeighbours().of(i))
            grad += (p.mass()[j] / sim.density()[j]) * (p.v()[j] - p.v()[i]) *
                    sim.kernel().gradW(p.x()[i] - p.x()[j]).transpose();
        out[i] = (0.5 * (grad + grad.transpose())).norm();
    }
    return out;
}

}  // namespace

TEST(ViscousLaplacian, VanishesForRigidRotationWhileStrainRateDoesNot) {
    // [WKBB18 Fig. 2-3]: on a rigidly rotating block, free surface included, Eq. 7 is zero up to round-off
    // (the paper reports below 1e-12; 1e-10 leaves room for the larger velocities here), whereas the SPH
    // strain rate is far from zero at the surface because of the missing neighbours.
    const Vec3 omega(0.3, 1.0, -0.5);
    const Vec3 vel(0.2, -0.1, 0.4);
    Simulation sim = freeBlock().simulation(withVelocity([&](const Vec3& x) { return Vec3(vel + omega.cross(x)); }));
    const LaplacianWeights weights(ViscosityParams::Laplacian::Lattice, sim.kernel().supportRadius() / 2, sim.kernel());
    const auto lap = viscousLaplacian(weights, sim.particles(), sim.density(), sim.fluidNeighbours(), sim.kernel());
    Real maxLap = 0;
    for (const Vec3& l : lap) maxLap = std::max(maxLap, l.norm());
    EXPECT_LT(maxLap, 1e-10);

    const auto strain = strainRateNorms(sim);
    Real maxStrain = 0;
    for (Real s : strain) maxStrain = std::max(maxStrain, s);
    // |omega| is about 1.2 1/s; a strain rate error of a tenth of it at the surface is "clearly non-zero".
    EXPECT_GT(maxStrain, 0.1 * omega.norm());
    std::printf("max |lap v| = %.3g 1/(m s), max |D| = %.3g 1/s\n", maxLap, maxStrain);
}

namespace {

// Eq. 7's answer to the shear fields v = (n . x)^2 / 2 t along a lattice axis, across a face diagonal and across a
// body diagonal (n, t orthonormal; the exact Laplacian is t), on a lattice block's interior particles (at least h
// from the free surface).
Vec3 shearResponses(ViscosityParams::Laplacian kind) {
    Simulation sim = freeBlock().simulation();
    const Real h = sim.kernel().supportRadius(), inner = 0.12 - 0.01 - h;
    const LaplacianWeights weights(kind, h / 2, sim.kernel());
    auto response = [&](Vec3 n, Vec3 t) {
        n.normalize(), t.normalize();
        ParticleSet p = sim.particles();
        for (std::size_t i = 0; i < p.size(); ++i) p.v()[i] = 0.5 * std::pow(n.dot(p.x()[i]), 2) * t;
        const auto lap = viscousLaplacian(weights, p, sim.density(), sim.fluidNeighbours(), sim.kernel());
        Real lo = INFINITY, hi = -INFINITY;
        for (std::size_t i = 0; i < p.size(); ++i)
            if ((p.x()[i].cwiseAbs().array() < inner).all()) lo = std::min(lo, lap[i].dot(t)), hi = std::max(hi, lap[i].dot(t));
        EXPECT_NEAR(lo, hi, 1e-9 * std::abs(hi));  // a quadratic field: the same answer at every interior site
        return hi;
    };
    return {response(Vec3::UnitY(), Vec3::UnitX()), response(Vec3(1, 1, 0), Vec3(1, -1, 0)),
            response(Vec3(1, 1, 1), Vec3(1, -1, 0))};
}

}  // namespace

TEST(ViscousLaplacian, PaperWeightsOnTheLatticeAreExactOnAverageOverShearDirectionsButNotAlongTheAxes) {
    // Why plane Couette flow between plates parallel to the sampling lattice lags the exact answer (ganache study,
    // couette): for a shear field v = (n . x)^2 / 2 t (n, t orthonormal; exact Laplacian t), Eq. 7 on the lattice
    // (support h = 2 spacings) answers R(n, t) t with R = B + (A - 3B) S, S = sum_a n_a^2 t_a^2, A and B the
    // lattice's fourth moments (x^4 and x^2 y^2) of the pair weights. A continuum has A = 3B; the lattice does not:
    // shear along the axes (S = 0: Couette on the lattice) gets R = 0.70, shear across a face diagonal
    // (S = 1/2) 1.43, yet the mean over all directions, (A + 2B) / 5, is 0.99. Momentum diffuses at 0.7 nu in the
    // Couette case, which the study's 4-5 % RMS error matches (an exact profile at 0.7 nu is 5.6 % off; 0.8 nu,
    // 3.4 %). No constant in place of 2(d+2) cures it: scaled to make Couette exact, every other direction, and
    // the mean, would be 1.43 times too viscous (`laplacian: paper`; the default reshapes the weights, below).
    const Vec3 r = shearResponses(ViscosityParams::Laplacian::Paper);
    const Real axis = r[0], face = r[1], body = r[2];
    std::printf("lattice response to shear: along an axis %.4f, face diagonal %.4f, body diagonal %.4f, mean %.4f\n",
                axis, face, body, (2 * face + 3 * axis) / 5);
    // The operator is the fourth-moment form above: A = 2 face + axis, B = axis, so the body diagonal (S = 1/3)
    // answers A / 3, to round-off.
    EXPECT_NEAR(body, (2 * face + axis) / 3, 1e-9);
    // The mean over directions, (A + 2B) / 5 = (2 face + 3 axis) / 5, is the continuum's Laplacian within the
    // 1-2 % that the 0.01 h^2 in Eq. 7's denominator takes off.
    EXPECT_NEAR((2 * face + 3 * axis) / 5, 1.0, 0.02);
    // Along the axes 30 % weak, across face diagonals 40 % strong: a factor of two between directions.
    EXPECT_LT(axis, 0.75);
    EXPECT_GT(face, 1.35);
}

TEST(ViscousLaplacian, LatticeWeightsAreExactInEveryShearDirection) {
    // The default weights (LaplacianWeights: the paper's times 1 + a u + b u^2, u = |x_ij|^2 / s^2 - 1, scaled on the
    // lattice) make the lattice's fourth moments those of a continuum, A = 3B, so every shear direction gets the
    // exact Laplacian; plane Couette flow between plates along the lattice then diffuses at nu (ganache study,
    // couette: 0.7 % RMS instead of 4.7 %). Round-off bound: the sums are of a few dozen terms of order one.
    const Vec3 r = shearResponses(ViscosityParams::Laplacian::Lattice);
    std::printf("lattice weights' response to shear: along an axis %.6f, face diagonal %.6f, body diagonal %.6f\n",
                r[0], r[1], r[2]);
    for (int d = 0; d < 3; ++d) EXPECT_NEAR(r[d], 1.0, 1e-9);
}

namespace {

SolveOutcome solveWeiler(Real mu, std::int64_t maxIterations,
                         ViscosityParams::Preconditioner preconditioner = ViscosityParams::Preconditioner::Rigid) {
    ViscosityParams params;
    params.mu = mu;
    params.tolerance = 1e-10;
    params.maxIterations = maxIterations;
    params.preconditioner = preconditioner;
    return solveRandomField(params);
}

}  // namespace

TEST(ViscosityWeiler2018, SolveConservesLinearAndAngularMomentum) {
    // R1: a random velocity field, one implicit solve at a large viscosity. Pair forces are equal, opposite
    // and along x_ij, so both momenta are kept to the solver tolerance.
    const SolveOutcome o = solveWeiler(1000, 1000);
    EXPECT_LT(o.momentumChange, 1e-8);
    EXPECT_LT(o.angularChange, 1e-8);
    EXPECT_LT(o.kineticKept, 0.5) << "viscosity must dissipate a random field";
    EXPECT_GT(o.iterations, 0u);
    EXPECT_EQ(o.capHits, 0u);
}

TEST(ViscosityWeiler2018, CappedSolveStillConservesMomentum) {
    // A stiff fluid (5e6 Pa s, the chocolate preset) whose solve stops at its cap: the rigid part of the
    // residual is solved exactly at the end, so the momenta are kept to round-off (1e-10 of their scale) with
    // either preconditioner. Without that, capped solves let a solid bunny on a slipping floor spin itself up.
    for (auto preconditioner : {ViscosityParams::Preconditioner::BlockJacobi, ViscosityParams::Preconditioner::Rigid}) {
        const SolveOutcome o = solveWeiler(5e6, 3, preconditioner);
        EXPECT_EQ(o.capHits, 1u);
        EXPECT_LT(o.momentumChange, 1e-10);
        EXPECT_LT(o.angularChange, 1e-10);
        EXPECT_LT(o.kineticKept, 1.0);
    }
}

TEST(ViscosityWeiler2018, PreconditionerAndWarmStartCutIterations) {
    // [WKBB18 Sec. 4]: block Jacobi about halves the CG iterations, the warm start v_df + dv cuts them about
    // 8x. Measured on a viscous cube spinning in zero gravity (Fig. 5), where the solve works every step. ganache adds
    // rigid motions as a coarse space (two-level), of the whole fluid or (its default) of each cluster: the whole
    // fluid's must cut the iterations (10.6 against 13.5 a solve when measured; CG without them takes 13.5, which is
    // what this catches), the clusters may take no more.
    using P = ViscosityParams::Preconditioner;
    auto iterationsWith = [](P preconditioner, bool warmStart) {
        World world(0.01);
        world.setup.timeStep.fixedDt = 0.002;
        world.block(Vec3::Constant(-0.1), Vec3::Constant(0.1));
        ViscosityParams& v = world.effect<ViscosityParams>("viscosity");
        v.mu = 10000;
        v.tolerance = 1e-6;
        v.maxIterations = 2000;
        v.preconditioner = preconditioner;
        v.warmStart = warmStart;
        Simulation sim = world.simulation(withVelocity([](const Vec3& x) { return Vec3(Vec3(0, 0, 2).cross(x)); }));
        sim.advanceTo(0.05);
        EXPECT_EQ(sim.counter("viscosity", "cap_hits"), 0);
        return sim.counter("viscosity", "iterations_per_solve");
    };
    const double plain = iterationsWith(P::None, false);
    const double jacobi = iterationsWith(P::BlockJacobi, false);
    const double both = iterationsWith(P::BlockJacobi, true);
    const double rigid = iterationsWith(P::Rigid, true);
    const double clusters = iterationsWith(P::Clusters, true);
    std::printf("CG iterations per solve: none %.1f, block Jacobi %.1f (%.2fx), + warm start %.1f (%.2fx), + rigid "
                "coarse space %.1f (%.2fx), + clusters' rigid motions instead %.1f (%.2fx)\n",
                plain, jacobi, plain / jacobi, both, jacobi / both, rigid, both / rigid, clusters, both / clusters);
    EXPECT_LT(jacobi, plain);
    EXPECT_LT(both, jacobi);
    EXPECT_LT(rigid, both);
    EXPECT_LE(clusters, rigid);
}

TEST(ViscosityWarmStart, LeastEnergyGuessIsNoWorseThanAnyFixedExtrapolation) {
    // leastEnergyGuess minimises E(x) = x.Mx / 2 - b.x over x = v + a d1 + c d2, so its residual b - Mx is orthogonal
    // to d1 and d2 and E is at most that of v, of the paper's warm start v + d1 and of the extrapolations from d1 and
    // d2 (E differs from the squared M-norm distance to the solution by a constant). Also where d2 is parallel to d1.
    constexpr int kParticles = 6, kSize = 3 * kParticles;
    std::mt19937_64 rng(7);
    std::normal_distribution<Real> normal(0, 1);
    Eigen::MatrixXd spread(kSize, kSize);
    for (int r = 0; r < kSize; ++r)
        for (int c = 0; c < kSize; ++c) spread(r, c) = normal(rng);
    const Eigen::MatrixXd m = Eigen::MatrixXd::Identity(kSize, kSize) + spread.transpose() * spread;
    auto field = [&] {
        std::vector<Vec3> f(kParticles);
        for (auto& x : f) x = Vec3(normal(rng), normal(rng), normal(rng));
        return f;
    };
    auto flat = [](const std::vector<Vec3>& f) {
        return Eigen::Map<const Eigen::VectorXd>(f[0].data(), kSize).eval();
    };
    auto times = [&](const std::vector<Vec3>& f) {
        std::vector<Vec3> out(kParticles);
        Eigen::Map<Eigen::VectorXd>(out[0].data(), kSize) = m * flat(f);
        return out;
    };
    const std::vector<Vec3> b = field(), v = field(), d1 = field();
    auto energy = [&](Real a, const std::vector<Vec3>& d2, Real c) {
        std::vector<Vec3> x(kParticles);
        for (int i = 0; i < kParticles; ++i) x[i] = v[i] + a * d1[i] + c * d2[i];
        return 0.5 * flat(x).dot(m * flat(x)) - flat(b).dot(flat(x));
    };
    std::vector<Vec3> parallel(kParticles);
    for (int i = 0; i < kParticles; ++i) parallel[i] = 2 * d1[i];
    for (const std::vector<Vec3>& d2 : {field(), parallel}) {
        std::vector<Vec3> x(kParticles), mx(kParticles);
        leastEnergyGuess(b, v, times(v), d1, times(d1), d2, times(d2), x, mx);
        const Eigen::VectorXd residual = flat(b) - m * flat(x);
        const Real scale = flat(b).norm() + (m * flat(v)).norm();
        EXPECT_LT(std::abs(residual.dot(flat(d1))) / flat(d1).norm(), 1e-12 * scale);
        EXPECT_LT(std::abs(residual.dot(flat(d2))) / flat(d2).norm(), 1e-12 * scale);
        EXPECT_LT((flat(mx) - m * flat(x)).norm(), 1e-12 * scale);
        const Real e = 0.5 * flat(x).dot(m * flat(x)) - flat(b).dot(flat(x));
        for (const auto& [a, c] : {std::pair{0.0, 0.0}, {1.0, 0.0}, {1.5, -0.5}, {2.0, -1.0}})
            EXPECT_LE(e, energy(a, d2, c) + 1e-12 * std::abs(e));
    }
}

TEST(ViscosityWeiler2018, DifferingViscositiesSolveToTheStiffTolerance) {
    // Two runny fluids side by side landing on a floor: no particle is stiff, so a single fluid's solves stop at
    // `tolerance` (1e-2), but where viscosities differ the correction is concentrated on the more viscous particles and
    // the solves aim at `stiff_tolerance` (1e-3): at 1e-2 the default scene's molten film threw particles at up to 0.7
    // m/s (docs/paper.md).
    auto worstResidual = [](Real secondMu) {
        World world(0.005);
        Material thick = preset("honey"), thin = preset("honey");
        thick.mu = 100;
        thin.mu = secondMu;
        world.block(Vec3(0, 0.01, 0), Vec3(0.05, 0.06, 0.1), thick, 20, Vec3(0, -1, 0));
        world.block(Vec3(0.05, 0.01, 0), Vec3(0.1, 0.06, 0.1), thin, 20, Vec3(0, -1, 0));
        world.plane("floor");
        world.effect<GravityParams>("gravity");
        world.effect<ViscosityParams>("viscosity");
        Simulation sim = world.simulation();
        sim.advanceTo(0.05);
        const double worst = sim.counter("viscosity", "worst_residual");
        std::printf("second fluid %g Pa s: worst residual %.3g\n", secondMu, worst);
        return worst;
    };
    const ViscosityParams defaults;
    const double same = worstResidual(100), differing = worstResidual(10);
    EXPECT_GT(same, defaults.stiffTolerance);
    EXPECT_LE(same, defaults.tolerance);
    EXPECT_LE(differing, defaults.stiffTolerance);
}

TEST(ViscosityWeiler2018, SpinningCubeKeepsItsAngularMomentum) {
    // R1, Fig. 5: a very viscous cube spinning in zero gravity turns as a rigid body; the Laplacian of Eq. 7
    // is zero for rigid rotation, so viscosity takes nothing from it. The bound: >= 99 % after 0.5 s;
    // the upper bound catches a gain (the warm start at a loose CG tolerance once added 1.9 %).
    World world(0.01);
    world.block(Vec3::Constant(-0.1), Vec3::Constant(0.1));
    world.effect<ViscosityParams>("viscosity").mu = 10000;
    Simulation sim = world.simulation(withVelocity([](const Vec3& x) { return Vec3(Vec3(0, 2, 0).cross(x)); }));
    const Vec3 l0 = angularMomentum(sim.particles());
    sim.advanceTo(0.5);
    const Vec3 l1 = angularMomentum(sim.particles());
    std::printf("angular momentum kept after 0.5 s: %.4f (%zu steps)\n", l1.dot(l0) / l0.squaredNorm(), sim.stats().steps);
    EXPECT_NEAR(l1.dot(l0) / l0.squaredNorm(), 1.0, 0.01);
    EXPECT_EQ(sim.particles().size(), std::size_t(1000));
}

TEST(Effects, OnlyWhatTheSceneAsksForExists) {
    // Inviscid: the viscosity stage is empty and no viscosity array exists.
    World inviscid = freeBlock();
    inviscid.effect<GravityParams>("gravity");
    Simulation a = inviscid.simulation();
    a.step();
    EXPECT_EQ(a.particles().findVector("_viscosity_dv"), nullptr);
    EXPECT_EQ(a.particles().find(attribute::kViscosity), nullptr);
    // No emitters: none built, nothing timed, nothing reported.
    EXPECT_EQ(a.effectNames(), std::vector<std::string>{"gravity"});
    EXPECT_EQ(a.findEffect<Emitters>(), nullptr);
    EXPECT_EQ(a.effectSummaries().size(), 1u);

    // One viscosity for every fluid: the warm-start array, but no per-particle viscosity.
    World viscous = freeBlock();
    viscous.effect<ViscosityParams>("viscosity");
    Simulation b = viscous.simulation();
    b.step();
    EXPECT_NE(b.particles().findVector("_viscosity_dv"), nullptr);
    EXPECT_EQ(b.particles().find(attribute::kViscosity), nullptr);
    EXPECT_EQ(b.counter("viscosity", "solves"), 1.0);  // one per step (ganache's order)

    // Two fluids of different viscosity: each particle carries its own.
    World mixed(0.01);
    mixed.block(Vec3(0, 0, 0), Vec3(0.1, 0.1, 0.1), preset("honey"));
    mixed.block(Vec3(0.2, 0, 0), Vec3(0.3, 0.1, 0.1), preset("molten_chocolate"));
    mixed.effect<ViscosityParams>("viscosity");
    Simulation c = mixed.simulation();
    const std::vector<Real>* mu = c.particles().find(attribute::kViscosity);
    ASSERT_NE(mu, nullptr);
    const std::vector<Real>& fluid = *c.particles().find(attribute::kFluid);
    for (std::size_t i = 0; i < mu->size(); ++i) EXPECT_EQ((*mu)[i], fluid[i] == 0 ? 10.0 : 100.0);
}

TEST(Simulation, SameIterationsAndResultsForAnyThreadCount) {
    auto run = [](int threads) {
        tbb::global_control c(tbb::global_control::max_allowed_parallelism, std::size_t(threads));
        World world(0.01, Vec3(-0.3, -0.1, -0.3), Vec3(0.3, 0.5, 0.3));
        world.block(Vec3(-0.06, 0.05, -0.06), Vec3(0.06, 0.17, 0.06));
        world.plane("floor");
        world.effect<GravityParams>("gravity");
        world.effect<ViscosityParams>("viscosity").mu = 1000;
        Simulation sim = world.simulation();
        sim.advanceTo(0.05);
        return std::make_tuple(sim.stats(), sim.counter("viscosity", "iterations_per_solve"), sim.particles().x());
    };
    const auto [s1, v1, x1] = run(1);
    const auto [s2, v2, x2] = run(2);
    EXPECT_EQ(s1.steps, s2.steps);
    EXPECT_EQ(s1.pressureIterations, s2.pressureIterations);
    EXPECT_EQ(s1.divergenceIterations, s2.divergenceIterations);
    EXPECT_EQ(v1, v2);
    ASSERT_EQ(x1.size(), x2.size());
    for (std::size_t i = 0; i < x1.size(); ++i) EXPECT_EQ(x1[i], x2[i]) << "particle " << i;
}

TEST(Simulation, LoneParticleAndPairStayFinite) {
    // A particle with no neighbours gets no pressure (its DFSPH factor is zero) and falls onto the floor,
    // which stops it; a pair likewise. Every value stays finite and nothing goes through the floor.
    World world(0.01, Vec3(-0.5, -0.1, -0.5), Vec3(0.5, 1, 0.5));
    world.block(Vec3(0, 0.2, 0), Vec3(0.02, 0.22, 0.02));
    world.block(Vec3(0.3, 0.1, 0), Vec3(0.34, 0.12, 0.02));
    world.plane("floor");
    world.effect<GravityParams>("gravity");
    world.effect<ViscosityParams>("viscosity").mu = 100;
    Simulation sim = world.simulation();
    ASSERT_EQ(sim.particles().size(), 3u);
    sim.advanceTo(0.5);
    EXPECT_EQ(sim.particles().size(), 3u);
    for (std::size_t i = 0; i < 3; ++i) {
        EXPECT_TRUE(sim.particles().x()[i].allFinite());
        EXPECT_GT(sim.particles().x()[i].y(), 0.0) << "particle " << i << " went through the floor";
    }
}

TEST(ViscosityWeiler2018, SameSpreadForStepsFrom5To005Milliseconds) {
    // R3, Fig. 9: a honey blob (mu = 20 Pa s, runny enough to spread to about twice its width) slumping on a
    // floor, with fixed dt = 5, 0.5 and 0.05 ms: at t = 0.3 s the extent (RMS radius) agrees within the issue's
    // 5 %. With the paper's step order (viscosity_coupling: paper) dt = 5 ms spreads 12 % further
    // (0.057 m against 0.051 m), ganache's order 0.7 %. Heights are not
    // compared: the pancake is two or three particles thick, and its height moves with the compression near the
    // floor rather than with the spreading.
    auto spreadAt = [](Real dt) {
        World world(0.005, Vec3(-0.3, -0.1, -0.3), Vec3(0.3, 0.3, 0.3));
        world.block(Vec3(-0.03, 0.011, -0.03), Vec3(0.03, 0.071, 0.03), preset("honey"));
        world.plane("floor");
        world.effect<GravityParams>("gravity");
        world.effect<ViscosityParams>("viscosity").mu = 20;
        world.setup.timeStep.fixedDt = dt;
        Simulation sim = world.simulation();
        sim.advanceTo(0.3);
        Real r2 = 0;
        for (const Vec3& x : sim.particles().x()) r2 += x.x() * x.x() + x.z() * x.z();
        return std::sqrt(r2 / Real(sim.particles().size()));
    };
    const auto fine = spreadAt(5e-5);
    for (Real dt : {5e-3, 5e-4}) {
        const auto coarse = spreadAt(dt);
        std::printf("dt %g s: RMS radius %.4f m (finest %.4f)\n", dt, coarse, fine);
        EXPECT_NEAR(coarse / fine, 1.0, 0.05) << dt;
    }
    EXPECT_GT(fine, 0.045) << "the blob spread (it starts at an RMS radius of 0.024 m)";
}

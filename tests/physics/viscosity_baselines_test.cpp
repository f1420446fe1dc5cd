// The two comparison methods (effects.viscosity.method: explicit, takahashi2015) against the main solver: what
// each keeps, what each loses, and that the explicit one respects its stable step.

#include "physics/viscosity/viscosity_explicit.h"
#include "physics/viscosity/viscosity_takahashi2015.h"

#include "random_field.h"

#include <gtest/gtest.h>

using namespace ganache;
using namespace ganache::testing;

namespace {

ViscosityParams paramsFor(ViscosityParams::Method method, Real mu) {
    ViscosityParams p;
    p.method = method;
    p.mu = mu;
    p.tolerance = 1e-10;
    p.maxIterations = method == ViscosityParams::Method::Explicit ? 1000000 : 2000;
    p.preconditioner = ViscosityParams::Preconditioner::BlockJacobi;
    return p;
}

// Angular momentum kept by a viscous cube (mu = 10,000 Pa s, 1,000 particles) spinning at 2 rad/s in zero
// gravity after 0.5 s [WKBB18 Fig. 5].
Real spinKept(ViscosityParams::Method method) {
    World world(0.01);
    world.block(Vec3::Constant(-0.1), Vec3::Constant(0.1));
    ViscosityParams& v = world.effect<ViscosityParams>("viscosity");
    v.mu = 10000;
    v.method = method;
    // takahashi2015 cannot use the rigid coarse space; the scene reader gives it block Jacobi by default
    if (method != ViscosityParams::Method::Weiler2018) v.preconditioner = ViscosityParams::Preconditioner::BlockJacobi;
    Simulation sim = world.simulation(withVelocity([](const Vec3& x) { return Vec3(Vec3(0, 2, 0).cross(x)); }));
    const Vec3 l0 = angularMomentum(sim.particles());
    sim.advanceTo(0.5);
    return angularMomentum(sim.particles()).dot(l0) / l0.squaredNorm();
}

}  // namespace

TEST(ViscosityBaselines, ExplicitSubStepsKeepBothMomenta) {
    // Forward Euler on the same Laplacian as the main solver: pair forces are equal, opposite and along x_ij, so
    // each sub-step keeps both momenta to round-off; at mu = 1000 Pa s a 10 ms step needs many sub-steps, and
    // within the stable bound every one of them takes energy out.
    const SolveOutcome o = solveRandomField(paramsFor(ViscosityParams::Method::Explicit, 1000));
    std::printf("explicit: %zu sub-steps in one 10 ms step, kinetic energy kept %.3f\n", o.iterations, o.kineticKept);
    EXPECT_GT(o.iterations, 10u);
    EXPECT_LT(o.momentumChange, 1e-10);
    EXPECT_LT(o.angularChange, 1e-10);
    EXPECT_LT(o.kineticKept, 0.5);
    EXPECT_EQ(o.capHits, 0u);
}

TEST(ViscosityBaselines, ExplicitStepStopsAtItsSubStepCap) {
    // A step that needs more sub-steps than max_iterations allows stops the run with the number it needs.
    ViscosityParams p = paramsFor(ViscosityParams::Method::Explicit, 1e6);
    p.maxIterations = 10;
    try {
        solveRandomField(p);
        FAIL() << "expected the sub-step cap to stop the step";
    } catch (const std::runtime_error& e) {
        EXPECT_NE(std::string(e.what()).find("sub-steps"), std::string::npos) << e.what();
        EXPECT_NE(std::string(e.what()).find("max_iterations"), std::string::npos) << e.what();
    }
}

TEST(ViscosityBaselines, ExplicitAgreesWithTheImplicitSolverOverSmallSteps) {
    // Both integrate the same operator; over 0.1 s of a decaying random field in 0.2 ms steps (well inside the
    // regime where one implicit step and a few explicit sub-steps see the same velocities) the velocity fields
    // agree to a few per cent of their size: the two differ by O(dt) per step.
    auto run = [](ViscosityParams::Method method) {
        World world = freeBlock();
        world.setup.timeStep.fixedDt = 0.0002;
        ViscosityParams& v = world.effect<ViscosityParams>("viscosity");
        v.mu = 10;
        v.method = method;
        if (method == ViscosityParams::Method::Explicit) v.maxIterations = 10000;  // the reader's default for explicit
        std::mt19937_64 rng(5);
        std::normal_distribution<Real> n(0, 0.1);
        Simulation sim = world.simulation(withVelocity([&](const Vec3&) { return Vec3(n(rng), n(rng), n(rng)); }));
        sim.advanceTo(0.02);
        return sim.particles();
    };
    const ParticleSet a = run(ViscosityParams::Method::Weiler2018);
    const ParticleSet b = run(ViscosityParams::Method::Explicit);
    ASSERT_EQ(a.size(), b.size());
    Real diff = 0, size = 0;
    for (std::size_t i = 0; i < a.size(); ++i) {
        ASSERT_EQ(a.id()[i], b.id()[i]);
        diff += (a.v()[i] - b.v()[i]).squaredNorm();
        size += a.v()[i].squaredNorm();
    }
    std::printf("explicit vs implicit after 20 ms: relative velocity difference %.4f\n", std::sqrt(diff / size));
    EXPECT_LT(std::sqrt(diff / size), 0.05);
}

TEST(ViscosityBaselines, TakahashiSolveConvergesAndKeepsLinearMomentum) {
    // The strain-rate system is symmetric positive definite (the divergence is the strain rate's adjoint), so CG
    // reaches 1e-10 without hitting its cap; F = -G^T S sums to zero over the particles (G of a uniform field is
    // zero), so linear momentum is kept to round-off, and a random field loses energy.
    const SolveOutcome o = solveRandomField(paramsFor(ViscosityParams::Method::Takahashi2015, 1000));
    std::printf("takahashi2015: %zu CG iterations, kinetic energy kept %.3f, angular momentum change %.3g\n",
                o.iterations, o.kineticKept, o.angularChange);
    EXPECT_EQ(o.capHits, 0u);
    EXPECT_LT(o.momentumChange, 1e-8);
    EXPECT_LT(o.kineticKept, 0.5);
}

TEST(ViscosityBaselines, StrainRateMethodBrakesASpinningCubeThatTheMainSolverKeeps) {
    // R1 and R2, [WKBB18 Fig. 5]: the SPH strain rate of a rigid rotation is not zero at the free surface, so
    // takahashi2015 exerts ghost forces there that brake the cube; Eq. 7 vanishes for rigid rotation and the main
    // solver keeps >= 99 % (its own test). The bar for "brakes": it loses at least a tenth in 0.5 s.
    const Real weiler = spinKept(ViscosityParams::Method::Weiler2018);
    const Real takahashi = spinKept(ViscosityParams::Method::Takahashi2015);
    std::printf("angular momentum kept after 0.5 s: weiler2018 %.4f, takahashi2015 %.4f\n", weiler, takahashi);
    EXPECT_NEAR(weiler, 1.0, 0.01);
    EXPECT_LT(takahashi, 0.9);
}

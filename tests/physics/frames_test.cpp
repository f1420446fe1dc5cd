// Frames written from the step that reaches them (Simulation::advancePast, writeAt): where frames fall changes no
// step, and a frame holds each particle where the step's straight path had it at the frame's time.

#include "physics/gravity.h"
#include "physics/viscosity/viscosity.h"
#include "world.h"

#include <gtest/gtest.h>

using namespace ganache;
using namespace ganache::testing;

namespace {

// A honey block thrown at a floor: it falls, lands and spreads within the 0.12 s the tests run.
World landingBlock() {
    World world(0.01, Vec3(-0.3, -0.1, -0.3), Vec3(0.3, 0.4, 0.3));
    world.block(Vec3(-0.05, 0.02, -0.05), Vec3(0.05, 0.12, 0.05), preset("honey"), 20, Vec3(0, -1, 0));
    world.plane("floor");
    world.effect<GravityParams>("gravity");
    world.effect<ViscosityParams>("viscosity").mu = 1.0e3;
    return world;
}

}  // namespace

TEST(Frames, WhereFramesFallChangesNoStep) {
    const World world = landingBlock();
    Simulation once = world.simulation();
    ASSERT_TRUE(once.advancePast(0.12));
    // Frames every 7 ms instead of one at the end (the steps here are 5 ms or less): with advanceTo every frame would
    // end a step.
    Simulation framed = world.simulation();
    for (int f = 1; f <= 17; ++f) ASSERT_TRUE(framed.advancePast(0.007 * f));
    ASSERT_TRUE(framed.advancePast(0.12));
    EXPECT_EQ(framed.stats().steps, once.stats().steps);
    EXPECT_EQ(framed.time(), once.time());
    EXPECT_EQ(framed.particles().x(), once.particles().x());
    EXPECT_EQ(framed.particles().v(), once.particles().v());
}

TEST(Frames, AFrameHoldsTheParticlesOnTheirStepsPathAndLeavesTheStateAlone) {
    const World world = landingBlock();
    Simulation sim = world.simulation();
    ASSERT_TRUE(sim.advancePast(0.047));
    const Real passed = sim.time() - 0.047;
    ASSERT_GT(passed, 0);
    ASSERT_LT(passed, sim.stats().dtMax);
    const std::vector<Vec3> x = sim.particles().x(), v = sim.particles().v();
    std::vector<Vec3> written;
    sim.writeAt(0.047, [&](const ParticleSet& fluid, const std::vector<BoundaryBody>&) { written = fluid.x(); });
    ASSERT_EQ(written.size(), x.size());
    for (std::size_t i = 0; i < x.size(); ++i) EXPECT_EQ(written[i], Vec3(x[i] - passed * v[i]));
    // The write borrowed the positions: the state is the step's end to the bit, and the run goes on as without it.
    EXPECT_EQ(sim.particles().x(), x);
    Simulation unwritten = world.simulation();
    ASSERT_TRUE(unwritten.advancePast(0.047));
    ASSERT_TRUE(sim.advancePast(0.08));
    ASSERT_TRUE(unwritten.advancePast(0.08));
    EXPECT_EQ(sim.particles().x(), unwritten.particles().x());
}

TEST(Frames, TheFramePositionsFollowTheExactOnesWithinAStep) {
    // Against a run that ends a step on the frame (advanceTo): the two take different steps, so they agree to the
    // discretisation, which over 0.061 s of fall and landing is far below a particle radius (1 cm here).
    const World world = landingBlock();
    Simulation past = world.simulation(), exact = world.simulation();
    ASSERT_TRUE(past.advancePast(0.061));
    ASSERT_TRUE(exact.advanceTo(0.061));
    std::vector<Vec3> written;
    past.writeAt(0.061, [&](const ParticleSet& fluid, const std::vector<BoundaryBody>&) { written = fluid.x(); });
    ASSERT_EQ(written.size(), exact.particles().size());
    Real worst = 0;
    for (std::size_t i = 0; i < written.size(); ++i)
        worst = std::max(worst, (written[i] - exact.particles().x()[i]).norm());
    EXPECT_LT(worst, 0.1 * 0.01);
}

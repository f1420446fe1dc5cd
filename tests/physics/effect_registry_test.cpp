// The registry as an extension point: an effect defined entirely in a test file (drag_effect.h) runs in its stage,
// reports its counters and carries its state through a checkpoint, with nothing else in ganache changed.

#include "drag_effect.h"
#include "world.h"

#include <gtest/gtest.h>

using namespace ganache;
using namespace ganache::testing;

TEST(EffectRegistry, AnEffectFromOutsideRunsReportsAndSavesItsState) {
    registerDrag();
    World world(0.01);
    world.block(Vec3::Constant(-0.05), Vec3::Constant(0.05));
    world.effect<DragParams>("drag").rate = 2;
    Simulation sim = world.simulation(withVelocity([](const Vec3&) { return Vec3(1, 0, 0); }));
    sim.advanceTo(0.1);
    // A uniform flow: the pressure solves have nothing to correct, so only the drag acts: v = exp(-2 t). Each step
    // multiplies by exp(-2 dt) exactly, so the product over the steps is exp(-2 t) to round-off.
    for (const Vec3& v : sim.particles().v()) EXPECT_NEAR(v.x(), std::exp(-0.2), 1e-12);
    EXPECT_EQ(sim.effectNames(), std::vector<std::string>{"drag"});
    EXPECT_EQ(sim.counter("drag", "applied"), double(sim.stats().steps));

    // Its state goes into the simulation's state and comes back.
    const SimulationState saved = sim.state();
    sim.advanceTo(0.2);
    Simulation resumed = world.simulation();
    resumed.restore(saved);
    resumed.advanceTo(0.2);
    EXPECT_EQ(resumed.counter("drag", "applied"), sim.counter("drag", "applied"));
    EXPECT_EQ(resumed.particles().v(), sim.particles().v());
}

TEST(EffectRegistry, NamesAreUnique) {
    registerDrag();
    EXPECT_THROW(registerEffect({"viscosity", Stage::Forces, "", &readDrag, &makeDrag}), std::logic_error);
    EXPECT_NE(findEffectEntry("gravity"), nullptr);
    EXPECT_EQ(findEffectEntry("no_such_effect"), nullptr);
}

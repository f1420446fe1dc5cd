// Heat and melting against analytic results: conduction as the 3D heat kernel, conservation of heat,
// radiation's exponential approach, the sources' fall-off, Reynolds' law, and which particles are surface.

#include "physics/gravity.h"
#include "physics/heat/heat.h"
#include "physics/viscosity/viscosity.h"
#include "world.h"

#include <gtest/gtest.h>

#include <fmt/format.h>

#include <cmath>

using namespace ganache;
using namespace ganache::testing;

namespace {

// A material with diffusivity D = k / (rho c) = 1e-3 m^2/s, so heat spreads visibly in half a second.
Material conductor() {
    Material m = preset("water");
    m.density = 1000;
    m.conductivity = 1000;
    m.heatCapacity = 1000;
    return m;
}

Real totalHeat(const ParticleSet& p, Real c) {
    Real q = 0;
    const auto& T = *p.find(attribute::kTemperature);
    for (std::size_t i = 0; i < p.size(); ++i) q += p.mass()[i] * c * T[i];
    return q;
}

}  // namespace

TEST(Heat, ConductionSpreadsAGaussianAsTheHeatKernel) {
    // A Gaussian bump of width sigma in a block at rest spreads as T0 + A (s0^2 / s^2)^(3/2) exp(-x^2 / (2 s^2))
    // with s^2 = s0^2 + 2 D t. The block reaches 4.5 sigma(t) from the centre, where the bump is below 1e-4 of its
    // peak, so the missing infinite medium does not matter. Width (from the second moment) and peak within 2 %,
    // as the issue asks; heat conserved to 1e-10.
    World world(0.005);
    world.block(Vec3::Constant(-0.16), Vec3::Constant(0.16), conductor());
    world.effect<HeatParams>("heat");
    world.setup.timeStep.fixedDt = 0.005;
    const Real sigma0 = 0.03, amplitude = 30, base = 20, D = 1e-3, t = 0.25;
    Simulation sim = world.simulation([&](ParticleSet& p) {
        auto& T = p.add(attribute::kTemperature);
        for (std::size_t i = 0; i < p.size(); ++i)
            T[i] = base + amplitude * std::exp(-p.x()[i].squaredNorm() / (2 * sigma0 * sigma0));
    });
    const Real heat0 = totalHeat(sim.particles(), 1000);
    sim.advanceTo(t);
    const ParticleSet& p = sim.particles();
    EXPECT_LT(maxSpeed(p), 1e-9) << "the block must stay at rest: only heat moves";
    EXPECT_NEAR(totalHeat(p, 1000) / heat0, 1.0, 1e-10);

    const Real s2 = sigma0 * sigma0 + 2 * D * t;
    const auto& Tn = *p.find(attribute::kTemperature);
    Real moment = 0, weight = 0, centre = 0, nearest = 1;
    for (std::size_t i = 0; i < p.size(); ++i) {
        const Real excess = Tn[i] - base;
        moment += excess * p.x()[i].squaredNorm();
        weight += excess;
        if (p.x()[i].norm() < nearest) nearest = p.x()[i].norm(), centre = excess;
    }
    const Real width = std::sqrt(moment / weight / 3);
    const Real peak = amplitude * std::pow(sigma0 * sigma0 / s2, 1.5) * std::exp(-nearest * nearest / (2 * s2));
    std::printf("width %.5f m (analytic %.5f), peak %.4f K (analytic %.4f)\n", width, std::sqrt(s2), centre, peak);
    EXPECT_NEAR(width / std::sqrt(s2), 1.0, 0.02);
    EXPECT_NEAR(centre / peak, 1.0, 0.02);
}

TEST(Heat, RadiationApproachesTheRoomWithItsTimeConstant) {
    // A lone particle is all surface; Eq. 14 integrated exactly gives T_room + (T0 - T_room) exp(-t / t_r).
    World world(0.01);
    world.block(Vec3(0, 0, 0), Vec3(0.02, 0.02, 0.02), preset("water"), 80);
    HeatParams& heat = world.effect<HeatParams>("heat");
    heat.roomTemperature = 20;
    heat.radiationTime = 0.5;
    Simulation sim = world.simulation();
    ASSERT_EQ(sim.particles().size(), 1u);
    for (Real t : {0.1, 0.5, 1.3}) {
        sim.advanceTo(t);
        EXPECT_NEAR((*sim.particles().find(attribute::kTemperature))[0], 20 + 60 * std::exp(-t / 0.5), 1e-9) << t;
    }
}

TEST(Heat, SourcesFallOffAsEquation17) {
    HeatSource lamp;
    lamp.point = Vec3(0, 1, 0);
    lamp.intensity = 800;
    lamp.radius = 0.1;
    EXPECT_DOUBLE_EQ(lamp.flux(Vec3(0, 1, 0), 0), 800);
    EXPECT_NEAR(lamp.flux(Vec3(0.1, 1, 0), 0), 400, 1e-9);   // Q(r) = Q(0) / 2
    EXPECT_NEAR(lamp.flux(Vec3(0, 0.9, 0), 0), 400, 1e-9);   // in every direction
    EXPECT_LT(lamp.flux(Vec3(0, 0.5, 0), 0), 400);
    HeatSource floor;
    floor.plane = true;
    floor.point = Vec3::Zero();
    floor.normal = Vec3::UnitY();
    floor.intensity = 500;
    floor.radius = 0.02;
    // Only the distance to the plane matters.
    EXPECT_DOUBLE_EQ(floor.flux(Vec3(0.3, 0.02, -0.7), 0), floor.flux(Vec3(-5, 0.02, 2), 0));
    EXPECT_NEAR(floor.flux(Vec3(1, 0.02, 1), 0), 250, 1e-9);
    EXPECT_NEAR(floor.flux(Vec3(1, -0.02, 1), 0), 250, 1e-9);
    // Switched on and off in time, and moved by its motion.
    floor.start = 1;
    floor.end = 2;
    EXPECT_EQ(floor.flux(Vec3::Zero(), 0.5), 0.0);
    EXPECT_EQ(floor.flux(Vec3::Zero(), 1.5), 500.0);
    EXPECT_EQ(floor.flux(Vec3::Zero(), 2.0), 0.0);
    lamp.motion.keyframes = {{0, Vec3::Zero()}, {1, Vec3(1, 0, 0)}};
    EXPECT_NEAR(lamp.flux(Vec3(1, 1, 0), 1), 800, 1e-9);
}

TEST(Heat, ASourceHeatsASurfaceParticleByItsCatchOverMassAndCapacity) {
    // [Eq. 18]: a lone particle under a lamp gains A_p Q / (m c) kelvin per second, A_p = pi r^2.
    World world(0.01);
    world.block(Vec3(0, 0, 0), Vec3(0.02, 0.02, 0.02), preset("honey"), 20);
    HeatSource lamp;
    lamp.point = Vec3(0.01, 0.11, 0.01);
    lamp.intensity = 1000;
    lamp.radius = 0.1;
    world.effect<HeatParams>("heat").sources.push_back(lamp);
    Simulation sim = world.simulation();
    const Real m = sim.particles().mass()[0], c = 2400;
    sim.advanceTo(0.2);
    const Real expected = 20 + 0.2 * M_PI * 0.01 * 0.01 * 500 / (m * c);  // 0.1 m away: Q = 500 W/m^2
    EXPECT_NEAR((*sim.particles().find(attribute::kTemperature))[0], expected, 1e-9);
}

TEST(Heat, ReynoldsLawAndRamps) {
    ViscosityLaw law;
    law.mu0 = 5e6;
    law.t0 = 20;
    law.alpha = 0.3;
    law.muMin = 100;
    law.muMax = 5e6;
    EXPECT_DOUBLE_EQ(law.at(20), 5e6);
    EXPECT_NEAR(law.at(20 + std::log(2.0) / 0.3), 2.5e6, 1e-6);  // halves where alpha (T - T0) = ln 2
    EXPECT_DOUBLE_EQ(law.at(200), 100.0);                         // clamped below
    EXPECT_DOUBLE_EQ(law.at(-50), 5e6);                           // and above
    // The chocolate preset reaches the paper's 100 Pa s at 50 C.
    EXPECT_NEAR(findPreset("chocolate")->law->at(50), 100, 1e-6);
    ViscosityLaw ramp;
    ramp.kind = ViscosityLaw::Kind::Ramp;
    ramp.ramp = {{20, 1e4}, {40, 1e2}};
    EXPECT_DOUBLE_EQ(ramp.at(10), 1e4);
    EXPECT_NEAR(ramp.at(30), 1e3, 1e-9);  // log-linear
    EXPECT_DOUBLE_EQ(ramp.at(60), 1e2);
}

TEST(Heat, SurfaceIsTheOuterLayerAndLoneParticles) {
    World world(0.01);
    world.block(Vec3(0, 0, 0), Vec3(0.2, 0.2, 0.2));
    world.block(Vec3(0.5, 0.5, 0.5), Vec3(0.52, 0.52, 0.52));
    world.effect<HeatParams>("heat");
    Simulation sim = world.simulation();
    const ParticleSet& p = sim.particles();
    const auto surface = surfaceParticles(p, sim.density(), sim.fluidNeighbours(), sim.gradients().fluid,
                                          sim.kernel().supportRadius(), 0.5);
    std::size_t outer = 0;
    for (std::size_t i = 0; i < p.size(); ++i) {
        const Vec3& x = p.x()[i];
        if (x.x() > 0.4) {
            EXPECT_TRUE(surface[i]) << "the lone particle";
            continue;
        }
        const bool onFace = (x.array() < 0.011).any() || (x.array() > 0.189).any();
        outer += onFace;
        EXPECT_EQ(bool(surface[i]), onFace) << x.transpose();
    }
    EXPECT_EQ(outer, 1000u - 512u);
}

TEST(Heat, AWarmPlateConductsIntoTheFluidTouchingIt) {
    // A plate held at 60 C under a 20 C block: heat flows in, temperatures stay between the two (the explicit
    // steps are monotone) and fall with height. The bottom layer, 1.5 lattice spacings above the plate, warms by
    // 6 K in 0.2 s (a semi-infinite medium touching the plate would be at 38 C there: the boundary particles
    // conduct like a fluid layer one spacing below the fluid, so the contact is a little insulated).
    World world(0.005);
    world.block(Vec3(-0.05, 0.01, -0.05), Vec3(0.05, 0.11, 0.05), conductor(), 20);
    world.plane("plate");
    HeatedBody plate;
    plate.body = "plate";
    plate.temperature = 60;
    world.effect<HeatParams>("heat").bodies.push_back(plate);
    Simulation sim = world.simulation();
    const Real heat0 = totalHeat(sim.particles(), 1000);
    sim.advanceTo(0.2);
    const ParticleSet& p = sim.particles();
    const auto& T = *p.find(attribute::kTemperature);
    Real low = 0, high = 0;
    std::size_t nl = 0, nh = 0;
    for (std::size_t i = 0; i < p.size(); ++i) {
        EXPECT_GE(T[i], 20 - 1e-9);
        EXPECT_LE(T[i], 60 + 1e-9);
        if (p.x()[i].y() < 0.02) low += T[i], ++nl;
        if (p.x()[i].y() > 0.1) high += T[i], ++nh;
    }
    std::printf("bottom layer %.2f C, top layer %.2f C\n", low / nl, high / nh);
    EXPECT_GT(low / nl, 24.0);
    EXPECT_LT(high / nh, low / nl);
    EXPECT_GT(totalHeat(p, 1000), heat0);
}

TEST(Heat, OnlyScenesWithHeatHaveTemperaturesOrMelt) {
    // Chocolate has a melting law, but without `heat:` there is no temperature and its viscosity is one number.
    World coldWorld(0.01);
    coldWorld.block(Vec3(0, 0, 0), Vec3(0.1, 0.1, 0.1), preset("chocolate"));
    coldWorld.effect<ViscosityParams>("viscosity");
    Simulation cold = coldWorld.simulation();
    cold.step();
    EXPECT_EQ(cold.particles().find(attribute::kTemperature), nullptr);
    EXPECT_EQ(cold.particles().find(attribute::kViscosity), nullptr);
    EXPECT_EQ(cold.effectNames(), std::vector<std::string>{"viscosity"});
    // With heat, every particle's viscosity follows its temperature (20 C: the law's 5e6 Pa s; 35 C: far less).
    World warmWorld(0.01);
    warmWorld.block(Vec3(0, 0, 0), Vec3(0.1, 0.1, 0.1), preset("chocolate"), 35);
    warmWorld.effect<ViscosityParams>("viscosity");
    warmWorld.effect<HeatParams>("heat");
    Simulation warm = warmWorld.simulation();
    warm.step();
    const auto* T = warm.particles().find(attribute::kTemperature);
    const auto* mu = warm.particles().find(attribute::kViscosity);
    ASSERT_TRUE(T && mu);
    const ViscosityLaw& law = *findPreset("chocolate")->law;
    for (std::size_t i = 0; i < mu->size(); ++i) EXPECT_DOUBLE_EQ((*mu)[i], law.at((*T)[i]));
    EXPECT_LT((*mu)[0], 1e5);
}

TEST(Heat, ConductionTooFastForTheStepIsSubSteppedAndStaysBounded) {
    // k = 1e5 W/(m K): one 5 ms step would overshoot by far; sub-steps keep every temperature within the range
    // it started in (explicit steps within the bound are weighted means), and the run says how many it took.
    Material superconductor = conductor();
    superconductor.conductivity = 1.0e5;
    World world(0.01);
    world.block(Vec3(0, 0, 0), Vec3(0.1, 0.2, 0.2), superconductor, 0);
    world.block(Vec3(0.1, 0, 0), Vec3(0.2, 0.2, 0.2), superconductor, 100);
    world.effect<HeatParams>("heat");
    world.setup.timeStep.fixedDt = 0.005;
    Simulation sim = world.simulation();
    const Real heat0 = totalHeat(sim.particles(), 1000);
    sim.advanceTo(0.05);
    EXPECT_GT(sim.counter("heat", "substeps_max"), 1);
    EXPECT_FALSE(sim.stats().warnings.empty());
    const auto& T = *sim.particles().find(attribute::kTemperature);
    for (Real t : T) {
        EXPECT_GE(t, -1e-9);
        EXPECT_LE(t, 100 + 1e-9);
    }
    EXPECT_NEAR(totalHeat(sim.particles(), 1000) / heat0, 1.0, 1e-10);
    std::printf("%.0f sub-steps at most in one step\n", sim.counter("heat", "substeps_max"));
}

// Checkpoint files: every field comes back exactly, and a damaged file is refused with a reason, never read.

#include "io/checkpoint.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <iterator>

namespace fs = std::filesystem;
using namespace ganache;

namespace {

SimulationState sampleState() {
    SimulationState s;
    s.time = 0.123456789;
    s.step = 4242;
    for (int i = 0; i < 5; ++i) s.fluid.add(Vec3(i, 0.1 * i, -i), Vec3(1.0 / 3, i, 2), 0.001 * (i + 1), 10 + i);
    auto& t = s.fluid.addScalar("temperature", 21.5);
    t[3] = 1e-300;
    s.fluid.addScalar("_pressure", 0, false)[1] = -0.0;
    s.fluid.addVector("_viscosity_dv", Vec3(1e-17, 2, 3), false);
    s.effects = {{"viscosity", 12.5, std::string("\0\x01saved", 7)}, {"emitters", 0.25, ""}};
    s.pressure = std::string("\x02\0coarse", 8);
    s.totalImpulse = {Vec3(1, 2, 3)};
    s.totalAngular = {Vec3(-1, 0, 1)};
    s.peakForce = {9.5};
    s.stats.steps = 4242;
    s.stats.boundaryContacts = 31;
    s.stats.lastPressureIterations = 17;
    s.stats.dtMin = 1e-4;
    s.stats.time.divergence = 12.5;
    s.stats.warn("step 1: something");
    return s;
}

std::string readBytes(const fs::path& file) {
    std::ifstream in(file, std::ios::binary);
    return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

}  // namespace

TEST(Checkpoint, EveryFieldComesBackExactly) {
    const fs::path file = fs::temp_directory_path() / "ganache_checkpoint_test.ckpt";
    const SimulationState s = sampleState();
    writeCheckpoint(file, {"scene", "abc123", 0.004, 17}, s);
    const Checkpoint c = readCheckpoint(file);
    EXPECT_EQ(c.info.scene, "scene");
    EXPECT_EQ(c.info.sceneHash, "abc123");
    EXPECT_EQ(c.info.particleRadius, 0.004);
    EXPECT_EQ(c.info.frame, 17);
    EXPECT_EQ(c.state.time, s.time);
    EXPECT_EQ(c.state.step, s.step);
    EXPECT_EQ(c.state.fluid.x(), s.fluid.x());
    EXPECT_EQ(c.state.fluid.v(), s.fluid.v());
    EXPECT_EQ(c.state.fluid.mass(), s.fluid.mass());
    EXPECT_EQ(c.state.fluid.id(), s.fluid.id());
    EXPECT_EQ(c.state.fluid.scalars(), s.fluid.scalars());
    EXPECT_EQ(c.state.fluid.vectors(), s.fluid.vectors());
    EXPECT_FALSE(c.state.fluid.isCached("_pressure"));
    EXPECT_TRUE(c.state.fluid.isCached("temperature"));
    ASSERT_EQ(c.state.effects.size(), 2u);
    for (std::size_t e = 0; e < 2; ++e) {
        EXPECT_EQ(c.state.effects[e].name, s.effects[e].name);
        EXPECT_EQ(c.state.effects[e].seconds, s.effects[e].seconds);
        EXPECT_EQ(c.state.effects[e].bytes, s.effects[e].bytes);
    }
    EXPECT_EQ(c.state.pressure, s.pressure);
    EXPECT_EQ(c.state.totalImpulse, s.totalImpulse);
    EXPECT_EQ(c.state.totalAngular, s.totalAngular);
    EXPECT_EQ(c.state.peakForce, s.peakForce);
    EXPECT_EQ(c.state.stats.steps, 4242u);
    EXPECT_EQ(c.state.stats.boundaryContacts, 31u);
    EXPECT_EQ(c.state.stats.lastPressureIterations, 17u);
    EXPECT_EQ(c.state.stats.dtMin, 1e-4);
    EXPECT_EQ(c.state.stats.time.divergence, 12.5);
    EXPECT_EQ(c.state.stats.warnings, s.stats.warnings);
    EXPECT_EQ(c.state.stats.warningCount, 1u);

    // The restored particles take a simulation's attributes in place, and only when they carry the same ones.
    ParticleSet live = sampleState().fluid;
    const std::vector<Real>* temperature = live.findScalar("temperature");
    live.assignValues(c.state.fluid);
    EXPECT_EQ(live.findScalar("temperature"), temperature);
    ParticleSet other;
    other.addScalar("viscosity");
    EXPECT_THROW(other.assignValues(c.state.fluid), std::runtime_error);
    fs::remove(file);
}

TEST(Checkpoint, EveryTruncationAndFlippedByteIsRefused) {
    const fs::path file = fs::temp_directory_path() / "ganache_checkpoint_damage.ckpt";
    writeCheckpoint(file, {"scene", "abc123", 0.004, 17}, sampleState());
    const std::string whole = readBytes(file);
    const fs::path damaged = fs::temp_directory_path() / "ganache_checkpoint_damaged.ckpt";
    for (std::size_t length = 0; length < whole.size(); length += 7) {
        std::ofstream(damaged, std::ios::binary) << whole.substr(0, length);
        EXPECT_THROW(readCheckpoint(damaged), std::runtime_error) << length;
    }
    for (std::size_t at = 0; at < whole.size(); at += 13) {
        std::string bytes = whole;
        bytes[at] ^= 0x01;
        std::ofstream(damaged, std::ios::binary) << bytes;
        EXPECT_THROW(readCheckpoint(damaged), std::runtime_error) << at;
    }
    fs::remove(file);
    fs::remove(damaged);
}

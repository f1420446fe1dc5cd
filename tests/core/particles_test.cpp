#include "core/particles.h"

#include <gtest/gtest.h>

using namespace ganache;

namespace {
ParticleSet threeParticles() {
    ParticleSet p;
    p.addScalar("temperature", 20);
    for (int i = 0; i < 3; ++i) p.add(Vec3(i, 0, 0), Vec3(0, i, 0), 1.0 + i, std::uint64_t(10 + i));
    for (int i = 0; i < 3; ++i) (*p.findScalar("temperature"))[i] = 100 + i;
    return p;
}
}  // namespace

TEST(ParticleSet, ReorderMovesEveryAttributeTogether) {
    ParticleSet p = threeParticles();
    p.addVector("normal", Vec3::UnitZ());
    p.reorder({2, 0, 1});
    EXPECT_EQ(p.x()[0], Vec3(2, 0, 0));
    EXPECT_EQ(p.v()[0], Vec3(0, 2, 0));
    EXPECT_EQ(p.mass()[0], 3.0);
    EXPECT_EQ(p.id()[0], 12u);
    EXPECT_EQ((*p.findScalar("temperature"))[0], 102.0);
    EXPECT_EQ((*p.findScalar("temperature"))[1], 100.0);
    EXPECT_EQ(p.findVector("normal")->size(), 3u);
}

TEST(ParticleSet, SortByIdRestoresOrder) {
    ParticleSet p = threeParticles();
    p.reorder({1, 2, 0});
    p.sortById();
    for (int i = 0; i < 3; ++i) {
        EXPECT_EQ(p.id()[i], std::uint64_t(10 + i));
        EXPECT_EQ((*p.findScalar("temperature"))[i], 100.0 + i);
    }
}

TEST(ParticleSet, RemoveIfKeepsOrderOfTheRest) {
    ParticleSet p = threeParticles();
    EXPECT_EQ(p.removeIf({0, 1, 0}), 1u);
    ASSERT_EQ(p.size(), 2u);
    EXPECT_EQ(p.id()[1], 12u);
    EXPECT_EQ((*p.findScalar("temperature"))[1], 102.0);
}

TEST(ParticleSet, AttributesExistOnlyWhenAdded) {
    ParticleSet p;
    EXPECT_EQ(p.findScalar("temperature"), nullptr);
    p.addScalar("temperature");
    EXPECT_THROW(p.addScalar("temperature"), std::logic_error);
    EXPECT_THROW(p.reorder({0}), std::logic_error);
}

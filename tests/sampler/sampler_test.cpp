#include "sampler/sampler.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <set>

using namespace ganache;
namespace fs = std::filesystem;

namespace {

Scene sceneFrom(const std::string& name, const std::string& body) {
    const fs::path dir = fs::temp_directory_path() / "ganache_sampler_test";
    fs::create_directories(dir);
    std::ofstream(dir / (name + ".yaml")) << "ganache: 1\n" << body;
    return loadScene(dir / (name + ".yaml"), Quality::parse("final"));
}

}  // namespace

TEST(Sampler, BoxHoldsItsVolumeOfLatticeCells) {
    const Scene s = sceneFrom("box", R"(particles: {radius: 0.01}
domain: {min: [-1, -1, -1], max: [1, 1, 1]}
fluids: [{box: {min: [0, 0, 0], max: [0.2, 0.4, 0.1]}}]
)");
    const Sample out = sampleScene(s);
    EXPECT_EQ(out.fluid.size(), 10u * 20u * 5u);  // extents divided by the spacing 2r = 0.02
    // Every particle lies inside the box, at least r from its faces.
    for (const Vec3& x : out.fluid.x()) {
        EXPECT_GE(x.minCoeff(), 0.01 - 1e-12);
        EXPECT_LE(x.x(), 0.19 + 1e-12);
    }
}

TEST(Sampler, SphereVolumeWithinTwoPercentAtFineSpacing) {
    // R / r = 25: the lattice volume N (2r)^3 approaches 4/3 pi R^3; the boundary layer error is about
    // 1/(R/r), below 2 % here.
    const Scene s = sceneFrom("sphere", R"(particles: {radius: 0.002}
domain: {min: [-1, -1, -1], max: [1, 1, 1]}
fluids: [{sphere: {centre: [0.01, 0.2, -0.1], radius: 0.05}}]
)");
    const Sample out = sampleScene(s);
    const Real volume = Real(out.fluid.size()) * std::pow(0.004, 3);
    const Real exact = 4.0 / 3.0 * M_PI * std::pow(0.05, 3);
    EXPECT_NEAR(volume / exact, 1.0, 0.02);
}

TEST(Sampler, InteriorStartsExactlyAtRestDensity) {
    const Scene s = sceneFrom("rest", R"(particles: {radius: 0.01}
domain: {min: [-1, -1, -1], max: [1, 1, 1]}
fluids: [{material: honey, box: {min: [0, 0, 0], max: [0.3, 0.3, 0.3]}}]
)");
    const Sample out = sampleScene(s);
    ASSERT_GT(out.density.interiorCount, 100u);
    // The mass is chosen from the lattice sum, so the interior error is round-off only.
    EXPECT_NEAR(out.density.meanInterior, 0.0, 1e-12);
    EXPECT_LT(out.density.maxCompression, 1e-12);  // free surfaces are under-dense, never compressed
}

TEST(Sampler, LaterFluidsAreCarvedWhereEarlierOnesAre) {
    const Scene s = sceneFrom("overlap", R"(particles: {radius: 0.01}
domain: {min: [-1, -1, -1], max: [1, 1, 1]}
fluids:
  - box: {min: [0, 0, 0], max: [0.2, 0.2, 0.2]}
  - box: {min: [0, 0, 0], max: [0.2, 0.2, 0.2]}
)");
    const Sample out = sampleScene(s);
    EXPECT_EQ(out.fluidCounts[0], 1000u);
    EXPECT_EQ(out.fluidCounts[1], 0u);
    EXPECT_EQ(out.carved, 1000u);
}

TEST(Sampler, BoxWallsAreDenseAndOpenTopIsOpen) {
    const Scene s = sceneFrom("walls", R"(particles: {radius: 0.01}
domain: {min: [-1, -1, -1], max: [1, 1, 1]}
fluids: [{box: {min: [0, 0, 0], max: [0.1, 0.1, 0.1]}}]
boundaries:
  - name: tank
    box: {min: [-0.05, -0.05, -0.05], max: [0.25, 0.15, 0.2], open_top: true}
)");
    const Sample out = sampleScene(s);
    ASSERT_EQ(out.boundaries.size(), 1u);
    const auto& b = out.boundaries[0];
    std::set<std::tuple<long, long, long>> unique;
    Real maxY = -1;
    for (const Vec3& x : b.x) {
        unique.insert({std::lround(x.x() * 1e6), std::lround(x.y() * 1e6), std::lround(x.z() * 1e6)});
        // Points only on the faces of the box.
        const bool onFace = std::abs(x.x() + 0.05) < 1e-9 || std::abs(x.x() - 0.25) < 1e-9 ||
                            std::abs(x.y() + 0.05) < 1e-9 || std::abs(x.z() + 0.05) < 1e-9 ||
                            std::abs(x.z() - 0.2) < 1e-9;
        EXPECT_TRUE(onFace) << x.transpose();
        maxY = std::max(maxY, x.y());
    }
    EXPECT_EQ(unique.size(), b.x.size()) << "no duplicate wall particles";
    EXPECT_NEAR(maxY, 0.15, 1e-9);  // the rim is there
    // The floor: spacing at most r, so its points number at least (extent / r + 1)^2.
    std::size_t floor = 0;
    for (const Vec3& x : b.x) floor += std::abs(x.y() + 0.05) < 1e-9;
    EXPECT_GE(floor, std::size_t(31 * 26));
    // Volumes: positive, and about r^2 times the sheet's thickness scale (one layer of spacing r).
    for (Real v : b.volume) EXPECT_GT(v, 0.0);
}

TEST(Sampler, PlaneLiesOnItselfWithinTheDomain) {
    const Scene s = sceneFrom("plane", R"(particles: {radius: 0.02}
domain: {min: [-0.5, -0.5, -0.5], max: [0.5, 0.5, 0.5]}
fluids: [{box: {min: [0, 0, 0], max: [0.1, 0.1, 0.1]}}]
boundaries:
  - name: slope
    plane: {point: [0, -0.2, 0], normal: [0.3, 1, 0]}
)");
    const Sample out = sampleScene(s);
    const Vec3 n = Vec3(0.3, 1, 0).normalized();
    const Real h = 4 * 0.02;
    ASSERT_GT(out.boundaries[0].x.size(), 500u);
    for (const Vec3& x : out.boundaries[0].x) {
        EXPECT_NEAR(n.dot(x - Vec3(0, -0.2, 0)), 0.0, 1e-12);
        EXPECT_LE(x.cwiseAbs().maxCoeff(), 0.5 + h + 1e-12);
    }
}

TEST(Sampler, LatticeMassMatchesRestDensity) {
    const CubicSpline w(0.04);
    const Real m = latticeMass(0.02, 1000, w);
    // Close to rho0 d^3 (the kernel's lattice sum is near 1 / d^3) but not equal: that is why it is computed.
    EXPECT_NEAR(m / (1000 * std::pow(0.02, 3)), 1.0, 0.1);
}

TEST(Sampler, AngularVelocitySpinsTheFluidAboutItsCentreOfMass) {
    // The rotating cube's start (the paper's Fig. 5): v = v0 + omega x (x - c), c the fluid's centre of mass, so
    // the linear momentum is v0's alone and every particle moves rigidly.
    const Scene s = sceneFrom("spin", R"(particles: {radius: 0.01}
domain: {min: [-1, -1, -1], max: [1, 1, 1]}
fluids: [{box: {min: [0.1, 0, 0], max: [0.3, 0.2, 0.2]}, velocity: [0, 1, 0], angular_velocity: [0, 0, 5]}]
)");
    const Sample out = sampleScene(s);
    Vec3 centre = Vec3::Zero(), momentum = Vec3::Zero();
    for (std::size_t i = 0; i < out.fluid.size(); ++i) centre += out.fluid.x()[i], momentum += out.fluid.v()[i];
    centre /= Real(out.fluid.size());
    EXPECT_NEAR((centre - Vec3(0.2, 0.1, 0.1)).norm(), 0, 1e-12);
    EXPECT_NEAR((momentum / Real(out.fluid.size()) - Vec3(0, 1, 0)).norm(), 0, 1e-12);
    for (std::size_t i = 0; i < out.fluid.size(); ++i)
        EXPECT_NEAR((out.fluid.v()[i] - Vec3(0, 1, 0) - Vec3(0, 0, 5).cross(out.fluid.x()[i] - centre)).norm(), 0, 1e-12);
}

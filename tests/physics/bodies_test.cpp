#include "physics/bodies.h"

#include <gtest/gtest.h>

#include <vector>

using namespace ganache;

namespace {

// A fluid particle's pushes on the boundary particles of one body, each along the line from the boundary particle
// to the fluid particle, taken at the fluid particle as one sum: the same impulse and angular impulse as pair by
// pair, on a rotating body that also translates (its centre moves).
TEST(BodyLoads, PushesAlongTheirLinesAddUpAtTheParticle) {
    BodySetup paddle{"paddle", {}};
    paddle.motion.centre = Vec3(0.1, 0, -0.2);
    paddle.motion.angularVelocity = 3;
    paddle.motion.axis = Vec3(0, 0.6, 0.8);
    paddle.motion.keyframes = {{0, Vec3::Zero()}, {1, Vec3(0.5, -0.1, 0.2)}};
    const std::vector<BoundaryBody> bodies{{"floor", {Vec3(0, 0, 0)}, {1e-6}},
                                           {"paddle", {Vec3(0.2, 0.1, 0), Vec3(0.25, 0.05, 0.02),
                                                       Vec3(0.18, 0.12, -0.03)}, {1e-6, 1e-6, 1e-6}}};
    BoundaryParticles b(bodies, {paddle});
    const Real t = 0.4;
    b.moveTo(t);
    const Vec3 x(0.22, 0.15, 0.01);
    const std::vector<std::uint32_t> ks{1, 2, 3};
    ASSERT_EQ(b.commonBody(ks.data(), ks.data() + ks.size()), 1u);
    const std::vector<std::uint32_t> mixed{0, 2};
    EXPECT_EQ(b.commonBody(mixed.data(), mixed.data() + mixed.size()), BoundaryParticles::kSeveralBodies);

    BodyLoads pairwise, summed;
    pairwise.clear(2), summed.clear(2);
    Vec3 total = Vec3::Zero();
    const Real strength[] = {2.0, -0.7, 1.3};
    for (std::size_t p = 0; p < ks.size(); ++p) {
        const Vec3 j = strength[p] * (x - b.x[ks[p]]);
        pairwise.add(b, ks[p], j, t);
        total += j;
    }
    summed.addFrom(b, 1, x, total, t);
    EXPECT_TRUE(pairwise.impulse[0].isZero() && summed.impulse[0].isZero());
    // Both sum the same few products in other orders: round-off of the order of their size.
    EXPECT_TRUE(summed.impulse[1].isApprox(pairwise.impulse[1], 1e-12));
    EXPECT_TRUE(summed.angularImpulse[1].isApprox(pairwise.angularImpulse[1], 1e-12))
        << summed.angularImpulse[1].transpose() << " against " << pairwise.angularImpulse[1].transpose();
    // A push off its line would not add up so: the check can fail.
    BodyLoads offLine;
    offLine.clear(2);
    offLine.addFrom(b, 1, x + Vec3(0, 0.05, 0), total, t);
    EXPECT_FALSE(offLine.angularImpulse[1].isApprox(pairwise.angularImpulse[1], 1e-6));
}

}  // namespace

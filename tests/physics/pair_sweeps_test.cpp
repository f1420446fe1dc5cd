// The pair sweeps against their definitions, taken pair by pair with Eigen: the sweeps group pairs by four (viscous
// product) or by coordinate lanes (pressure sweeps) and pad a particle's last group with itself, so every pair count
// from 0 up is met, and the last particle, whose row ends its array, is a neighbour of others.
#include "physics/pair_sweeps.h"

#include <gtest/gtest.h>

#include <random>
#include <utility>

namespace ganache {
namespace {

struct Field {
    std::vector<Vec3> x, u;
    std::vector<Real> s;
    sweeps::PairWeights weight;
    std::vector<Mat3> block;              // every particle's boundary block, zero where it has none
    std::vector<std::uint32_t> walled;    // the particles with one
    std::vector<Mat3> walledBlock;        // their blocks
    std::vector<Vec3> boundarySum;
    std::vector<Real> bodyRate;
    NeighbourList list;
    sweeps::Rows xRows, uRows;

    sweeps::BoundaryBlocks boundary() const { return {walled.data(), walledBlock.data(), walled.size()}; }
};

// n particles in a unit box; particle i has i % 9 neighbours (0 to 8: every tail length twice), always including the
// last particle where it has any.
Field field(std::size_t n) {
    std::mt19937_64 rng(7);
    std::uniform_real_distribution<Real> unit(-1, 1);
    Field f;
    for (std::size_t i = 0; i < n; ++i) {
        f.x.emplace_back(unit(rng), unit(rng), unit(rng));
        f.u.emplace_back(unit(rng), unit(rng), unit(rng));
        f.s.push_back(1 + unit(rng));
        // two particles in three next to a wall, in runs that start and end anywhere
        const Mat3 a = Mat3::Random();
        f.block.push_back(i % 3 == 1 ? Mat3(Mat3::Zero()) : Mat3(a + a.transpose()));
        if (i % 3 != 1) f.walled.push_back(std::uint32_t(i)), f.walledBlock.push_back(f.block.back());
        f.boundarySum.emplace_back(unit(rng), unit(rng), unit(rng));
        f.bodyRate.push_back(unit(rng));
    }
    for (std::size_t i = 0; i < n; ++i) {  // offsets start with the 0 NeighbourList holds
        for (std::size_t c = 0; c < i % 9; ++c) {
            f.list.indices.push_back(std::uint32_t(c == 0 ? n - 1 : (i + 7 * c + 1) % n));
            f.weight.push_back(sweeps::PairWeight(unit(rng)));
        }
        f.list.offsets.push_back(f.list.indices.size());
    }
    f.xRows.resize(n);
    f.uRows.resize(n);
    sweeps::toRows(0, n, f.x.data(), f.xRows.data());
    sweeps::toRows(0, n, f.u.data(), f.uRows.data());
    return f;
}

// Round-off of sums of at most 8 products of numbers of order 1: 1e-13 leaves a factor 100 over double's.
constexpr Real kTolerance = 1e-13;

TEST(PairSweeps, TakeTheViscousProductAsDefinedPairByPair) {
    const Field f = field(40);
    const Real dt = 0.3;
    std::vector<Vec3> out(f.x.size()), out1(f.x.size()), out2(f.x.size());
    // in two ranges, as a parallel loop's blocks take them: the second finds its first boundary block itself
    for (const auto& [begin, end] : {std::pair<std::size_t, std::size_t>{0, 17}, {17, f.x.size()}})
        sweeps::viscousProduct(begin, end, {&f.list, f.weight.data()}, f.boundary(), f.xRows.data(), f.uRows.data(),
                               dt, out.data());
    // the two-input sweep gives each input's product, the same bytes as one at a time
    sweeps::viscousProducts(0, f.x.size(), {&f.list, f.weight.data()}, f.boundary(), f.xRows.data(),
                            f.xRows.data(), f.uRows.data(), dt, out1.data(), out2.data());
    for (std::size_t i = 0; i < f.x.size(); ++i) {
        Vec3 a = Vec3::Zero();
        for (std::size_t p = f.list.first(i); p < f.list.last(i); ++p) {
            const std::size_t j = f.list.indices[p];
            const Vec3 d = f.x[i] - f.x[j];
            a += f.weight[p] * d.dot(f.u[i] - f.u[j]) * d;
        }
        const Vec3 expected = f.u[i] - dt * a + f.block[i] * f.u[i];
        EXPECT_LT((out[i] - expected).norm(), kTolerance) << "particle " << i;
        EXPECT_EQ(out2[i], out[i]) << "particle " << i;
    }
}

TEST(PairSweeps, TakeTheDensityRateAndThePressuresVelocityChangeAsDefinedPairByPair) {
    const Field f = field(40);
    const Real dt = 0.3;
    std::vector<Real> rate(f.x.size());
    std::vector<Vec3> dv(f.x.size());
    sweeps::densityRate(0, f.x.size(), {&f.list, f.weight.data()}, f.boundarySum.data(), f.bodyRate.data(),
                        f.xRows.data(), f.uRows.data(), rate.data());
    sweeps::pressureChange(0, f.x.size(), {&f.list, f.weight.data()}, f.boundarySum.data(), f.xRows.data(),
                           f.s.data(), dt, dv.data());
    for (std::size_t i = 0; i < f.x.size(); ++i) {
        Real r = f.u[i].dot(f.boundarySum[i]) - f.bodyRate[i];
        Vec3 a = f.s[i] * f.boundarySum[i];
        for (std::size_t p = f.list.first(i); p < f.list.last(i); ++p) {
            const std::size_t j = f.list.indices[p];
            const Vec3 d = f.x[i] - f.x[j];
            r += f.weight[p] * (f.u[i] - f.u[j]).dot(d);
            a += f.weight[p] * (f.s[i] + f.s[j]) * d;
        }
        EXPECT_NEAR(rate[i], r, kTolerance) << "particle " << i;
        EXPECT_LT((dv[i] + dt * a).norm(), kTolerance) << "particle " << i;
    }
}

// From about 130k particles the sweeps prefetch their neighbours' rows, in code of its own: the same
// definitions hold there, to the last particle, whose pairs lie within the prefetch distance of the lists' end.
TEST(PairSweeps, TakeTheSameSumsWhereTheyPrefetch) {
    const Field f = field(150000);
    ASSERT_TRUE(sweeps::prefetches(f.list, 2));
    const std::size_t n = f.x.size();
    const Real dt = 0.3;
    std::vector<Vec3> out(n), out1(n), out2(n), out3(n), dv(n);
    std::vector<Real> rate(n);
    const sweeps::Pairs pairs{&f.list, f.weight.data()};
    sweeps::viscousProduct(0, n, pairs, f.boundary(), f.xRows.data(), f.uRows.data(), dt, out.data());
    sweeps::viscousProducts(0, n, pairs, f.boundary(), f.xRows.data(), f.xRows.data(), f.uRows.data(),
                            f.xRows.data(), dt, out1.data(), out2.data(), out3.data());
    sweeps::densityRate(0, n, pairs, f.boundarySum.data(), f.bodyRate.data(), f.xRows.data(), f.uRows.data(),
                        rate.data());
    sweeps::pressureChange(0, n, pairs, f.boundarySum.data(), f.xRows.data(), f.s.data(), dt, dv.data());
    std::size_t wrong = 0;
    for (std::size_t i = 0; i < n; ++i) {
        Vec3 a = Vec3::Zero(), push = f.s[i] * f.boundarySum[i];
        Real r = f.u[i].dot(f.boundarySum[i]) - f.bodyRate[i];
        for (std::size_t p = f.list.first(i); p < f.list.last(i); ++p) {
            const std::size_t j = f.list.indices[p];
            const Vec3 d = f.x[i] - f.x[j];
            a += f.weight[p] * d.dot(f.u[i] - f.u[j]) * d;
            r += f.weight[p] * (f.u[i] - f.u[j]).dot(d);
            push += f.weight[p] * (f.s[i] + f.s[j]) * d;
        }
        const Vec3 expected = f.u[i] - dt * a + f.block[i] * f.u[i];
        wrong += (out[i] - expected).norm() >= kTolerance || out2[i] != out[i] ||
                 std::abs(rate[i] - r) >= kTolerance || (dv[i] + dt * push).norm() >= kTolerance;
    }
    EXPECT_EQ(wrong, 0u) << "particles whose sums differ from the definitions";
}

TEST(PairSweeps, TakeTheSquaredDistancesAndThePressureWeightsAsDefinedPairByPair) {
    const Field f = field(40);
    std::mt19937_64 rng(13);
    std::uniform_real_distribution<Real> unit(-1, 1), positive(0.5, 2);
    std::vector<Real> gradient, mass;
    for (std::size_t p = 0; p < f.list.pairs(); ++p) gradient.push_back(unit(rng));
    for (std::size_t i = 0; i < f.x.size(); ++i) mass.push_back(positive(rng));
    std::vector<Real> d2(f.list.pairs());
    sweeps::squaredDistances(0, f.x.size(), f.list, f.xRows.data(), d2.data());
    sweeps::PairWeights weights(f.list.pairs());
    sweeps::Rows sums(f.x.size());
    sweeps::pressureWeights(0, f.x.size(), f.list, f.xRows.data(), gradient.data(), mass.data(), weights.data(),
                            sums.data());
    // a range that starts further on writes from its first pair (distances) and particle (sums) on
    std::vector<Real> d2Later(f.list.pairs() - f.list.first(13));
    sweeps::squaredDistances(13, f.x.size(), f.list, f.xRows.data(), d2Later.data());
    sweeps::PairWeights weightsLater(f.list.pairs());
    sweeps::Rows sumsLater(f.x.size() - 13);
    sweeps::pressureWeights(13, f.x.size(), f.list, f.xRows.data(), gradient.data(), mass.data(), weightsLater.data(),
                            sumsLater.data());
    for (std::size_t i = 0; i < f.x.size(); ++i) {
        Vec3 sum = Vec3::Zero();
        Real squares = 0;
        for (std::size_t p = f.list.first(i); p < f.list.last(i); ++p) {
            const std::uint32_t j = f.list.indices[p];
            const Vec3 d = f.x[i] - f.x[j];
            EXPECT_NEAR(d2[p], d.squaredNorm(), kTolerance) << "pair " << p;
            EXPECT_EQ(weights[p], sweeps::PairWeight(mass[j] * gradient[p])) << "pair " << p;
            if (i >= 13) {
                EXPECT_EQ(d2Later[p - f.list.first(13)], d2[p]) << "pair " << p;
                EXPECT_EQ(weightsLater[p], weights[p]) << "pair " << p;
            }
            const Vec3 g = Real(weights[p]) * d;
            sum += g;
            squares += g.squaredNorm();
        }
        EXPECT_LT((sums[i].head<3>() - sum).norm(), kTolerance) << "particle " << i;
        EXPECT_NEAR(sums[i][3], squares, kTolerance) << "particle " << i;
        if (i >= 13) {
            EXPECT_EQ(sumsLater[i - 13], sums[i]) << "particle " << i;
        }
    }
}

TEST(PairSweeps, TakeTheViscousWeightsAndBlocksAsDefinedPairByPair) {
    Field f = field(40);
    std::mt19937_64 rng(11);
    std::uniform_real_distribution<Real> positive(0.5, 2);
    std::vector<Real> gradient, mass, inverseDensity, mu;
    for (std::size_t p = 0; p < f.list.pairs(); ++p) gradient.push_back(-positive(rng));
    for (std::size_t i = 0; i < f.x.size(); ++i)
        mass.push_back(positive(rng)), inverseDensity.push_back(positive(rng)), mu.push_back(positive(rng));
    for (const bool varies : {false, true}) {
        sweeps::ViscousWeightTerms t;
        t.gradient = gradient.data(), t.mass = mass.data(), t.inverseDensity = inverseDensity.data();
        t.mu = varies ? mu.data() : nullptr;
        t.muConstant = 1.7, t.c = 0.3, t.eps = 0.01, t.inverseSpacing2 = 4, t.linear = 0.1, t.quadratic = 0.8;
        sweeps::PairWeights weights(f.list.pairs());
        std::vector<Mat3> blocks(f.x.size());
        sweeps::viscousWeights(0, f.x.size(), f.list, f.xRows.data(), t, weights.data(), blocks.data());
        for (std::size_t i = 0; i < f.x.size(); ++i) {
            Mat3 block = Mat3::Zero();
            for (std::size_t p = f.list.first(i); p < f.list.last(i); ++p) {
                const std::size_t j = f.list.indices[p];
                const Vec3 d = f.x[i] - f.x[j];
                const Real u = d.squaredNorm() * t.inverseSpacing2 - 1;
                const Real muI = varies ? mu[i] : t.muConstant, muJ = varies ? mu[j] : t.muConstant;
                const Real k = t.c * (muI + muJ) * (mass[i] + mass[j]) * gradient[p] *
                               (1 + u * (t.linear + u * t.quadratic)) / (d.squaredNorm() + t.eps) *
                               (inverseDensity[i] * inverseDensity[j]);
                // stored in single precision: within its rounding of the double value
                EXPECT_NEAR(weights[p], k, 1e-6 * std::abs(k)) << "pair " << p;
                block += Real(weights[p]) * d * d.transpose();
            }
            // the weights reach hundreds here (the shape's quadratic at |x_ij| up to 3.5): relative round-off
            EXPECT_LT((blocks[i] - block).norm(), kTolerance * std::max(Real(1), block.norm())) << "particle " << i;
        }
    }
}

}  // namespace
}  // namespace ganache

#include "physics/viscosity/coarse_space.h"

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <map>
#include <random>

using namespace ganache;

namespace {

// A jittered lattice with a symmetric pair system like Eq. 7's: (M v)_i = v_i - dt sum_j k_ij (x_ij . v_ij) x_ij,
// k_ij < 0 and equal for both orders of a pair.
struct PairSystem {
    std::vector<Vec3> x;
    NeighbourList fluid;
    sweeps::PairWeights k;
    Real dt = 0.01;

    // side^3 jittered lattice points from each corner
    explicit PairSystem(int side, const std::vector<Vec3>& corners = {Vec3::Zero()}) {
        std::mt19937 rng(7);
        std::uniform_real_distribution<Real> jitter(-0.1, 0.1);
        for (const Vec3& corner : corners)
            for (int a = 0; a < side; ++a)
                for (int b = 0; b < side; ++b)
                    for (int c = 0; c < side; ++c)
                        x.push_back(corner + Vec3(a + jitter(rng), b + jitter(rng), c + jitter(rng)));
        UniformGrid grid(kSupport);
        findFluidNeighbours(grid, x, kSupport, fluid);
        k.resize(fluid.pairs());
        for (std::size_t i = 0; i < x.size(); ++i)
            for (std::size_t p = fluid.first(i); p < fluid.last(i); ++p)
                k[p] = sweeps::PairWeight(-1e3 / (1 + (x[i] - x[fluid.indices[p]]).squaredNorm()));  // symmetric
    }
    std::vector<Vec3> multiply(const std::vector<Vec3>& v) const {
        std::vector<Vec3> out(v.size());
        for (std::size_t i = 0; i < x.size(); ++i) {
            Vec3 a = Vec3::Zero();
            for (std::size_t p = fluid.first(i); p < fluid.last(i); ++p) {
                const std::uint32_t j = fluid.indices[p];
                const Vec3 d = x[i] - x[j];
                a += k[p] * d.dot(v[i] - v[j]) * d;
            }
            out[i] = v[i] - dt * a;
        }
        return out;
    }
    static constexpr Real kSupport = 2.1;
};

/// max_i |a_i - b_i| relative to max_i |b_i|.
Real largestDifference(const std::vector<Vec3>& a, const std::vector<Vec3>& b) {
    Real worst = 0, scale = 0;
    for (std::size_t i = 0; i < a.size(); ++i) {
        worst = std::max(worst, (a[i] - b[i]).norm());
        scale = std::max(scale, b[i].norm());
    }
    return worst / scale;
}

}  // namespace

TEST(ClusterModes, RecoversAnyRigidMotionOfTheClusters) {
    // The coarse correction is Z (Z^T M Z)^-1 Z^T: applied to M Z y it must give back Z y, the velocity field in
    // which each cluster moves rigidly. Any slip in assembling E (a sign, a missed pair across clusters, a block
    // in the wrong place) breaks this identity; round-off keeps it to about 1e-12 of the motion. With one cluster
    // a cell; with two interleaved groups (a cluster per cell and group, as molten and solid particles are kept
    // apart); and with every third particle in no cluster (as runny ones), where Z y is zero.
    const PairSystem s(9);
    using Groups = std::vector<std::uint8_t>;
    Groups alternate(s.x.size()), someOutside(s.x.size());
    for (std::size_t i = 0; i < s.x.size(); ++i) {
        alternate[i] = std::uint8_t(i % 2);
        someOutside[i] = i % 3 == 0 ? ClusterModes::kNoCluster : 0;
    }
    for (const Groups* group : {static_cast<const Groups*>(nullptr), static_cast<const Groups*>(&alternate),
                                static_cast<const Groups*>(&someOutside)}) {
        ClusterModes modes;
        modes.build(s.x, group, 2 * PairSystem::kSupport, 1000, s.fluid, s.k, s.dt, {});
        ASSERT_EQ(modes.clusters(), group == &alternate ? 16u : 8u);
        // a rigid motion per cluster (cells of side 4.2 over a 9^3 lattice): the velocity of particle i in its cell
        std::mt19937 rng(3);
        std::normal_distribution<Real> normal;
        std::vector<Vec3> zy(s.x.size());
        std::map<std::array<int, 4>, std::pair<Vec3, Vec3>> motions;
        Vec3 lo = s.x[0];
        for (const Vec3& xi : s.x) lo = lo.cwiseMin(xi);  // the cells start at the lowest corner
        for (std::size_t i = 0; i < s.x.size(); ++i) {
            const Vec3 cellOf = ((s.x[i] - lo) / (2 * PairSystem::kSupport)).array().floor();
            const std::array<int, 4> cluster{int(cellOf.x()), int(cellOf.y()), int(cellOf.z()), group ? (*group)[i] : 0};
            if (cluster[3] == ClusterModes::kNoCluster) {
                zy[i].setZero();
                continue;
            }
            auto [it, fresh] = motions.try_emplace(cluster);
            if (fresh)
                it->second = {Vec3(normal(rng), normal(rng), normal(rng)), Vec3(normal(rng), normal(rng), normal(rng))};
            zy[i] = it->second.first + it->second.second.cross(s.x[i]);
        }
        std::vector<Vec3> z(s.x.size(), Vec3::Zero());
        modes.addCorrection(s.x, s.multiply(zy), z);
        EXPECT_LT(largestDifference(z, zy), 1e-9) << (!group ? "one group" : group == &alternate ? "two groups" : "some outside");
    }
}

TEST(ClusterModes, FewerLargerClustersStillHoldTheWholeFluidsRigidMotion) {
    // Capped at 8 clusters the 27 cells of a 12^3 lattice grow until 8 are occupied; a rigid motion of the whole
    // lattice lies in the span of any clustering, so the correction still recovers it (to round-off, as above).
    const PairSystem s(12);
    ClusterModes modes;
    modes.build(s.x, nullptr, 2 * PairSystem::kSupport, 8, s.fluid, s.k, s.dt, {});
    EXPECT_LE(modes.clusters(), 8u);
    EXPECT_GE(modes.clusters(), 2u);  // not one cell for everything
    std::vector<Vec3> motion(s.x.size());
    for (std::size_t i = 0; i < s.x.size(); ++i) motion[i] = Vec3(0.3, -1, 2) + Vec3(1, 0.5, -0.2).cross(s.x[i]);
    std::vector<Vec3> z(s.x.size(), Vec3::Zero());
    modes.addCorrection(s.x, s.multiply(motion), z);
    EXPECT_LT(largestDifference(z, motion), 1e-9);
}

TEST(ClusterModes, CountsTheClustersOfFluidFarApart) {
    // Two lumps 2,000 spacings apart along every axis: the fluid's box holds about 10^8 cells of the coarse space for
    // 250 particles, too many for the table that counts occupied cells, so the clusters are counted from the sorted
    // keys. The same clusters either way: one per occupied cell; capped at 2, the cells grow until each lump is one.
    const PairSystem s(5, {Vec3::Zero(), Vec3::Constant(2000)});
    const Real cell = 2 * PairSystem::kSupport;
    Vec3 lo = s.x[0];
    for (const Vec3& xi : s.x) lo = lo.cwiseMin(xi);
    std::map<std::array<int, 3>, int> occupied;
    for (const Vec3& xi : s.x) {
        const Vec3 c = ((xi - lo) / cell).array().floor();
        ++occupied[{int(c.x()), int(c.y()), int(c.z())}];
    }
    ClusterModes modes;
    modes.build(s.x, nullptr, cell, 1000, s.fluid, s.k, s.dt, {});
    EXPECT_EQ(modes.clusters(), occupied.size());
    modes.build(s.x, nullptr, cell, 2, s.fluid, s.k, s.dt, {});
    EXPECT_EQ(modes.clusters(), 2u);
}

TEST(BlockLdlt, SolvesASparseBlockSystemAsADenseFactorisationDoes) {
    // A symmetric positive definite matrix of 6x6 blocks coupled as the cells of a 4 x 4 x 3 grid are (the coarse
    // system's pattern: each cluster with its face, edge and corner neighbours), with random blocks. Its solution must
    // match a dense LDL^T of the same matrix to round-off: about 1e-13 of the solution for this conditioning.
    constexpr int nx = 4, ny = 4, nz = 3, m = nx * ny * nz;
    std::mt19937 rng(11);
    std::normal_distribution<Real> normal;
    auto randomBlock = [&] {
        Mat6 b;
        for (int r = 0; r < 6; ++r)
            for (int c = 0; c < 6; ++c) b(r, c) = normal(rng);
        return b;
    };
    Eigen::MatrixXd dense = Eigen::MatrixXd::Zero(6 * m, 6 * m);
    std::vector<std::vector<std::pair<std::uint32_t, Mat6>>> lower(m);
    auto index = [&](int a, int b, int c) { return (a * ny + b) * nz + c; };
    for (int a = 0; a < nx; ++a)
        for (int b = 0; b < ny; ++b)
            for (int c = 0; c < nz; ++c)
                for (int da = -1; da <= 1; ++da)
                    for (int db = -1; db <= 1; ++db)
                        for (int dc = -1; dc <= 1; ++dc) {
                            const int p = a + da, q = b + db, r = c + dc;
                            if (p < 0 || p >= nx || q < 0 || q >= ny || r < 0 || r >= nz) continue;
                            const int i = index(a, b, c), j = index(p, q, r);
                            if (j <= i) continue;
                            const Mat6 block = 0.1 * randomBlock();  // E[i, j]
                            lower[std::size_t(i)].emplace_back(std::uint32_t(j), block);
                            dense.block<6, 6>(6 * i, 6 * j) = block;
                            dense.block<6, 6>(6 * j, 6 * i) = block.transpose();
                        }
    for (int i = 0; i < m; ++i) {
        const Mat6 g = randomBlock();
        const Mat6 diagonal = g * g.transpose() + 30 * Mat6::Identity();  // dominant: 26 neighbours of 0.1 N(0, 1)
        dense.block<6, 6>(6 * i, 6 * i) = diagonal;
        lower[std::size_t(i)].insert(lower[std::size_t(i)].begin(), {std::uint32_t(i), diagonal});
    }
    BlockLdlt factor;
    factor.factor(lower);
    Eigen::VectorXd b(6 * m);
    for (int i = 0; i < 6 * m; ++i) b[i] = normal(rng);
    const Eigen::VectorXd expected = dense.ldlt().solve(b);
    Eigen::VectorXd x = b;
    factor.solve(x);
    EXPECT_LT((x - expected).norm(), 1e-12 * expected.norm());
}

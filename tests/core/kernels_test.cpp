#include "core/kernels.h"

#include <gtest/gtest.h>

#include <cmath>
#include <vector>

using namespace ganache;

namespace {

// Sum of V W over a cubic lattice of spacing d around `centre`, V = d^3: the discrete integral of W.
Real latticeIntegral(const CubicSpline& w, Real d, const Vec3& centre) {
    const int m = int(std::ceil(w.supportRadius() / d)) + 1;
    Real sum = 0;
    for (int k = -m; k <= m; ++k)
        for (int j = -m; j <= m; ++j)
            for (int i = -m; i <= m; ++i) sum += w.W(Vec3(i * d, j * d, k * d) - centre);
    return sum * d * d * d;
}

}  // namespace

TEST(CubicSpline, IntegratesToOneOnALattice) {
    const CubicSpline w(0.1);
    // The midpoint rule on a lattice of h/8 converges at second order; 1e-3 is the bound and the
    // measured error at this spacing is well below it. Off-centre too: the sum must not rely on symmetry.
    EXPECT_NEAR(latticeIntegral(w, 0.1 / 8, Vec3::Zero()), 1.0, 1e-3);
    EXPECT_NEAR(latticeIntegral(w, 0.1 / 8, Vec3(0.003, -0.0051, 0.0017)), 1.0, 1e-3);
}

TEST(CubicSpline, HasCompactSupportAndIsContinuous) {
    const CubicSpline w(0.2);
    EXPECT_EQ(w.W(0.2), 0.0);
    EXPECT_EQ(w.W(0.25), 0.0);
    EXPECT_EQ(w.gradW(Vec3(0.2, 0, 0)), Vec3::Zero());
    EXPECT_GT(w.W(0.199), 0.0);
    EXPECT_DOUBLE_EQ(w.W(0.0), w.W0());
    // The two polynomial pieces meet at q = 1/2.
    EXPECT_NEAR(w.W(0.1 - 1e-12), w.W(0.1 + 1e-12), 1e-6 * w.W0());
}

TEST(CubicSpline, GradientIsAntisymmetric) {
    const CubicSpline w(0.1);
    for (const Vec3& r : {Vec3(0.031, -0.012, 0.027), Vec3(0.01, 0.0, 0.0), Vec3(-0.06, 0.05, 0.02)})
        EXPECT_TRUE((w.gradW(r) + w.gradW(-r)).norm() < 1e-12 * w.gradW(r).norm());
    EXPECT_EQ(w.gradW(Vec3::Zero()), Vec3::Zero());
}

TEST(CubicSpline, GradientMatchesCentralDifference) {
    const CubicSpline w(0.1);
    // Both kernel pieces: q about 0.43 and about 0.79.
    for (const Vec3& r : {Vec3(0.031, -0.012, 0.027), Vec3(0.05, 0.06, -0.01)}) {
        for (int axis = 0; axis < 3; ++axis) {
            const Vec3 e = Real(1e-6) * Vec3::Unit(axis);
            const Real fd = (w.W(r + e) - w.W(r - e)) / 2e-6;
            // Central differences err by O(e^2 W'''), about 1e-9 relative here.
            EXPECT_NEAR(w.gradW(r)[axis], fd, 1e-6 * std::max<Real>(1, std::abs(fd)));
        }
    }
}

TEST(CubicSpline, BulkEvaluationIsBitForBitTheScalarOne) {
    // The solvers take the step's kernel values through the vectorised bulk form; a simulation's bytes must not
    // change with it. Distances cover both pieces, their seam, zero, below the zero-gradient guard, and the support's
    // edge and beyond; more than one SIMD vector, with a remainder.
    const CubicSpline w(0.1);
    std::vector<Real> r = {0, 1e-14, 1e-12, 0.001, 0.02, 0.05 - 1e-15, 0.05, 0.05 + 1e-15, 0.0731, 0.099999, 0.1, 0.13};
    for (int k = 0; k < 23; ++k) r.push_back(0.1 * std::sqrt((k + 0.5) / 23));
    std::vector<Real> r2(r.size()), values(r.size());
    for (std::size_t p = 0; p < r.size(); ++p) r2[p] = r[p] * r[p];
    w.valuesAndGradients(r2.size(), r2.data(), values.data());
    for (std::size_t p = 0; p < r.size(); ++p) {
        const Real rp = std::sqrt(r[p] * r[p]);
        EXPECT_EQ(values[p], w.W(rp)) << "r = " << r[p];
        EXPECT_EQ(r2[p], w.gradFactor(rp)) << "r = " << r[p];
    }
}

TEST(CubicSpline, RejectsNonPositiveSupport) {
    EXPECT_THROW(CubicSpline(0.0), std::invalid_argument);
    EXPECT_THROW(CubicSpline(-1.0), std::invalid_argument);
}

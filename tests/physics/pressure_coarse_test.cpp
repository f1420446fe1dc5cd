// The pressure solves' coarse space: its system is the pressure system's R A R^T, a resumed run gets the same one
// back, and a landing solved with it ends as near the converged landing as one solved without it, in fewer products.
#include "physics/gravity.h"
#include "physics/pressure/pressure_coarse.h"
#include "physics/viscosity/viscosity.h"
#include "world.h"

#include <gtest/gtest.h>

#include <random>

using namespace ganache;
using namespace ganache::testing;

namespace {

constexpr Real kSupport = 2;

// A jittered lattice of spacing 1 with the pressure sweeps' data: pair weights symmetric in the pair (equal masses),
// and a boundary sum on the bottom layer, as a floor gives.
struct PressurePairs {
    std::vector<Vec3> x, boundarySum, gradientSum;
    std::vector<Real> mass;
    NeighbourList fluid;
    sweeps::PairWeights w;
    sweeps::Rows rows;

    // `side`^3 lattice points, then the `extra` ones.
    explicit PressurePairs(int side, const std::vector<Vec3>& extra = {}) {
        std::mt19937 rng(11);
        std::uniform_real_distribution<Real> jitter(-0.1, 0.1);
        for (int a = 0; a < side; ++a)
            for (int b = 0; b < side; ++b)
                for (int c = 0; c < side; ++c)
                    x.push_back(Vec3(a + jitter(rng), b + jitter(rng), c + jitter(rng)) + Vec3::Constant(0.5));
        x.insert(x.end(), extra.begin(), extra.end());
        const std::size_t n = x.size();
        UniformGrid grid(kSupport);
        findFluidNeighbours(grid, x, kSupport, fluid);
        mass.assign(n, 1);
        rows.resize(n);
        sweeps::toRows(0, n, x.data(), rows.data());
        for (std::size_t i = 0; i < n; ++i) {
            boundarySum.push_back(x[i].y() < 0.5 ? Vec3(0, -0.3, 0) : Vec3::Zero());
            Vec3 g = boundarySum[i];
            for (std::size_t p = fluid.first(i); p < fluid.last(i); ++p) {
                const Vec3 d = x[i] - x[fluid.indices[p]];
                w.push_back(sweeps::PairWeight(-1 / (0.5 + d.squaredNorm())));
                g += Real(w.back()) * d;
            }
            gradientSum.push_back(g);
        }
    }
    // A s = C B s (the system without dt^2): minus the density rate of the velocity change of the pressures s at dt 1.
    std::vector<Real> multiply(const std::vector<Real>& s) const {
        const std::size_t n = x.size();
        std::vector<Vec3> dv(n);
        sweeps::Rows dvRows(n);
        std::vector<Real> rate(n);
        sweeps::pressureChange(0, n, {&fluid, w.data()}, boundarySum.data(), rows.data(), s.data(), 1, dv.data(),
                               dvRows.data());
        sweeps::densityRate(0, n, {&fluid, w.data()}, boundarySum.data(), nullptr, rows.data(), dvRows.data(),
                            rate.data());
        for (Real& r : rate) r = -r;
        return rate;
    }
    void build(PressureCoarseSpace& coarse, std::size_t maxCells = 1000) const {
        coarse.build(x, mass, fluid, w, rows, gradientSum, 2 * kSupport, kSupport, maxCells);
    }
};

// R A R^T y for pressures y per cell.
Eigen::VectorXd coarseProduct(const PressurePairs& f, const PressureCoarseSpace& coarse, const Eigen::VectorXd& y) {
    std::vector<Real> s(f.x.size());
    for (std::size_t i = 0; i < s.size(); ++i) s[i] = y[coarse.cellOf(i)];
    const std::vector<Real> as = f.multiply(s);
    Eigen::VectorXd out = Eigen::VectorXd::Zero(y.size());
    for (std::size_t i = 0; i < s.size(); ++i) out[coarse.cellOf(i)] += as[i];
    return out;
}

}  // namespace

TEST(PressureCoarseSpace, SolvesThePressureSystemRestrictedToItsCells) {
    // 10^3 particles of spacing 1 in cells of side 4: 27 cells, every particle in one. Solving R A R^T z = R A R^T y
    // must give y back: the coarse system is the pressure system's own product summed by cell, not an approximation
    // of it. 1e-9 relative: the coarse system's condition number (the cells' Laplacian, about 10) times round-off.
    // Capped at 8 cells, the cells grow (to side 6: 2 an axis) and the same holds.
    const PressurePairs f(10);
    for (const auto& [maxCells, expected] : {std::pair<std::size_t, std::size_t>{1000, 27}, {8, 8}}) {
        PressureCoarseSpace coarse;
        f.build(coarse, maxCells);
        ASSERT_TRUE(coarse.active());
        EXPECT_EQ(coarse.cells(), expected);
        std::mt19937 rng(3);
        std::uniform_real_distribution<Real> unit(-1, 1);
        Eigen::VectorXd y(coarse.cells());
        for (auto& v : y) v = unit(rng);
        Eigen::VectorXd z = coarseProduct(f, coarse, y);
        coarse.solve(z);
        EXPECT_LT((z - y).norm(), 1e-9 * y.norm()) << "at most " << maxCells << " cells";
    }
}

TEST(PressureCoarseSpace, ACellOfParticlesWithoutNeighboursLeavesTheOthersExact) {
    // A particle thrown off alone into a cell of its own has no pushes: its cell's row of R A R^T is empty, and the
    // factorisation, given it as it was, failed on the zero pivot (a 56k bunny landing at 5 ms steps stopped there).
    // The other cells must still be solved exactly, as in SolvesThePressureSystemRestrictedToItsCells.
    const PressurePairs f(10, {Vec3(30.5, 30.5, 30.5)});
    PressureCoarseSpace coarse;
    ASSERT_NO_THROW(f.build(coarse));
    ASSERT_EQ(coarse.cells(), 28u);
    const std::uint32_t alone = coarse.cellOf(f.x.size() - 1);
    Eigen::VectorXd y = Eigen::VectorXd::LinSpaced(Eigen::Index(coarse.cells()), -1, 1);
    y[alone] = 0;
    Eigen::VectorXd z = coarseProduct(f, coarse, y);
    EXPECT_EQ(z[alone], 0);
    coarse.solve(z);
    EXPECT_LT((z - y).norm(), 1e-9 * y.norm());
}

TEST(PressureCoarseSpace, ComesBackFromItsSavedBytesAsItWas) {
    const PressurePairs f(10);
    PressureCoarseSpace built, restored;
    f.build(built);
    ByteWriter out;
    built.save(out);
    ByteReader in(out.bytes);
    restored.restore(in);
    EXPECT_TRUE(in.atEnd());
    restored.assign(f.x);
    ASSERT_EQ(restored.cells(), built.cells());
    for (std::size_t i = 0; i < f.x.size(); ++i) ASSERT_EQ(restored.cellOf(i), built.cellOf(i)) << "particle " << i;
    Eigen::VectorXd a = Eigen::VectorXd::LinSpaced(Eigen::Index(built.cells()), -1, 1), b = a;
    built.solve(a);
    restored.solve(b);
    for (Eigen::Index c = 0; c < a.size(); ++c) EXPECT_EQ(a[c], b[c]) << "cell " << c;  // the same bytes

    // Bytes cut short or with a cell's coordinates changed are refused, never half taken.
    ByteReader cut(std::string_view(out.bytes).substr(0, out.bytes.size() / 2));
    EXPECT_THROW(restored.restore(cut), std::runtime_error);
    std::string moved = out.bytes;
    moved[sizeof(Real) + sizeof(std::uint64_t)] ^= 0x1;  // the first cell's x coordinate
    ByteReader movedIn(moved);
    EXPECT_THROW(restored.restore(movedIn), std::runtime_error);
}

// The build's grid takes Z order or row order by how many particles it holds (UniformGrid::kSlabPoints), which the
// saved cells do not say: 175,616 particles in 2,744 cells take Z order, where the cells' centres alone would take row
// order. Such a checkpoint of a 1M-particle statue was refused as "out of order" before restore tried both orders.
TEST(PressureCoarseSpace, ComesBackInTheOrderOfAGridOfManyParticles) {
    const PressurePairs big(56);
    PressureCoarseSpace built, restored;
    big.build(built, 4096);
    ASSERT_EQ(built.cells(), 2744U);  // cells of 2 supports, 14 a side: none grew
    ByteWriter out;
    built.save(out);
    ByteReader in(out.bytes);
    ASSERT_NO_THROW(restored.restore(in));
    restored.assign(big.x);
    for (std::size_t i = 0; i < big.x.size(); ++i) ASSERT_EQ(restored.cellOf(i), built.cellOf(i)) << "particle " << i;
    // Its next build, of a body that takes row order, is the uninterrupted run's: the grid the restore found keeps no
    // order of its own.
    const PressurePairs small(20);
    PressureCoarseSpace fresh;
    small.build(fresh, 4096);
    small.build(restored, 4096);
    ByteWriter a, b;
    fresh.save(a);
    restored.save(b);
    EXPECT_TRUE(a.bytes == b.bytes) << "the restored space built other cells, or in another order";
}

namespace {

struct Landing {
    std::size_t products = 0;
    Vec3 centroid = Vec3::Zero();
    Real meanCompression = 0;
};

// A 0.1 x 0.15 x 0.1 m block of runny honey (100 Pa s) touching a floor, moving down at 1 m/s; the pressure solves
// stop at `densityError` and ten times that for the divergence (the defaults' ratio).
World landing(Real radius, std::int64_t coarseFrom, Real densityError = PressureSettings{}.densityError) {
    World world(radius, Vec3(-0.2, -0.05, -0.2), Vec3(0.2, 0.5, 0.2));
    world.block(Vec3(-0.05, 0.02, -0.05), Vec3(0.05, 0.17, 0.05), preset("honey"), 20, Vec3(0, -1, 0));
    world.plane("floor");
    world.effect<GravityParams>("gravity");
    world.effect<ViscosityParams>("viscosity").mu = 100;
    world.setup.pressure.coarseFrom = coarseFrom;
    world.setup.pressure.densityError = densityError;
    world.setup.pressure.divergenceError = 10 * densityError;
    world.setup.pressure.maxIterations = 5000;
    return world;
}

// The landing at r = 2.5 mm (12,000 particles, 30 layers), from its first contact over 30 steps.
Landing land(std::int64_t coarseFrom, Real densityError = PressureSettings{}.densityError) {
    Simulation sim = landing(0.0025, coarseFrom, densityError).simulation();
    Landing r;
    const std::size_t before = sim.stats().pressureIterations + sim.stats().divergenceIterations;
    for (int step = 0; step < 30; ++step) sim.step();
    r.products = sim.stats().pressureIterations + sim.stats().divergenceIterations - before;
    const std::size_t n = sim.particles().size();
    for (std::size_t i = 0; i < n; ++i) {
        r.centroid += sim.particles().x()[i] / Real(n);
        r.meanCompression += std::max<Real>(sim.density()[i] / sim.restDensity()[i] - 1, 0) / Real(n);
    }
    return r;
}

}  // namespace

TEST(PressureCoarseSpace, ALandingEndsNearTheConvergedOneInFewerProducts) {
    const Landing plain = land(std::numeric_limits<std::int32_t>::max()), coarse = land(0);
    // The same landing with both solves a hundred times stricter: a thousand times stricter moves its centroid by at
    // most 7 um, so this is the landing the solves converge to.
    const Landing converged = land(std::numeric_limits<std::int32_t>::max(), 1e-6);
    std::printf("products %zu without, %zu with the coarse space; centroid heights %.6f / %.6f m (converged %.6f), "
                "mean compression %.2e / %.2e (%.2e)\n",
                plain.products, coarse.products, plain.centroid.y(), coarse.centroid.y(), converged.centroid.y(),
                plain.meanCompression, coarse.meanCompression, converged.meanCompression);
    // An impact that keeps changing which particles hold pressure, the coarse space's hardest case (it saves 40 % on
    // the 50k anchor block): 333 products against 350.
    EXPECT_LT(coarse.products, plain.products);
    // Both solves stop at a mean residual of 0.01 % of rest density, and a body held to that ends a little lower than
    // the converged one: 0.13 mm lower without and with the coarse space, on a 2.5 mm particle radius. How much lower
    // scatters from tolerance to tolerance and does not shrink between 1e-4 and 2e-5: 0.03-0.30 mm over ten landings
    // (five tolerances, with and without the coarse space), and 0.02-0.35 mm with MPRGP's own proportioning steps,
    // whose 0.02 and 0.06 mm at 1e-4 were the low end of that scatter. 0.2 mm is 8 % of a radius; the expansions that
    // stopped at the first particle's bound (before kProjectedStep) left both 0.33 mm lower. The mean compression
    // after the particles move (what the linearised solve did not foresee: the converged landing's is 1.7e-4) exceeds
    // the converged one's by at most the solve's tolerance, 1e-4: measured 0 and 0.4e-4.
    EXPECT_LT((plain.centroid - converged.centroid).norm(), 2e-4);
    EXPECT_LT((coarse.centroid - converged.centroid).norm(), 2e-4);
    EXPECT_LT(plain.meanCompression, converged.meanCompression + 1e-4);
    EXPECT_LT(coarse.meanCompression, converged.meanCompression + 1e-4);
}

TEST(PressureCoarseSpace, AResumedRunSolvesWithTheSavedOneAndEndsOnTheSameBytes) {
    // Saved 3 steps after a build and resumed in a fresh simulation, past the next build: the same bytes as the run
    // that went on, which it would not be if the resumed run built its coarse system anew.
    const World world = landing(0.01, 0);
    Simulation sim = world.simulation();
    for (int step = 0; step < 11; ++step) sim.step();
    const SimulationState saved = sim.state();
    for (int step = 0; step < 8; ++step) sim.step();
    Simulation resumed = world.simulation();
    resumed.restore(saved);
    for (int step = 0; step < 8; ++step) resumed.step();
    ASSERT_EQ(resumed.particles().size(), sim.particles().size());
    for (std::size_t i = 0; i < sim.particles().size(); ++i) {
        ASSERT_EQ(resumed.particles().x()[i], sim.particles().x()[i]) << "particle " << i;
        ASSERT_EQ(resumed.particles().v()[i], sim.particles().v()[i]) << "particle " << i;
    }
}

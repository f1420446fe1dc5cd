#include "core/neighbour_search.h"

#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <algorithm>
#include <random>
#include <set>
#include <tuple>
#include <utility>

using namespace ganache;

namespace {

std::vector<Vec3> randomPoints(std::size_t n, const Vec3& lo, const Vec3& hi, unsigned seed) {
    std::mt19937_64 rng(seed);
    std::uniform_real_distribution<Real> u(0, 1);
    std::vector<Vec3> x(n);
    for (auto& p : x) p = lo + (hi - lo).cwiseProduct(Vec3(u(rng), u(rng), u(rng)));
    return x;
}

std::vector<std::set<std::uint32_t>> bruteForce(const std::vector<Vec3>& q, const std::vector<Vec3>& t, Real radius,
                                                bool sameSet) {
    std::vector<std::set<std::uint32_t>> out(q.size());
    for (std::size_t i = 0; i < q.size(); ++i)
        for (std::size_t j = 0; j < t.size(); ++j)
            if ((q[i] - t[j]).squaredNorm() < radius * radius && !(sameSet && i == j)) out[i].insert(std::uint32_t(j));
    return out;
}

void expectSameAsBruteForce(const NeighbourList& nl, const std::vector<std::set<std::uint32_t>>& expected) {
    ASSERT_EQ(nl.particles(), expected.size());
    for (std::size_t i = 0; i < expected.size(); ++i) {
        const auto r = nl.of(i);
        const std::set<std::uint32_t> got(r.begin(), r.end());
        ASSERT_EQ(got.size(), r.size()) << "duplicate neighbour of " << i;
        ASSERT_EQ(got, expected[i]) << "particle " << i;
    }
}

NeighbourList fluidSearch(const std::vector<Vec3>& x, Real radius) {
    UniformGrid grid(radius);
    NeighbourList nl;
    findFluidNeighbours(grid, x, radius, nl);
    return nl;
}

}  // namespace

TEST(NeighbourSearch, MatchesBruteForceOnRandomPoints) {
    // About 30 neighbours each, with points on both sides of the origin (negative cell coordinates).
    const auto x = randomPoints(3000, Vec3(-0.3, -0.2, -0.1), Vec3(0.3, 0.25, 0.2), 1);
    const Real radius = 0.06;
    expectSameAsBruteForce(fluidSearch(x, radius), bruteForce(x, x, radius, true));
}

TEST(NeighbourSearch, MatchesBruteForceBetweenTwoSets) {
    const auto fluid = randomPoints(1500, Vec3(0, 0, 0), Vec3(0.5, 0.5, 0.5), 2);
    const auto boundary = randomPoints(800, Vec3(-0.1, -0.1, -0.1), Vec3(0.6, 0.1, 0.6), 3);
    const Real radius = 0.07;
    UniformGrid fg(radius), bg(radius);
    fg.build(fluid);
    bg.build(boundary);
    NeighbourList nl;
    findNeighbours(fg, fluid, bg, boundary, radius, false, nl);
    expectSameAsBruteForce(nl, bruteForce(fluid, boundary, radius, false));
}

TEST(NeighbourSearch, AllPointsInOneCell) {
    const auto x = randomPoints(200, Vec3(0.01, 0.01, 0.01), Vec3(0.02, 0.02, 0.02), 4);
    const NeighbourList nl = fluidSearch(x, 0.05);
    for (std::size_t i = 0; i < x.size(); ++i) EXPECT_EQ(nl.of(i).size(), x.size() - 1);
}

TEST(NeighbourSearch, CoincidentPointsAreNeighboursButNotOfThemselves) {
    const std::vector<Vec3> x(5, Vec3(0.3, -0.2, 0.1));
    const NeighbourList nl = fluidSearch(x, 0.01);
    expectSameAsBruteForce(nl, bruteForce(x, x, 0.01, true));
    EXPECT_EQ(nl.pairs(), 20u);
}

TEST(NeighbourSearch, VerySparsePointsHaveNoNeighbours) {
    const auto x = randomPoints(100, Vec3(-500, -500, -500), Vec3(500, 500, 500), 5);
    const NeighbourList nl = fluidSearch(x, 0.01);
    EXPECT_EQ(nl.pairs(), 0u);
    EXPECT_EQ(nl.particles(), 100u);
}

TEST(NeighbourSearch, DenseTableAndHashGiveTheSameLists) {
    // Cells are found through a dense table when the occupied cells fill their bounding box well, else through the
    // hash: two compact clusters far apart take the hash, each alone the table, and all match brute force.
    const auto a = randomPoints(600, Vec3(0, 0, 0), Vec3(0.3, 0.3, 0.3), 8);
    const auto b = randomPoints(600, Vec3(20, -5, 3), Vec3(20.3, -4.7, 3.3), 9);
    std::vector<Vec3> both = a;
    both.insert(both.end(), b.begin(), b.end());
    const Real radius = 0.05;
    const std::vector<Vec3>* sets[] = {&a, &both};
    for (const std::vector<Vec3>* x : sets) {
        UniformGrid grid(radius);
        grid.build(*x);
        EXPECT_EQ(grid.dense(), x == &a);
        NeighbourList nl;
        findNeighbours(grid, *x, grid, *x, radius, true, nl);
        expectSameAsBruteForce(nl, bruteForce(*x, *x, radius, true));
    }
}

TEST(NeighbourSearch, ADenseTargetFoundFromEveryCellAroundItsBox) {
    // The cells around a query cell are read from the target's dense table without a test of bounds: queries from
    // every side of a compact target, up to two cells past its box, must find what brute force finds.
    const Real radius = 0.05;
    const auto target = randomPoints(2000, Vec3(0, 0, 0), Vec3(0.3, 0.2, 0.25), 10);
    const auto query = randomPoints(4000, Vec3(-0.12, -0.12, -0.12), Vec3(0.42, 0.32, 0.37), 11);
    UniformGrid qg(radius), tg(radius);
    qg.build(query);
    tg.build(target);
    ASSERT_TRUE(tg.dense());
    NeighbourList nl;
    findNeighbours(qg, query, tg, target, radius, false, nl);
    expectSameAsBruteForce(nl, bruteForce(query, target, radius, false));
}

TEST(NeighbourSearch, EmptyInputs) {
    const NeighbourList empty = fluidSearch({}, 0.1);
    EXPECT_EQ(empty.particles(), 0u);
    // Fluid against an empty boundary: every list empty.
    const auto fluid = randomPoints(10, Vec3::Zero(), Vec3::Ones(), 6);
    UniformGrid fg(0.1), bg(0.1);
    fg.build(fluid);
    bg.build({});
    NeighbourList nl;
    findNeighbours(fg, fluid, bg, {}, 0.1, false, nl);
    EXPECT_EQ(nl.particles(), 10u);
    EXPECT_EQ(nl.pairs(), 0u);
}

TEST(NeighbourSearch, ASetSearchedAgainstItselfNeedsOneGrid) {
    // The search leaves a point out of its own list by its place in the grid's sorted order, which only the one grid
    // the set was sorted into gives.
    const auto x = randomPoints(100, Vec3::Zero(), Vec3::Ones(), 12);
    UniformGrid a(0.2), b(0.2);
    a.build(x);
    b.build(x);
    NeighbourList nl;
    EXPECT_THROW(findNeighbours(a, x, b, x, 0.2, true, nl), std::logic_error);
    EXPECT_NO_THROW(findNeighbours(a, x, b, x, 0.2, false, nl));
}

TEST(NeighbourSearch, PointsExactlyOnCellFaces) {
    // Lattice points at multiples of the radius sit on cell boundaries; pairs at exactly the radius are out.
    std::vector<Vec3> x;
    for (int k = -2; k <= 2; ++k)
        for (int j = -2; j <= 2; ++j)
            for (int i = -2; i <= 2; ++i) x.push_back(Real(0.05) * Vec3(i, j, k));
    expectSameAsBruteForce(fluidSearch(x, 0.1), bruteForce(x, x, 0.1, true));
}

TEST(NeighbourSearch, SameListsForAnyThreadCount) {
    const auto x = randomPoints(20000, Vec3::Zero(), Vec3::Ones(), 7);
    NeighbourList one, two;
    {
        tbb::global_control c(tbb::global_control::max_allowed_parallelism, 1);
        one = fluidSearch(x, 0.04);
    }
    {
        tbb::global_control c(tbb::global_control::max_allowed_parallelism, 2);
        two = fluidSearch(x, 0.04);
    }
    EXPECT_EQ(one.offsets, two.offsets);
    EXPECT_EQ(one.indices, two.indices);
}

TEST(NeighbourSearch, SortedOrderIsAPermutationGroupedByCell) {
    const auto x = randomPoints(5000, Vec3(-1, -1, -1), Vec3(1, 1, 1), 8);
    UniformGrid grid(0.1);
    grid.build(x);
    std::vector<std::uint32_t> perm = grid.sortedIndices();
    std::vector<std::uint32_t> sorted = perm;
    std::sort(sorted.begin(), sorted.end());
    for (std::uint32_t i = 0; i < sorted.size(); ++i) ASSERT_EQ(sorted[i], i);
    for (std::size_t c = 0; c < grid.cellCount(); ++c) {
        const auto& cc = grid.cellCoords(c);
        EXPECT_EQ(grid.findCell(cc[0], cc[1], cc[2]), std::int64_t(c));
        for (std::size_t s = grid.cellBegin(c); s < grid.cellBegin(c + 1); ++s) {
            const Vec3 cell = (x[perm[s]] / 0.1).array().floor();
            EXPECT_EQ(cell, Vec3(cc[0], cc[1], cc[2]));
        }
    }
}

TEST(NeighbourSearch, BothCellOrdersMatchBruteForce) {
    // Row order where three slabs of cells hold few points, Z order elsewhere: each is forced here on a fluid and a
    // boundary in different orders, and on points either side of the origin.
    const auto fluid = randomPoints(2500, Vec3(-0.3, -0.1, -0.2), Vec3(0.3, 0.1, 0.25), 10);
    const auto boundary = randomPoints(900, Vec3(-0.4, -0.2, -0.3), Vec3(0.4, -0.05, 0.3), 11);
    const Real radius = 0.06;
    const std::size_t zOrder = 0, rowOrder = std::size_t(1) << 40;
    for (const auto& [fluidSlab, boundarySlab] : {std::pair{rowOrder, zOrder}, std::pair{zOrder, rowOrder}}) {
        UniformGrid fg(radius, fluidSlab), bg(radius, boundarySlab);
        fg.build(fluid);
        bg.build(boundary);
        EXPECT_EQ(fg.rowOrder(), fluidSlab == rowOrder);
        EXPECT_EQ(bg.rowOrder(), boundarySlab == rowOrder);
        NeighbourList ff, fb;
        findNeighbours(fg, fluid, fg, fluid, radius, true, ff);
        findNeighbours(fg, fluid, bg, boundary, radius, false, fb);
        expectSameAsBruteForce(ff, bruteForce(fluid, fluid, radius, true));
        expectSameAsBruteForce(fb, bruteForce(fluid, boundary, radius, false));
        for (const UniformGrid* g : {&fg, &bg}) {
            for (std::size_t c = 0; c < g->cellCount(); ++c) {
                const auto& cc = g->cellCoords(c);
                ASSERT_EQ(g->findCell(cc[0], cc[1], cc[2]), std::int64_t(c));
            }
            EXPECT_EQ(g->findCell(1000, 0, 0), -1);  // outside the box the row keys cover
            EXPECT_EQ(g->findCell(0, -1000, 0), -1);
        }
        // In row order the cells run along the shortest side fastest and along the longest (x here) slowest.
        const UniformGrid& rows = fg.rowOrder() ? fg : bg;
        for (std::size_t c = 1; c < rows.cellCount(); ++c) {
            const auto& a = rows.cellCoords(c - 1);
            const auto& b = rows.cellCoords(c);
            EXPECT_TRUE(std::tie(a[0], a[2], a[1]) < std::tie(b[0], b[2], b[1])) << "cell " << c;
        }
    }
}

TEST(NeighbourSearch, RejectsNonFiniteAndFarPoints) {
    UniformGrid grid(0.01);
    EXPECT_THROW(grid.build({Vec3(0, 0, 0), Vec3(NAN, 0, 0)}), std::runtime_error);
    EXPECT_THROW(grid.build({Vec3(1e6, 0, 0)}), std::runtime_error);
}

TEST(NeighbourSearch, SortByKeyGivesTheOrderOfStdSort) {
    // Keys that differ in every byte, in a few bytes only (a small fluid's cells), and repeated keys (points sharing a
    // cell), each with ascending indices as the grid makes them.
    std::mt19937_64 rng(11);
    for (const std::uint64_t mask : {~std::uint64_t(0), std::uint64_t(0x00ff00000000f0f0), std::uint64_t(0x7)}) {
        for (const std::size_t n : {0, 1, 2, 300, 5000}) {
            std::vector<std::pair<std::uint64_t, std::uint32_t>> items(n), scratch;
            for (std::size_t i = 0; i < n; ++i) items[i] = {(rng() & mask) | 0x1234000000000000ULL, std::uint32_t(i)};
            auto expected = items;
            std::sort(expected.begin(), expected.end());
            sortByKey(items, scratch);
            EXPECT_EQ(items, expected) << "mask " << mask << ", " << n << " items";
            sortByKey(items, scratch);  // already in order: left as it is
            EXPECT_EQ(items, expected) << "mask " << mask << ", " << n << " items, sorted again";
        }
    }
}

// Neighbour search cost: grid build + compressed lists for fluid-fluid pairs, at 8k, 100k and 1M particles on 1 and 2
// threads, with particles in the grid's cell order (as the simulator keeps them: `ordered/n/threads/0`; /1 and /2 force
// Z order and row order, in the grid and in the particles) and shuffled (no reordering).
// Run: build/benchmarks/neighbour_search_bench --benchmark_counters_tabular=true

#include "core/kernels.h"
#include "core/neighbour_search.h"
#include "core/particles.h"

#include <benchmark/benchmark.h>
#include <tbb/global_control.h>

#include <algorithm>
#include <cmath>
#include <random>

using namespace ganache;

namespace {

constexpr Real kRadius = 0.01;  // particle radius; lattice spacing 2r, support radius h = 4r

// The grid's bound for row order: the grid's own choice (0), Z order (1) or row order (2).
std::size_t slabPoints(std::int64_t order) {
    return order == 0 ? UniformGrid::kSlabPoints : order == 1 ? 0 : std::size_t(1) << 40;
}

// A jittered lattice block of about n particles (jitter 10 % of the spacing, like a fluid at rest), shuffled or (order
// >= 0) in a grid's cell order.
std::vector<Vec3> fluidBlock(std::size_t n, std::int64_t order) {
    const int side = int(std::round(std::cbrt(Real(n))));
    std::mt19937_64 rng(42);
    std::uniform_real_distribution<Real> jitter(-0.1, 0.1);
    std::vector<Vec3> x;
    x.reserve(std::size_t(side) * side * side);
    const Real d = 2 * kRadius;
    for (int k = 0; k < side; ++k)
        for (int j = 0; j < side; ++j)
            for (int i = 0; i < side; ++i)
                x.push_back(d * Vec3(i + jitter(rng), j + jitter(rng), k + jitter(rng)));
    std::shuffle(x.begin(), x.end(), rng);
    if (order >= 0) {
        UniformGrid grid(supportRadiusFor(kRadius), slabPoints(order));
        grid.build(x);
        std::vector<Vec3> sorted;
        sorted.reserve(x.size());
        for (std::uint32_t i : grid.sortedIndices()) sorted.push_back(x[i]);
        x.swap(sorted);
    }
    return x;
}

void search(benchmark::State& state, std::int64_t order) {
    const std::size_t n = std::size_t(state.range(0));
    tbb::global_control threads(tbb::global_control::max_allowed_parallelism, std::size_t(state.range(1)));
    const std::vector<Vec3> x = fluidBlock(n, order);
    const Real h = supportRadiusFor(kRadius);
    UniformGrid grid(h, slabPoints(std::max<std::int64_t>(order, 0)));
    NeighbourList nl;
    // One search untimed: the simulator searches every step into buffers it keeps, so the first search's allocations
    // and page faults (most of a 1M search's time when it runs only once or twice) are not what a step pays.
    findFluidNeighbours(grid, x, h, nl);
    for (auto _ : state) {
        findFluidNeighbours(grid, x, h, nl);
        benchmark::DoNotOptimize(nl.indices.data());
    }
    state.counters["particles"] = Real(x.size());
    state.counters["threads"] = Real(state.range(1));
    state.counters["neighbours_per_particle"] = Real(nl.pairs()) / Real(x.size());
    state.counters["row_order"] = grid.rowOrder();
    state.counters["ns_per_particle"] =
        benchmark::Counter(Real(x.size()), benchmark::Counter::kIsIterationInvariantRate | benchmark::Counter::kInvert);
}

void ordered(benchmark::State& state) { search(state, state.range(2)); }
void shuffled(benchmark::State& state) { search(state, -1); }

}  // namespace

BENCHMARK(ordered)
    ->ArgsProduct({{8000, 100'000, 1'000'000}, {1, 2}, {0, 1, 2}})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();
BENCHMARK(shuffled)->ArgsProduct({{8000, 100'000, 1'000'000}, {1, 2}})->Unit(benchmark::kMillisecond)->UseRealTime();

BENCHMARK_MAIN();

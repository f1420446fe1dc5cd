// The solvers' inner loops on their own: one viscous product (I - dt A) v and one pressure product (a velocity change
// and a density rate) per iteration, and the viscous pairs' weights once a step (`viscousWeights`), on a jittered
// lattice block in the grid's cell order, at 8k, 50k, 200k and 1M
// particles on 1 and 2 threads; beside them the machine's streaming bandwidth (a triad over 256 MiB arrays), so that
// each product's cost can be set against the time its bytes take to move; and the viscous product alone on input rows
// that no thread rewrites between passes (`viscousKeptRows`), which shows what two threads lose to each other's fresh
// writes.
// Run: build/benchmarks/sweep_bench --benchmark_counters_tabular=true

#include "core/kernels.h"
#include "core/neighbour_search.h"
#include "core/parallel.h"
#include "physics/pair_sweeps.h"

#include <benchmark/benchmark.h>
#include <tbb/global_control.h>

#include <cmath>
#include <random>

using namespace ganache;

namespace {

constexpr Real kRadius = 0.01;

struct Block {
    std::vector<Vec3> x, v;
    sweeps::Rows xRows, vRows;  // as the sweeps read them
    NeighbourList pairs;
    sweeps::PairWeights weight;  // one per pair
};

// A jittered lattice block of about n particles in the grid's cell order (as the simulator keeps them), its neighbour
// lists and a weight per pair.
Block block(std::size_t n) {
    const int side = int(std::round(std::cbrt(Real(n))));
    std::mt19937_64 rng(42);
    std::uniform_real_distribution<Real> jitter(-0.1, 0.1), unit(-1, 1);
    Block b;
    const Real d = 2 * kRadius;
    for (int k = 0; k < side; ++k)
        for (int j = 0; j < side; ++j)
            for (int i = 0; i < side; ++i) b.x.push_back(d * Vec3(i + jitter(rng), j + jitter(rng), k + jitter(rng)));
    UniformGrid grid(supportRadiusFor(kRadius));
    grid.build(b.x);
    std::vector<Vec3> sorted;
    for (std::uint32_t i : grid.sortedIndices()) sorted.push_back(b.x[i]);
    b.x.swap(sorted);
    findFluidNeighbours(grid, b.x, supportRadiusFor(kRadius), b.pairs);
    for (std::size_t i = 0; i < b.x.size(); ++i) b.v.emplace_back(unit(rng), unit(rng), unit(rng));
    for (std::size_t p = 0; p < b.pairs.pairs(); ++p)
        b.weight.push_back(sweeps::PairWeight(-1e3 * (1 + 0.1 * unit(rng))));
    b.xRows.resize(b.x.size());
    b.vRows.resize(b.x.size());
    sweeps::toRows(0, b.x.size(), b.x.data(), b.xRows.data());
    sweeps::toRows(0, b.x.size(), b.v.data(), b.vRows.data());
    return b;
}

void setCounters(benchmark::State& state, const Block& b, double bytesPerIteration) {
    const double particles = double(b.x.size());
    state.counters["particles"] = particles;
    state.counters["threads"] = double(state.range(1));
    state.counters["pairs_per_particle"] = double(b.pairs.pairs()) / particles;
    state.counters["ns_per_particle"] =
        benchmark::Counter(particles, benchmark::Counter::kIsIterationInvariantRate | benchmark::Counter::kInvert);
    state.counters["bytes_per_particle"] = bytesPerIteration / particles;
    state.SetBytesProcessed(std::int64_t(state.iterations() * bytesPerIteration));
}

// Bytes a product moves at least once: the lists (offsets, indices), the pair weights, the input and output vectors
// and the positions; neighbours' values are assumed to come from cache (the particles are in the grid's cell order).
double productBytes(const Block& b, double perParticleIn, double perParticleOut) {
    return double(b.x.size()) * (8 + 24 + perParticleIn + perParticleOut) +
           double(b.pairs.pairs()) * double(4 + sizeof(sweeps::PairWeight));
}

void viscous(benchmark::State& state) {
    tbb::global_control threads(tbb::global_control::max_allowed_parallelism, std::size_t(state.range(1)));
    const Block b = block(std::size_t(state.range(0)));
    std::vector<Vec3> out(b.x.size());
    sweeps::Rows in(b.x.size());
    for (auto _ : state) {
        // as the solver makes it: the input into rows, then the product
        forEachBlock(b.x.size(), [&](std::size_t begin, std::size_t end) {
            sweeps::toRows(begin, end, b.v.data(), in.data());
        });
        forEachBlock(b.x.size(), [&](std::size_t begin, std::size_t end) {
            sweeps::viscousProduct(begin, end, {&b.pairs, b.weight.data()}, {}, b.xRows.data(), in.data(), 1e-3,
                                   out.data());
        });
        benchmark::DoNotOptimize(out.data());
    }
    setCounters(state, b, productBytes(b, 24, 24));
}

// The product alone, its input rows written once before the loop: set against `viscous`, what it costs a sweep that
// another thread wrote the rows it reads since its last pass (on two threads every solver iteration does).
void viscousKeptRows(benchmark::State& state) {
    tbb::global_control threads(tbb::global_control::max_allowed_parallelism, std::size_t(state.range(1)));
    const Block b = block(std::size_t(state.range(0)));
    std::vector<Vec3> out(b.x.size());
    for (auto _ : state) {
        forEachBlock(b.x.size(), [&](std::size_t begin, std::size_t end) {
            sweeps::viscousProduct(begin, end, {&b.pairs, b.weight.data()}, {}, b.xRows.data(), b.vRows.data(),
                                   1e-3, out.data());
        });
        benchmark::DoNotOptimize(out.data());
    }
    setCounters(state, b, productBytes(b, 24, 24));
}

void pressure(benchmark::State& state) {
    tbb::global_control threads(tbb::global_control::max_allowed_parallelism, std::size_t(state.range(1)));
    const Block b = block(std::size_t(state.range(0)));
    std::vector<Real> s(b.x.size(), 1), rate(b.x.size());
    std::vector<Vec3> dv(b.x.size());
    sweeps::Rows u(b.x.size());
    for (auto _ : state) {
        // as the solver makes them: the velocity change, its rows, the rate
        forEachBlock(b.x.size(), [&](std::size_t begin, std::size_t end) {
            sweeps::pressureChange(begin, end, {&b.pairs, b.weight.data()}, {}, b.xRows.data(), s.data(), 1e-3,
                                   dv.data());
        });
        forEachBlock(b.x.size(), [&](std::size_t begin, std::size_t end) {
            sweeps::toRows(begin, end, dv.data(), u.data());
        });
        forEachBlock(b.x.size(), [&](std::size_t begin, std::size_t end) {
            sweeps::densityRate(begin, end, {&b.pairs, b.weight.data()}, nullptr, nullptr, b.xRows.data(), u.data(),
                                rate.data());
        });
        benchmark::DoNotOptimize(rate.data());
    }
    setCounters(state, b, productBytes(b, 8, 24) + productBytes(b, 24, 8));
}

// The viscous pairs' weights and the fluid's diagonal blocks, which every step computes once before its viscosity
// solve, with the same made-up gradients, masses and densities for every pair (the cost does not depend on them).
void viscousWeights(benchmark::State& state) {
    tbb::global_control threads(tbb::global_control::max_allowed_parallelism, std::size_t(state.range(1)));
    const Block b = block(std::size_t(state.range(0)));
    const std::vector<Real> gradient(b.pairs.pairs(), -1e3), mass(b.x.size(), 8e-3), inverseDensity(b.x.size(), 1e-3);
    sweeps::ViscousWeightTerms terms;
    terms.gradient = gradient.data();
    terms.mass = mass.data();
    terms.inverseDensity = inverseDensity.data();
    terms.muConstant = 10;
    terms.c = 5;
    terms.eps = 0.01 * 16 * kRadius * kRadius;
    terms.inverseSpacing2 = 1 / (4 * kRadius * kRadius);
    terms.linear = 0.1;
    terms.quadratic = 0.01;
    sweeps::PairWeights weights(b.pairs.pairs());
    std::vector<Mat3> blocks(b.x.size());
    for (auto _ : state) {
        forEachBlock(b.x.size(), [&](std::size_t begin, std::size_t end) {
            sweeps::viscousWeights(begin, end, b.pairs, b.xRows.data(), terms, weights.data(), blocks.data());
        });
        benchmark::DoNotOptimize(weights.data());
    }
    // the lists, each pair's gradient in and weight out; each particle's row, mass, density and block
    setCounters(state, b, double(b.x.size()) * (8 + 32 + 16 + 72) +
                              double(b.pairs.pairs()) * double(4 + 8 + sizeof(sweeps::PairWeight)));
}

// a = b + s c over arrays far larger than the caches: what the memory system streams.
void triad(benchmark::State& state) {
    tbb::global_control threads(tbb::global_control::max_allowed_parallelism, std::size_t(state.range(0)));
    const std::size_t n = std::size_t(32) << 20;  // 32 Mi doubles: 256 MiB per array
    std::vector<double> a(n), b(n, 1), c(n, 2);
    for (auto _ : state) {
        forEachBlock(n, [&](std::size_t begin, std::size_t end) {
            for (std::size_t i = begin; i < end; ++i) a[i] = b[i] + 3 * c[i];
        }, 1 << 16);
        benchmark::DoNotOptimize(a.data());
    }
    state.SetBytesProcessed(std::int64_t(state.iterations() * 3 * 8 * n));
    state.counters["threads"] = double(state.range(0));
}

}  // namespace

BENCHMARK(viscous)->ArgsProduct({{8000, 50653, 195112, 1000000}, {1, 2}})->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(viscousKeptRows)->ArgsProduct({{8000, 50653}, {1, 2}})->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(pressure)->ArgsProduct({{8000, 50653, 195112, 1000000}, {1, 2}})->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(viscousWeights)->ArgsProduct({{8000, 50653, 1000000}, {1, 2}})->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(triad)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond)->UseRealTime();

BENCHMARK_MAIN();

// Time to sample the Stanford bunny (assets/cgal/bunny00.off, fitted to 0.2 m) into about 56k, 200k and 1.1M
// fluid particles, with each inside/outside method, on 1 and 2 threads. Includes the lattice, the inside test,
// the initial density check; the mesh is read and repaired once, outside the timing.
// Run: build/benchmarks/sample_bench --benchmark_counters_tabular=true

#include "sampler/sampler.h"
#include "scene/scene.h"

#include <benchmark/benchmark.h>
#include <fmt/format.h>
#include <tbb/global_control.h>

#include <cmath>
#include <filesystem>
#include <fstream>

using namespace ganache;

namespace {

// range(0): target particles in thousands; range(1): 0 level set, 1 winding numbers; range(2): threads.
void sampleBunny(benchmark::State& state) {
    const std::filesystem::path bunny = std::filesystem::path(GANACHE_SOURCE_DIR) / "assets/cgal/bunny00.off";
    if (!std::filesystem::exists(bunny)) {
        state.SkipWithError("assets/cgal/bunny00.off is missing: run scripts/assets.sh");
        return;
    }
    const Real volume = 0.0016024;  // of the bunny fitted to 0.2 m [m^3]
    const Real r = std::cbrt(volume / (1000.0 * Real(state.range(0)))) / 2;
    const std::filesystem::path file = std::filesystem::temp_directory_path() / "ganache_sample_bench.yaml";
    std::ofstream(file) << fmt::format(
        "ganache: 1\nparticles: {{radius: {}, max_count: 100000000}}\ndomain: {{min: [-1, -1, -1], max: [1, 1, 1]}}\n"
        "fluids: [{{mesh: {{file: {}, fit: {{size: 0.2, centre: [0, 0, 0]}}, inside: {}}}}}]\n",
        r, bunny.string(), state.range(1) ? "winding_number" : "level_set");
    const Scene scene = loadScene(file, Quality::parse("final"));
    tbb::global_control threads(tbb::global_control::max_allowed_parallelism, std::size_t(state.range(2)));
    std::size_t n = 0;
    for (auto _ : state) n = sampleScene(scene).fluid.size();
    state.counters["particles"] = double(n);
    state.counters["ns_per_particle"] =
        benchmark::Counter(double(n) * double(state.iterations()), benchmark::Counter::kIsIterationInvariantRate |
                                                                       benchmark::Counter::kInvert);
}

}  // namespace

BENCHMARK(sampleBunny)
    ->ArgsProduct({{56, 200, 1100}, {0, 1}, {1, 2}})
    ->ArgNames({"kparticles", "winding", "threads"})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->Iterations(1);

BENCHMARK_MAIN();

// A Table-2-style breakdown of one simulation step (Weiler et al. 2018, Table 2): a viscous blob
// (mu = 1e4 Pa s) hitting a floor at 1 m/s, fixed dt = 0.5 ms, about 56k and 200k particles, 1 and 2 threads.
// Reported per step: neighbours (search, densities, DFSPH factors), pressure (both DFSPH solves), viscosity,
// CG iterations per solve, total; and resident memory per particle. A heat variant gives the heat effect's share,
// a block-Jacobi variant the saving of the rigid coarse space.
// Run: build/benchmarks/step_bench --benchmark_counters_tabular=true

#include "sampler/sampler.h"
#include "scene/scene.h"
#include "physics/simulation.h"

#include <benchmark/benchmark.h>
#include <fmt/format.h>
#include <tbb/global_control.h>

#include <filesystem>
#include <fstream>
#include <unistd.h>

using namespace ganache;

namespace {

std::size_t residentBytes() {
    std::ifstream statm("/proc/self/statm");
    std::size_t pages = 0, resident = 0;
    statm >> pages >> resident;
    return resident * std::size_t(::sysconf(_SC_PAGESIZE));
}

// A cube of `side` particles per axis (r = 5 mm) just above a floor, moving down at 1 m/s; with `heat`, also
// conduction, radiation and a lamp above it (the heat effect's share of a step).
Scene blobScene(int side, bool heat, const char* preconditioner) {
    const Real r = 0.005, edge = side * 2 * r;
    const auto dir = std::filesystem::temp_directory_path() / "ganache_bench";
    std::filesystem::create_directories(dir);
    const auto file = dir / fmt::format("blob{}{}_{}.yaml", side, heat ? "_heat" : "", preconditioner);
    std::ofstream(file) << fmt::format(R"(ganache: 1
particles: {{radius: {r}, max_count: 100000000}}
domain: {{min: [-1, -0.1, -1], max: [1, 1, 1]}}
simulation: {{time_step: {{fixed: 0.0005}}}}
fluids: [{{material: honey, velocity: [0, -1, 0], box: {{min: [{lo}, 0.011, {lo}], max: [{hi}, {top}, {hi}]}}}}]
boundaries: [{{name: floor, plane: {{point: [0, 0, 0], normal: [0, 1, 0]}}}}]
effects: {{gravity: {{}}, viscosity: {{mu: 1.0e4, preconditioner: {preconditioner}}}{heat}}}
)",
                                       fmt::arg("heat", heat ? ", heat: {radiation_time: 10, sources: [{sphere: {centre: "
                                                               "[0, 0.5, 0]}, intensity: 1.0e4, radius: 0.1}]}"
                                                             : ""),
                                       fmt::arg("preconditioner", preconditioner), fmt::arg("r", r), fmt::arg("lo", -edge / 2), fmt::arg("hi", edge / 2),
                                       fmt::arg("top", 0.011 + edge));
    return loadScene(file, Quality::parse("final"));
}

void step(benchmark::State& state) {
    tbb::global_control threads(tbb::global_control::max_allowed_parallelism, std::size_t(state.range(1)));
    const Scene scene = blobScene(int(state.range(0)), state.range(2) != 0, state.range(3) ? "block_jacobi" : "rigid");
    const std::size_t before = residentBytes();
    Sample sample = sampleScene(scene);
    Simulation sim(scene, std::move(sample.fluid), sample.boundaries);
    for (int i = 0; i < 10; ++i) sim.step();  // past the first, unrepresentative steps: the blob touches down
    const SolverStats start = sim.stats();
    for (auto _ : state) sim.step();
    const SolverStats& end = sim.stats();
    const double steps = double(end.steps - start.steps);
    auto ms = [&](double a, double b) { return 1000 * (a - b) / steps; };
    state.counters["particles"] = double(sim.particles().size());
    state.counters["threads"] = double(state.range(1));
    state.counters["neighbours_ms"] = ms(end.time.neighbours, start.time.neighbours);
    state.counters["pressure_ms"] = ms(end.time.pressure + end.time.divergence, start.time.pressure + start.time.divergence);
    state.counters["viscosity_ms"] = ms(end.time.viscosity, start.time.viscosity);
    state.counters["heat_ms"] = ms(end.time.heat, start.time.heat);
    state.counters["total_ms"] = ms(end.time.total(), start.time.total());
    state.counters["heat_share"] = (end.time.heat - start.time.heat) / (end.time.total() - start.time.total());
    state.counters["cg_iterations"] =
        double(end.viscosityIterations - start.viscosityIterations) / double(end.viscositySolves - start.viscositySolves);
    state.counters["pressure_iterations"] =
        double(end.pressureIterations + end.divergenceIterations - start.pressureIterations - start.divergenceIterations) /
        steps;
    state.counters["bytes_per_particle"] = double(residentBytes() - before) / double(sim.particles().size());
}

}  // namespace

// 38^3 = 54,872 particles (the paper's 56k bunny), 58^3 = 195,112 (its 200k). Arguments: side, threads, heat (1:
// on), preconditioner (0: rigid, the default; 1: the paper's block Jacobi).
BENCHMARK(step)->ArgsProduct({{38, 58}, {1, 2}, {0}, {0}})->Unit(benchmark::kMillisecond)->UseRealTime()->Iterations(10);
BENCHMARK(step)->ArgsProduct({{38}, {1, 2}, {1}, {0}})->Unit(benchmark::kMillisecond)->UseRealTime()->Iterations(10);
BENCHMARK(step)->ArgsProduct({{38}, {2}, {0}, {1}})->Unit(benchmark::kMillisecond)->UseRealTime()->Iterations(10);

BENCHMARK_MAIN();

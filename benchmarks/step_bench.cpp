// A Table-2-style breakdown of one simulation step (Weiler et al. 2018, Table 2): a viscous blob
// (mu = 1e4 Pa s) hitting a floor at 1 m/s, fixed dt = 0.5 ms, about 56k and 200k particles on 1 and 2 threads and
// 1M on 2.
// Reported per step: neighbours (search, densities, DFSPH factors), pressure (both DFSPH solves), viscosity,
// CG iterations per solve, constant-density and divergence-free iterations per step, total; and resident memory per
// particle. A heat variant gives the heat effect's share, a block-Jacobi variant the saving of the coarse space (at
// this viscosity no particle is stiff enough for the clusters, so the default uses the fluid-wide rigid motions), and
// `stiffStep` the same blob at 1e6 Pa s, whose solves take the clusters' rigid motions and the stiff tolerance.
// Run: build/benchmarks/step_bench --benchmark_counters_tabular=true

#include "physics/simulation.h"
#include "sampler/sampler.h"
#include "scene/scene.h"

#include <benchmark/benchmark.h>
#include <fmt/format.h>

#include <map>
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
Scene blobScene(int side, bool heat, const char* preconditioner, Real mu) {
    const Real r = 0.005, edge = side * 2 * r;
    const auto dir = std::filesystem::temp_directory_path() / "ganache_bench";
    std::filesystem::create_directories(dir);
    const auto file = dir / fmt::format("blob{}{}_{}_{}.yaml", side, heat ? "_heat" : "", preconditioner, mu);
    std::ofstream(file) << fmt::format(R"(ganache: 1
particles: {{radius: {r}, max_count: 100000000}}
domain: {{min: [-1, -0.1, -1], max: [1, 2, 1]}}
simulation: {{time_step: {{fixed: 0.0005}}}}
fluids: [{{material: honey, velocity: [0, -1, 0], box: {{min: [{lo}, 0.011, {lo}], max: [{hi}, {top}, {hi}]}}}}]
boundaries: [{{name: floor, plane: {{point: [0, 0, 0], normal: [0, 1, 0]}}}}]
effects: {{gravity: {{}}, viscosity: {{mu: {mu}, preconditioner: {preconditioner}}}{heat}}}
)",
                                       fmt::arg("heat", heat ? ", heat: {radiation_time: 10, sources: [{sphere: {centre: "
                                                               "[0, 0.5, 0]}, intensity: 1.0e4, radius: 0.1}]}"
                                                             : ""),
                                       fmt::arg("preconditioner", preconditioner), fmt::arg("mu", mu), fmt::arg("r", r),
                                       fmt::arg("lo", -edge / 2), fmt::arg("hi", edge / 2), fmt::arg("top", 0.011 + edge));
    return loadScene(file, Quality::parse("final"));
}

// Ten steps of the blob (after ten to its landing), reported by part.
void measureSteps(benchmark::State& state, const Scene& scene) {
    const std::size_t resident = residentBytes();
    Sample sample = sampleScene(scene);
    Simulation sim(simulationSetup(scene), std::move(sample.fluid), sample.boundaries);
    for (int i = 0; i < 10; ++i) sim.step();  // past the first, unrepresentative steps: the blob touches down
    // Seconds by part (the step's own, then each effect's), and the viscosity totals, so far.
    auto parts = [&] {
        std::map<std::string, double> t{{"neighbours", sim.stats().time.neighbours},
                                        {"pressure", sim.stats().time.pressure + sim.stats().time.divergence},
                                        {"total", sim.stats().time.total()}};
        for (const EffectSummary& e : sim.effectSummaries()) t[e.name] += e.seconds, t["total"] += e.seconds;
        const double solves = sim.counter("viscosity", "solves");
        t["cg_solves"] = solves;
        t["cg_iterations"] = solves * sim.counter("viscosity", "iterations_per_solve");
        t["pressure_iterations"] = double(sim.stats().pressureIterations);
        t["divergence_iterations"] = double(sim.stats().divergenceIterations);
        return t;
    };
    const SolverStats start = sim.stats();
    auto before = parts();
    for (auto _ : state) sim.step();
    auto after = parts();
    const double steps = double(sim.stats().steps - start.steps);
    auto ms = [&](const std::string& part) { return 1000 * (after[part] - before[part]) / steps; };
    state.counters["particles"] = double(sim.particles().size());
    state.counters["threads"] = double(state.range(1));
    state.counters["neighbours_ms"] = ms("neighbours");
    state.counters["pressure_ms"] = ms("pressure");
    state.counters["viscosity_ms"] = ms("viscosity");
    state.counters["heat_ms"] = ms("heat");
    state.counters["total_ms"] = ms("total");
    state.counters["heat_share"] = ms("heat") / ms("total");
    state.counters["cg_iterations"] =
        (after["cg_iterations"] - before["cg_iterations"]) / (after["cg_solves"] - before["cg_solves"]);
    state.counters["pressure_iterations"] = (after["pressure_iterations"] - before["pressure_iterations"]) / steps;
    state.counters["divergence_iterations"] =
        (after["divergence_iterations"] - before["divergence_iterations"]) / steps;
    state.counters["bytes_per_particle"] = double(residentBytes() - resident) / double(sim.particles().size());
}

void step(benchmark::State& state) {
    tbb::global_control threads(tbb::global_control::max_allowed_parallelism, std::size_t(state.range(1)));
    measureSteps(state, blobScene(int(state.range(0)), state.range(2) != 0,
                                  state.range(3) ? "block_jacobi" : "clusters", 1e4));
}

// The same blob of a chocolate as stiff as 1e6 Pa s, where the viscosity's preconditioner takes clusters' rigid
// motions (dt A against the identity above the threshold at every particle) and its solves the stiff tolerance.
void stiffStep(benchmark::State& state) {
    tbb::global_control threads(tbb::global_control::max_allowed_parallelism, std::size_t(state.range(1)));
    measureSteps(state, blobScene(int(state.range(0)), false, "clusters", 1e6));
}

}  // namespace

// 38^3 = 54,872 particles (the paper's 56k bunny), 58^3 = 195,112 (its 200k), 100^3 = 1,000,000 (its statue's 1.1M).
// Arguments: side, threads, heat (1: on), preconditioner (0: clusters, the default; 1: the paper's block Jacobi).
// Every size measures the same ten steps: the blob touches the floor in the tenth, and the pressure's work there
// changes from step to step (at 1M 6, 25, 37, 15, 6, 7, 14, 104, 87 and 44 constant-density products before the
// projected expansions), so a shorter window at 1M measured a different part of the landing.
BENCHMARK(step)->ArgsProduct({{38, 58}, {1, 2}, {0}, {0}})->Unit(benchmark::kMillisecond)->UseRealTime()->Iterations(10);
BENCHMARK(step)->Args({100, 2, 0, 0})->Unit(benchmark::kMillisecond)->UseRealTime()->Iterations(10);
BENCHMARK(step)->ArgsProduct({{38}, {1, 2}, {1}, {0}})->Unit(benchmark::kMillisecond)->UseRealTime()->Iterations(10);
BENCHMARK(step)->ArgsProduct({{38}, {2}, {0}, {1}})->Unit(benchmark::kMillisecond)->UseRealTime()->Iterations(10);
// Arguments: side, threads.
BENCHMARK(stiffStep)->ArgsProduct({{38, 58}, {2}})->Unit(benchmark::kMillisecond)->UseRealTime()->Iterations(10);

BENCHMARK_MAIN();

// Frames per second of the preview renderer (issue 7's benchmark): a 1M-triangle mesh (a bumpy ball, so that
// the shadow and the shading see real relief) on a ground plane at 1280x720, and 200k particles as sprites.
// llvmpipe draws with as many threads as LP_NUM_THREADS says (default: every core); run e.g.
//   LP_NUM_THREADS=2 build/benchmarks/render_bench --benchmark_counters_tabular=true

#include "render/render.h"

#include <benchmark/benchmark.h>

#include <cmath>

using namespace ganache;

namespace {

// A ball of radius 0.1 m with ripples, 2 segments^2 / 2 triangles.
DrawMesh bumpyBall(int segments) {
    DrawMesh m = sphereMesh(Vec3(0, 0.1, 0), 0.1, segments, Vec3(0.32, 0.17, 0.09));
    m.gloss = 0.6;
    for (std::size_t k = 0; k < m.points.size(); ++k) {
        const Vec3& n = m.normals[k];
        m.points[k] += 0.004 * std::sin(9 * std::acos(n.y())) * std::cos(7 * std::atan2(n.z(), n.x())) * n;
    }
    return m;
}

void renderMesh(benchmark::State& state) {
    Renderer renderer(1280, 720);
    FrameView view;
    view.meshes.push_back(bumpyBall(1000));  // 1,000,000 triangles
    view.groundHeight = 0.0;
    view.camera = frameBounds(Vec3(-0.1, 0, -0.1), Vec3(0.1, 0.2, 0.1), 1280.0 / 720);
    for (auto _ : state) benchmark::DoNotOptimize(renderer.render(view));
    state.counters["triangles"] = double(view.meshes[0].triangles.size());
    state.counters["fps"] = benchmark::Counter(double(state.iterations()), benchmark::Counter::kIsRate);
}

void renderParticles(benchmark::State& state) {
    Renderer renderer(1280, 720);
    FrameView view;
    DrawPoints points;
    points.radius = 0.0025;
    for (int i = 0; i < 200'000; ++i) {  // a 100 x 20 x 100 block
        points.x.emplace_back(0.005 * (i % 100), 0.0025 + 0.005 * ((i / 100) % 20), 0.005 * (i / 2000));
        points.colour.push_back(colourRamp(Real(i % 100) / 99));
    }
    view.points = points;
    view.legend = Legend{"speed [m/s]", 0, 1};
    view.groundHeight = 0.0;
    view.camera = frameBounds(Vec3(0, 0, 0), Vec3(0.5, 0.1, 0.5), 1280.0 / 720);
    for (auto _ : state) benchmark::DoNotOptimize(renderer.render(view));
    state.counters["particles"] = double(points.x.size());
    state.counters["fps"] = benchmark::Counter(double(state.iterations()), benchmark::Counter::kIsRate);
}

}  // namespace

BENCHMARK(renderMesh)->Unit(benchmark::kMillisecond)->UseRealTime()->MinTime(5);
BENCHMARK(renderParticles)->Unit(benchmark::kMillisecond)->UseRealTime()->MinTime(5);

BENCHMARK_MAIN();

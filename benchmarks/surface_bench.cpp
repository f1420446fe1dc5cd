// What surfacing one frame costs, per method, at 200k and 1M particles (issue 6's benchmark).
// The frame: a viscous puddle, half an oblate ellipsoid three times as wide as it is high, filled with a lattice
// of spacing 2r (r = 5 mm) jittered by up to 0.2 r per axis; default surface settings (voxel 0.5 r, two smoothing
// passes, each method's default adaptivity). Reported per frame: core-microseconds per particle (wall time x threads
// / particles) of a frame after the process's first and of the first, the share of each part (level set, smoothing,
// mesh), triangles, the level set's active voxels, and the peak resident memory the first frame added on top of its
// particles.
// Run one benchmark per process for honest memory peaks, e.g.
//   build/benchmarks/surface_bench --benchmark_counters_tabular=true --benchmark_filter='surface/2/200000/2'
// meshFile: writing and reading a frame's mesh as OBJ or binary PLY (--benchmark_filter=meshFile).

#include "core/memory.h"
#include "surfacer/surfacer.h"

#include <benchmark/benchmark.h>
#include <tbb/global_control.h>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <random>
#include <string>

using namespace ganache;

namespace {

constexpr Real kRadius = 0.005;

// /proc/self/status field in kB, as bytes.
double statusBytes(const std::string& field) {
    std::ifstream status("/proc/self/status");
    std::string line;
    while (std::getline(status, line))
        if (line.rfind(field + ":", 0) == 0) return 1024.0 * std::stod(line.substr(field.size() + 1));
    return 0;
}

// Resets the kernel's peak-resident counter (VmHWM) to the current resident size.
void resetPeakMemory() { std::ofstream("/proc/self/clear_refs") << "5"; }

ParticleSet puddle(std::size_t count) {
    // Half ellipsoid with semi-axes (a, c, a), a = 3c: volume (2/3) pi a^2 c = 6 pi c^3 holds count lattice cells.
    const Real spacing = 2 * kRadius;
    const Real c = std::cbrt(Real(count) * spacing * spacing * spacing / (6 * M_PI)), a = 3 * c;
    std::mt19937_64 random(7);
    std::uniform_real_distribution<Real> jitter(-0.2 * kRadius, 0.2 * kRadius);
    ParticleSet out;
    out.reserve(count + count / 8);
    const int n = int(std::ceil(a / spacing));
    std::uint64_t id = 0;
    for (int i = -n; i <= n; ++i)
        for (int j = 0; spacing * (j + 0.5) < c; ++j)
            for (int k = -n; k <= n; ++k) {
                const Vec3 p((i + 0.5) * spacing, (j + 0.5) * spacing, (k + 0.5) * spacing);
                if (std::pow(p.x() / a, 2) + std::pow(p.y() / c, 2) + std::pow(p.z() / a, 2) > 1) continue;
                out.add(p + Vec3(jitter(random), jitter(random), jitter(random)), Vec3::Zero(), 1e-3, id++);
            }
    return out;
}

void surface(benchmark::State& state) {
    const auto method = SurfaceMethod(state.range(0));
    const std::size_t threads = std::size_t(state.range(2));
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism, threads);
    const ParticleSet fluid = puddle(std::size_t(state.range(1)));
    SurfaceSettings settings;
    settings.requested = true;
    settings.method = method;
    SurfaceTimings sum;
    std::size_t triangles = 0, voxels = 0;
    // A process's first frame pays for its memory's pages; the frames after it reuse them (keepFreedMemory), as a
    // pipeline's frames do. The first frame gives the peak, the timed ones the cost a frame.
    resetPeakMemory();
    const double before = statusBytes("VmRSS");
    const double first = surfaceParticles(fluid, kRadius, settings).timings().total();
    const double peak = statusBytes("VmHWM") - before;
    for (auto _ : state) {
        const FrameSurface frame = surfaceParticles(fluid, kRadius, settings);
        sum.levelSet += frame.timings().levelSet;
        sum.smoothing += frame.timings().smoothing;
        sum.mesh += frame.timings().mesh;
        triangles = frame.mesh().triangles.size();
        voxels = frame.activeVoxels();
    }
    const double frames = double(state.iterations()), particles = double(fluid.size());
    const double perFrame = sum.total() / frames;
    const auto coreMicroseconds = [&](double seconds) { return 1e6 * seconds * double(threads) / particles; };
    state.counters["particles"] = particles;
    state.counters["threads"] = double(threads);
    state.counters["core_us_per_particle"] = coreMicroseconds(perFrame);
    state.counters["first_frame_core_us"] = coreMicroseconds(first);
    state.counters["level_set_share"] = sum.levelSet / sum.total();
    state.counters["smoothing_share"] = sum.smoothing / sum.total();
    state.counters["mesh_share"] = sum.mesh / sum.total();
    state.counters["triangles"] = double(triangles);
    state.counters["band_voxels"] = double(voxels);
    state.counters["peak_MB"] = peak / 1e6;
    state.counters["estimate_MB"] = estimateSurfaceBytes(fluid.size(), kRadius, settings) / 1e6;
}

// Writing and reading one frame's mesh as OBJ text or binary PLY: the 200k puddle's smooth-spheres surface.
void meshFile(benchmark::State& state) {
    const bool ply = state.range(0) == 1;
    SurfaceSettings settings;
    settings.requested = true;
    settings.method = SurfaceMethod::SmoothSpheres;
    static const FrameSurface frame = surfaceParticles(puddle(200'000), kRadius, settings);
    const std::filesystem::path file =
        std::filesystem::temp_directory_path() / (ply ? "ganache_bench_mesh.ply" : "ganache_bench_mesh.obj");
    double write = 0, read = 0;
    for (auto _ : state) {
        auto t0 = std::chrono::steady_clock::now();
        writeSurfaceMesh(file, frame.mesh(), "benchmark");
        auto t1 = std::chrono::steady_clock::now();
        benchmark::DoNotOptimize(readSurfaceMesh(file));
        auto t2 = std::chrono::steady_clock::now();
        write += std::chrono::duration<double>(t1 - t0).count();
        read += std::chrono::duration<double>(t2 - t1).count();
    }
    const double frames = double(state.iterations());
    state.counters["triangles"] = double(frame.mesh().triangles.size());
    state.counters["file_MB"] = double(std::filesystem::file_size(file)) / 1e6;
    state.counters["write_ms"] = 1e3 * write / frames;
    state.counters["read_ms"] = 1e3 * read / frames;
    std::filesystem::remove(file);
}

}  // namespace

// Arguments: format (0 OBJ, 1 binary PLY).
BENCHMARK(meshFile)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond)->UseRealTime()->Iterations(5);

// Arguments: method (0 spheres, 1 smooth_spheres, 2 anisotropic; SurfaceMethod's order), particles, threads.
BENCHMARK(surface)
    ->ArgsProduct({{0, 1, 2}, {200'000, 1'000'000}, {2}})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->Iterations(1);

int main(int argc, char** argv) {
    ganache::keepFreedMemory();  // as ganache does
    benchmark::Initialize(&argc, argv);
    if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
    benchmark::RunSpecifiedBenchmarks();
    benchmark::Shutdown();
}

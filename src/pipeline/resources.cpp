// The resource guard: the memory and disk a command will need, estimated from the scene before anything starts,
// printed, and compared with what the machine has. A run that cannot fit is refused up front, naming the setting
// to change, instead of dying hours in (out of memory) or filling the disk at frame 900.

#include "pipeline/stages.h"

#include "core/errors.h"
#include "surfacer/surfacer.h"

#include <fmt/format.h>

#include <cmath>
#include <fstream>
#include <limits>

#include <sys/statvfs.h>

namespace ganache {

namespace fs = std::filesystem;

namespace {

constexpr double kGiB = 1 << 30;

// What the program needs before any particle: its libraries, OpenVDB, TBB (`ganache scene` peaks at 88 MiB).
constexpr double kProgramBytes = 100 * double(1 << 20);
// Simulation memory per particle: a fluid particle's attributes, neighbour lists and solver vectors, and a
// boundary particle's arrays, grid and share of the cache it is read from. Measured: 155 MiB peak for 25,428 fluid
// and 94,580 boundary particles (tests/scenes/resume.yaml at --quality 0.2), which these put at 171 MiB.
constexpr double kFluidBytes = 1024, kBoundaryBytes = 512;
// The render stage: per llvmpipe context (one per thread) its multisampled buffers and shadow maps, and a frame's
// surface mesh as read and drawn. Measured on the default scene (two threads, 1280x720): 330 MiB at preview (63k
// triangles a frame), 711 MiB at final (400k), which these put at 429 and 874 MiB with the program's 100.
constexpr double kRenderContextBytes = 125 * double(1 << 20), kRenderTriangleBytes = 600;
constexpr int kRenderContexts = 2;  // what the guard plans for
// File sizes per particle: a particle cache holds 32-bit positions and velocities, 64-bit mass and id and 32-bit
// effect attributes (about 60 bytes a fluid particle, 35 a boundary particle with the OpenVDB overhead, measured on
// tests/scenes/resume.yaml; the default scene's 96 frames: 16 MiB estimated, 12 MiB written); a checkpoint holds
// every attribute in 64 bits (about 150 bytes).
constexpr double kFluidCacheBytes = 60, kBoundaryCacheBytes = 35, kCheckpointBytes = 150;
// The PLY export: 32 bytes a particle, and 4 per effect attribute (at most a few).
constexpr double kFluidPlyBytes = 48;

// Boundary particles the sampler puts on the scene's boundaries: one layer, r apart, over their surfaces within
// the domain (tests/scenes/resume.yaml: 3,750 estimated, 3,920 sampled).
double estimateBoundaryParticles(const Scene& scene) {
    const Vec3 extent = scene.domainMax - scene.domainMin;
    double area = 0;
    for (const auto& b : scene.boundaries) {
        if (const auto* box = std::get_if<BoxBoundary>(&b.shape)) {
            const Vec3 e = (box->max.cwiseMin(scene.domainMax) - box->min.cwiseMax(scene.domainMin)).cwiseMax(0);
            area += 2 * (e.x() * e.y() + e.y() * e.z() + e.z() * e.x());
        } else if (const auto* plane = std::get_if<PlaneBoundary>(&b.shape)) {
            const Vec3 n = plane->normal.cwiseAbs();  // the domain's cross-section across the plane
            area += n.x() * extent.y() * extent.z() + n.y() * extent.x() * extent.z() + n.z() * extent.x() * extent.y();
        } else {
            area += std::get<MeshShape>(b.shape).mesh->area();
        }
    }
    return area / (scene.particleRadius * scene.particleRadius);
}

// Free bytes on the file system that will hold `folder` (its nearest existing parent).
double freeDiskBytes(fs::path folder) {
    std::error_code ec;
    folder = fs::absolute(folder, ec);
    while (!folder.empty() && !fs::exists(folder, ec) && folder != folder.parent_path()) folder = folder.parent_path();
    struct statvfs disk {};
    if (::statvfs(folder.c_str(), &disk) != 0) return std::numeric_limits<double>::infinity();
    return double(disk.f_bavail) * double(disk.f_frsize);
}

// Bytes of the files already under `folder`: a rerun replaces them, so their space counts as available.
double existingBytes(const fs::path& folder) {
    double total = 0;
    std::error_code ec;
    for (auto it = fs::recursive_directory_iterator(folder, ec); !ec && it != fs::recursive_directory_iterator();
         it.increment(ec))
        if (it->is_regular_file(ec)) total += double(it->file_size(ec));
    return total;
}

std::string size(double bytes) {
    return bytes >= kGiB ? fmt::format("{:.1f} GiB", bytes / kGiB) : fmt::format("{:.1f} MiB", bytes / (1 << 20));
}

bool has(const std::vector<StageId>& stages, StageId id) {
    return std::find(stages.begin(), stages.end(), id) != stages.end();
}

}  // namespace

double availableBytes() {
    double free = std::numeric_limits<double>::infinity();
    std::ifstream meminfo("/proc/meminfo");
    std::string key, unit;
    double kib = 0;
    while (meminfo >> key >> kib >> unit)
        if (key == "MemAvailable:") free = kib * 1024;
    double limit = 0, used = 0;
    std::ifstream max("/sys/fs/cgroup/memory.max"), current("/sys/fs/cgroup/memory.current");
    if (max >> limit && current >> used) free = std::min(free, std::max(0.0, limit - used));  // "max": no limit
    return free;
}

ResourceEstimate estimateResources(const Scene& scene, std::pair<std::int64_t, std::int64_t> frames,
                                   const std::vector<StageId>& stages) {
    ResourceEstimate e;
    e.fluid = estimateFluidParticles(scene, scene.particleRadius);
    e.boundary = estimateBoundaryParticles(scene);
    e.programBytes = kProgramBytes;
    const double written = double(frames.second - frames.first + 1);
    const bool surface = has(stages, StageId::Surface) && scene.surface.requested;
    const bool render = has(stages, StageId::Render) && scene.render.requested;
    bool moving = false;
    for (const auto& b : scene.boundaries) moving |= !b.motion.isStatic();

    if (has(stages, StageId::Sample) || has(stages, StageId::Simulate))
        e.simulateBytes = kFluidBytes * e.fluid + kBoundaryBytes * e.boundary;
    if (surface) e.surfaceFrameBytes = estimateSurfaceBytes(std::size_t(e.fluid), scene.particleRadius, scene.surface);
    if (render) {
        const bool meshes = scene.surface.requested && scene.render.view != RenderView::Particles;
        e.renderContextBytes =
            kRenderContextBytes +
            (meshes ? kRenderTriangleBytes *
                          estimateSurfaceTriangles(std::size_t(e.fluid), scene.particleRadius, scene.surface)
                    : 0.0);
        e.renderBytes = kFluidBytes * e.fluid + kRenderContexts * e.renderContextBytes;
    }

    if (has(stages, StageId::Sample)) e.sampleDisk = kFluidCacheBytes * e.fluid + kBoundaryCacheBytes * e.boundary;
    if (has(stages, StageId::Simulate)) {
        e.particleDisk = written * (kFluidCacheBytes * e.fluid + (moving ? kBoundaryCacheBytes * e.boundary : 0) +
                                    (scene.exportPly ? kFluidPlyBytes * e.fluid : 0));
        if (scene.checkpointEvery > 0) e.checkpointDisk = double(scene.checkpointsKept + 1) * kCheckpointBytes * e.fluid;
    }
    if (surface) {
        const auto [vdb, obj] = estimateSurfaceFileBytes(std::size_t(e.fluid), scene.particleRadius, scene.surface);
        e.levelSetDisk = written * vdb;
        e.meshDisk = written * obj;
    }
    if (render)  // PNG previews compress to about 4 % of their pixels' bytes (default scene: 9.9 MiB for 96 frames)
        e.previewDisk = (written + 1) * 0.06 * 3 * double(scene.render.width * scene.render.height);
    return e;
}

void checkResources(const Scene& scene, const OutputLayout& layout, std::pair<std::int64_t, std::int64_t> frames,
                    const std::vector<StageId>& stages, double memoryGiB, bool skipCheck, RunReport& report) {
    const ResourceEstimate e = estimateResources(scene, frames, stages);
    const double fluid = e.fluid, boundary = e.boundary;

    // Memory the scene's data needs on top of the program, in the largest stage (they run one after the other).
    // This is what is compared with the free memory (which the running program is already not part of) or
    // --memory, as the surface stage does for each frame.
    double memory = 0;
    std::string heaviest, fix;
    Location at = scene.radiusAt;
    auto consider = [&](double bytes, const char* stage, const Location& where, const char* remedy) {
        if (bytes > memory) memory = bytes, heaviest = stage, at = where, fix = remedy;
    };
    consider(e.simulateBytes, "simulate", scene.radiusAt,
             "raise particles.radius or use a coarser --quality (memory grows as 1 / radius^3)");
    consider(e.surfaceFrameBytes, "surface", scene.surface.at,
             "raise surface.voxel_size, or particles.radius (a coarser --quality)");
    consider(e.renderBytes, "render", scene.render.at, "render on another machine (`ganache render`)");
    const double disk = e.disk();

    const double memoryBudget = memoryGiB > 0 ? memoryGiB * kGiB : 0.8 * availableBytes();
    const double diskFree = freeDiskBytes(layout.root) + existingBytes(layout.root);
    fmt::print(stderr,
               "plan: about {:.0f} fluid and {:.0f} boundary particles; memory about {} (the program's {} and {} for the "
               "scene) of {} {}; disk about {} (particles {}, checkpoints {}, level sets {}, meshes {}, previews {}) of "
               "{} free in {}\n",
               fluid, boundary, size(kProgramBytes + memory), size(kProgramBytes), size(memory), size(memoryBudget), memoryGiB > 0 ? "(--memory)" : "usable", size(disk),
               size(e.sampleDisk + e.particleDisk), size(e.checkpointDisk), size(e.levelSetDisk), size(e.meshDisk),
               size(e.previewDisk),
               size(diskFree), layout.root.string());
    report.measure("plan/fluid_particles", fluid);
    report.measure("plan/boundary_particles", boundary);
    report.measure("plan/memory_bytes", kProgramBytes + memory);
    report.measure("plan/memory_budget_bytes", memoryBudget);
    report.measure("plan/disk_bytes", disk);
    report.measure("plan/disk_free_bytes", diskFree);
    if (skipCheck) return;
    if (memory > memoryBudget)
        throw SceneError(at,
                         fmt::format("the {} stage needs about {} of memory for this scene at particle radius {} m ({} "
                                     "quality, about {:.0f} particles), more than the {} {}",
                                     heaviest, size(memory), formatNumber(scene.particleRadius), scene.quality.str(),
                                     fluid + boundary, size(memoryBudget),
                                     memoryGiB > 0 ? "--memory allows" : "it may use of what this machine has free"),
                         fix + ", run on a machine with more memory, or pass --skip-resource-check if the estimate is "
                               "wrong");
    if (disk > diskFree)
        throw InputError(fmt::format(
            "the outputs need about {} of disk, but {} has {} free\n  fix: free space there, write "
            "elsewhere with --out, run fewer frames (--frames), keep fewer checkpoints (simulation.checkpoints_kept), "
            "drop the meshes (surface.mesh: false), or pass --skip-resource-check if the estimate is wrong",
            size(disk), layout.root.string(), size(diskFree)));
}

}  // namespace ganache

#pragma once
// What the stages' source files share inside the pipeline library.

#include "app/report.h"
#include "io/checkpoint.h"
#include "pipeline/frame_stage.h"
#include "pipeline/pipeline.h"

#include <filesystem>
#include <optional>
#include <utility>
#include <vector>

namespace ganache {

/// Memory this process can still get [bytes]: the machine's MemAvailable, or less when a cgroup (v2: a farm's
/// container or job slot) caps it; infinity when neither can be read.
double availableBytes();

/// The resource guard (resources.cpp): prints the memory and disk the stages will need, estimated from the scene,
/// and refuses (SceneError at particles.radius for memory, InputError for disk, each naming what to change) when
/// they exceed what the machine has, unless skipCheck. memoryGiB > 0 replaces the free memory (--memory).
void checkResources(const Scene& scene, const OutputLayout& layout, std::pair<std::int64_t, std::int64_t> frames,
                    const std::vector<StageId>& stages, double memoryGiB, bool skipCheck, RunReport& report);

/// The checkpoint `--resume` continues from: the newest in <out>/checkpoints that reads back whole (each one
/// that does not is reported and skipped); none when there is none. InputError when it belongs to another
/// version of the scene or another quality.
std::optional<Checkpoint> findResumePoint(const Scene& scene, const OutputLayout& layout, RunReport& report);

/// The sample stage (sample_stage.cpp).
void runSample(const Scene& scene, const OutputLayout& layout, RunReport& report);

/// The simulate stage (simulate_stage.cpp), from the sample or from a checkpoint. Throws Interrupted after
/// saving a checkpoint when SIGINT or SIGTERM arrives (the caller holds the InterruptGuard).
void runSimulate(const Scene& scene, const OutputLayout& layout, std::pair<std::int64_t, std::int64_t> frames,
                 const std::optional<Checkpoint>& from, RunReport& report);

/// The surface stage (surface_stage.cpp): frames in parallel within `memoryGiB` (0: 80 % of what is free).
void runSurface(const Scene& scene, const OutputLayout& layout, std::pair<std::int64_t, std::int64_t> frames,
                bool force, int threads, double memoryGiB, RunReport& report);

/// The render stage (render_stage.cpp); framesOnly leaves the contact sheet and the video alone.
void runRender(const Scene& scene, const OutputLayout& layout, std::pair<std::int64_t, std::int64_t> frames,
               bool force, bool framesOnly, RunReport& report);

}  // namespace ganache

#pragma once
// What the stages' source files share inside the pipeline library.

#include "pipeline.h"
#include "report.h"

#include <filesystem>
#include <utility>

namespace ganache {

/// An output is up to date when it exists and is newer than its input.
bool upToDate(const std::filesystem::path& output, const std::filesystem::path& input);

/// Throws InputError naming the first frame of the range without a particle cache, before a stage does any work.
void requireParticleCaches(const char* stage, const Scene& scene, const OutputLayout& layout,
                           std::pair<std::int64_t, std::int64_t> frames);

/// The render stage (render_stage.cpp).
void runRender(const Scene& scene, const OutputLayout& layout, std::pair<std::int64_t, std::int64_t> frames,
               bool force, RunReport& report);

}  // namespace ganache

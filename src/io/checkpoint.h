#pragma once
// Checkpoints: a simulation's whole state (SimulationState) in one file, so that a run that was killed or stopped
// continues where it was and takes exactly the steps it would have taken. Binary, in this machine's byte order,
// sealed with a checksum footer and written atomically; a file that fails its checksum is never read.

#include "physics/simulation.h"

#include <filesystem>
#include <string>

namespace ganache {

/// What a checkpoint says about where it comes from.
struct CheckpointInfo {
    std::string scene;          ///< the scene's name
    std::string sceneHash;      ///< FNV-1a 64 of the scene file (Scene::hash)
    Real particleRadius = 0;    ///< [m], the run's quality
    std::int64_t frame = 0;     ///< the last frame written before it
};

struct Checkpoint {
    CheckpointInfo info;
    SimulationState state;
};

void writeCheckpoint(const std::filesystem::path& path, const CheckpointInfo& info, const SimulationState& state);

/// Reads a checkpoint; std::runtime_error saying what is wrong when the file is truncated, corrupt (checksum), of
/// another format version, or not a checkpoint.
Checkpoint readCheckpoint(const std::filesystem::path& path);

}  // namespace ganache

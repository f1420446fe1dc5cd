#pragma once
// Particle caches: OpenVDB point files read by renderers (Houdini, Blender) and by ganache's own stages.
// Grid `points` holds the fluid: P, v, id, mass, plus one attribute per effect attribute the particles carry
// (temperature, viscosity, ...). Grid `boundary`, when the scene has boundaries, holds P, volume and body.

#include "core/particles.h"

#include <filesystem>
#include <string>
#include <vector>

namespace ganache {

/// What a cache file says about itself (grid metadata).
struct CacheInfo {
    std::string scene;
    std::int64_t frame = 0;
    Real time = 0;            ///< simulated time [s]
    Real fps = 24;
    Real particleRadius = 0;  ///< [m]
};

/// The fluid as a binary PLY point cloud (`particles.export: ply`), for tools that read no OpenVDB points (Blender
/// 3.4 among them): per point float x y z, vx vy vz [m/s], mass [kg], uint id, then each attribute the cache carries
/// (float, vectors as <name>_x, _y, _z); no faces; in id order. Metres, y up, as every other output. Written
/// atomically.
void writeParticlePly(const std::filesystem::path& path, const ParticleSet& fluid, const CacheInfo& info);

struct CacheContents {
    CacheInfo info;
    ParticleSet fluid;  ///< sorted by id
    std::vector<BoundaryBody> boundaries;
};

/// Writes one cache file atomically, sealed with a checksum footer that OpenVDB readers ignore. Positions are stored as 32-bit offsets within voxels of 4 particle
/// radii (error below 1e-7 of a voxel), velocities and effect attributes as 32-bit floats, mass and the
/// boundary volume as 64-bit floats, id as a 64-bit integer.
void writeParticleCache(const std::filesystem::path& path, const ParticleSet& fluid,
                        const std::vector<BoundaryBody>& boundaries, const CacheInfo& info);

/// Reads a cache; InputError when the file is missing, truncated or corrupt (checksum), or lacks `points`.
CacheContents readParticleCache(const std::filesystem::path& path);

}  // namespace ganache

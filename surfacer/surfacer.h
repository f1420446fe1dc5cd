#pragma once
// The surfacer: fluid particles become a narrow-band level set (OpenVDB) and a triangle mesh a renderer reads.
// OpenVDB stays behind this header: only the surfacer's own .cpp files include it.
//
// Three ways to turn particles into a level set (scene key surface.method):
//  - spheres: a sphere of 2.5 r around every particle, large enough to leave no bubble between disordered
//    particles (their union's distance evaluated near the surface only), then moved inward by 1.36 r (the
//    level-set offset of smoothing.cpp) so that a flat layer's surface sits about r above its top particles (where
//    the lattice cells end);
//  - smooth_spheres: Zhu & Bridson 2005: distance to the weighted average of the neighbours within 2.7 r, less
//    0.9 r, which fills the dips between spheres; evaluated only near the surface, like the anisotropic kernels;
//  - anisotropic: Yu & Turk 2013: each particle's kernel (support 4 r) stretched along its neighbours' spread
//    (a principal component analysis, at most 2:1, volume kept), so thin sheets and threads stay smooth instead
//    of beading; the surface is where the kernel sum falls to half its value inside a lattice of spacing 2 r. The
//    sum is taken only near the surface (found on a lattice of twice the voxel), and the signed distance comes
//    from it directly (kernel_level_sets.cpp).
// Then mean-curvature smoothing (smoothing.cpp: OpenVDB LevelSetFilter's flow on the leaves' buffers), and meshing
// (contour.cpp: dual contouring on the leaves' buffers, closed and manifold, flat areas merged per `adaptivity`).

#include "core/particles.h"
#include "scene/scene.h"

#include <array>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

namespace ganache {

/// A triangle mesh with per-vertex normals and, on request, per-vertex temperatures.
struct SurfaceMesh {
    std::vector<Vec3> points;
    std::vector<Vec3> normals;                          ///< unit, outward
    std::vector<std::array<std::uint32_t, 3>> triangles;  ///< counter-clockwise seen from outside
    std::vector<float> temperature;                     ///< per vertex, when asked for [C]

    /// Sets the vertex normals to the area-weighted normals of the faces around each vertex.
    void normalsFromFaces();
    /// Enclosed volume (divergence theorem) [m^3]; meaningful for closed meshes.
    Real volume() const;
    /// Edges used by exactly one triangle, and edges used by more, but not by two in opposite directions; both zero
    /// for a closed, manifold, consistently oriented mesh.
    std::pair<std::size_t, std::size_t> openAndNonManifoldEdges() const;
};

/// Wall time of each part of surfacing one frame [s].
struct SurfaceTimings {
    double levelSet = 0;    ///< particles to level set (for anisotropic: kernels, coarse and fine sums, distance)
    double smoothing = 0;   ///< mean-curvature filter
    double grids = 0;       ///< extra grids (density, temperature, vel)
    double mesh = 0;        ///< meshing, normals, per-vertex temperatures
    double total() const { return levelSet + smoothing + grids + mesh; }
};

/// The surface of one frame: the level set (grid `surface`), optional extra grids, and the mesh.
class FrameSurface {
public:
    FrameSurface();
    ~FrameSurface();
    FrameSurface(FrameSurface&&) noexcept;
    FrameSurface& operator=(FrameSurface&&) noexcept;

    Real voxelSize() const;
    std::size_t activeVoxels() const;  ///< of the level set
    /// Signed distance at a world point (trilinear; negative inside, background outside the band) [m].
    Real signedDistance(const Vec3& p) const;
    const SurfaceMesh& mesh() const { return m_mesh; }
    SurfaceMesh& mesh() { return m_mesh; }
    const SurfaceTimings& timings() const { return m_timings; }

    /// Writes every grid to one .vdb file, atomically (a temporary file renamed into place).
    void writeVdb(const std::filesystem::path& path, const std::string& sceneName, std::int64_t frame) const;

private:
    friend FrameSurface surfaceParticles(const ParticleSet&, Real, const SurfaceSettings&);
    struct Grids;
    std::unique_ptr<Grids> m_grids;
    SurfaceMesh m_mesh;
    SurfaceTimings m_timings;
};

/// Surfaces the particles (radius r of the run) as the settings ask: level set, extra grids, mesh. An empty set
/// gives an empty level set and an empty mesh.
FrameSurface surfaceParticles(const ParticleSet& fluid, Real particleRadius, const SurfaceSettings& settings);

/// Bytes one frame of `particles` particles is expected to need at most (for the memory check).
double estimateSurfaceBytes(std::size_t particles, Real particleRadius, const SurfaceSettings& settings);

/// Triangles one frame's mesh is expected to have (for the render stage's memory).
double estimateSurfaceTriangles(std::size_t particles, Real particleRadius, const SurfaceSettings& settings);

/// Rough sizes of one frame's files [bytes]: the level set (with the extra grids asked for) and the OBJ mesh (0
/// without `mesh`). For the disk estimate printed before a run.
std::pair<double, double> estimateSurfaceFileBytes(std::size_t particles, Real particleRadius,
                                                   const SurfaceSettings& settings);

/// Writes a Wavefront OBJ atomically: `v` and `vn` per vertex, faces `f v//vn`; with temperatures, each vertex
/// also has a texture coordinate `vt T 0` carrying its temperature in C (faces `f v/vt/vn`), the one per-vertex
/// value every OBJ reader keeps. `header` goes in comment lines at the top.
void writeObj(const std::filesystem::path& path, const SurfaceMesh& mesh, const std::string& header);

/// Reads a triangle OBJ as writeObj writes it (normals and temperatures optional; normals from the faces when
/// absent). InputError naming the file and line when it is missing or malformed.
SurfaceMesh readObj(const std::filesystem::path& path);

/// Writes a binary little-endian PLY atomically: per vertex float x y z nx ny nz (and `temperature` [C] when the
/// mesh has them), triangles as `vertex_indices` lists; `header` goes in comment lines.
void writePly(const std::filesystem::path& path, const SurfaceMesh& mesh, const std::string& header);

/// Reads a binary little-endian triangle PLY (properties in any order and of any scalar type; normals from the
/// faces when absent). InputError naming the file when it is missing or malformed.
SurfaceMesh readPly(const std::filesystem::path& path);

/// writePly for a path ending in .ply, else writeObj; readSurfaceMesh likewise.
void writeSurfaceMesh(const std::filesystem::path& path, const SurfaceMesh& mesh, const std::string& header);
SurfaceMesh readSurfaceMesh(const std::filesystem::path& path);

}  // namespace ganache

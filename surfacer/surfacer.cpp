#include "surfacer/surfacer.h"

#include "surfacer/level_sets.h"

#include "core/attributes.h"
#include "core/neighbour_search.h"
#include "core/parallel.h"
#include "core/timing.h"
#include "io/vdb_file.h"

#include <openvdb/openvdb.h>
#include <openvdb/tools/Interpolation.h>
#include <openvdb/tools/LevelSetUtil.h>
#include <openvdb/tools/Morphology.h>
#include <openvdb/tools/Prune.h>
#include <openvdb/tools/SignedFloodFill.h>
#include <openvdb/tree/LeafManager.h>

#include <map>
#include <mutex>

namespace ganache {

namespace {

using openvdb::FloatGrid;

constexpr Real kHalfBand = 3;           // voxels each side of the surface
// Spheres: the radius (in particle radii) that leaves no void inside a lattice of spacing 2r (sqrt 3 = 1.73 reaches
// the centre of each lattice cube), and the inward move that brings a flat lattice's mean surface height from
// 1.54 r (the mean of the union of spheres over a cell) back to r, where the lattice cells end.
constexpr Real kSphereRadius = 2.5;
constexpr Real kSphereInset = 1.36;
// Smooth spheres: radius and search radius (particle radii) that put a lattice ball of radius 20 r within
// 0.2 % of its particles' volume (2 r and 4 r gave +16 %; 1 r and 2 r, -1.7 %).
constexpr Real kSmoothRadius = 0.9;
constexpr Real kSmoothSearch = 2.7;

void initialiseOpenVdb() {
    static std::once_flag once;
    std::call_once(once, [] { openvdb::initialize(); });
}

// --- the narrow band ----------------------------------------------------------------------------------------

// The spheres' fields leave part of the fluid's inside active (the bricks evaluated around the surface, where
// the nearest sphere is never far and Zhu-Bridson's mean stays near the point, so that their values stay inside
// the band), and the smoothing's cost with it. Keeps only the voxels within the half band of a sign change; the
// rest reads as inside or outside by flood fill.
void trimToBand(FloatGrid& grid) {
    grid.tree().voxelizeActiveTiles();
    std::vector<const surfacing::FloatLeaf*> leaves;
    grid.tree().getNodes(leaves);
    using MaskLeaf = openvdb::MaskTree::LeafNodeType;
    std::vector<std::unique_ptr<MaskLeaf>> crossed(leaves.size());
    forEachBlock(leaves.size(), [&](std::size_t begin, std::size_t end) {
        surfacing::LeafNeighbourhood at(grid.tree());  // a leaf and its neighbours' faces, read once
        for (std::size_t l = begin; l != end; ++l) {
            at.gather(*leaves[l]);
            auto mask = std::make_unique<MaskLeaf>(leaves[l]->origin(), false);
            for (auto it = leaves[l]->cbeginValueOn(); it; ++it) {
                const int i = int(it.pos() >> 6), j = int((it.pos() >> 3) & 7), k = int(it.pos() & 7);
                const bool inside = at(i, j, k) < 0;
                const bool crossing = (at(i - 1, j, k) < 0) != inside || (at(i + 1, j, k) < 0) != inside ||
                                      (at(i, j - 1, k) < 0) != inside || (at(i, j + 1, k) < 0) != inside ||
                                      (at(i, j, k - 1) < 0) != inside || (at(i, j, k + 1) < 0) != inside;
                if (crossing) mask->setValueOn(it.pos());
            }
            if (!mask->isEmpty()) crossed[l] = std::move(mask);
        }
    }, 16);
    openvdb::MaskGrid::Ptr band = openvdb::MaskGrid::create();
    for (auto& leaf : crossed)
        if (leaf) band->tree().addLeaf(leaf.release());
    openvdb::tools::dilateActiveValues(band->tree(), int(kHalfBand), openvdb::tools::NN_FACE_EDGE_VERTEX,
                                       openvdb::tools::IGNORE_TILES);
    grid.tree().topologyIntersection(band->tree());
    openvdb::tools::signedFloodFill(grid.tree());
    openvdb::tools::pruneLevelSet(grid.tree());
}

// --- spheres -----------------------------------------------------------------------------------------------

FloatGrid::Ptr spheres(const std::vector<Vec3>& x, Real r, Real voxel) {
    const FloatGrid::Ptr grid = surfacing::sphereUnionLevelSet(x, kSphereRadius * r, voxel, kHalfBand);
    trimToBand(*grid);
    // On the leaves' buffers with first-order renormalisation: OpenVDB's LevelSetFilter::offset, with its fifth-order
    // stencils through tree accessors, took 90 % of a frame (docs/benchmarks.md).
    surfacing::offsetLevelSet(*grid, float(kSphereInset * r));
    return grid;
}

// --- per-voxel and per-vertex attributes from the nearest particle ------------------------------------------

class NearestParticle {
public:
    NearestParticle(const std::vector<Vec3>& x, Real cell) : m_x(x), m_grid(cell) {
        m_grid.build(x);
        m_grid.releaseWorkingMemory();
    }
    /// The index of the nearest particle within two cells, or -1.
    std::int64_t find(const Vec3& p) const {
        const Real cell = m_grid.cellSize();
        const std::int64_t cx = std::int64_t(std::floor(p.x() / cell)), cy = std::int64_t(std::floor(p.y() / cell)),
                           cz = std::int64_t(std::floor(p.z() / cell));
        std::int64_t best = -1;
        Real bestDistance = std::numeric_limits<Real>::infinity();
        for (std::int64_t a = cx - 1; a <= cx + 1; ++a)
            for (std::int64_t b = cy - 1; b <= cy + 1; ++b)
                for (std::int64_t c = cz - 1; c <= cz + 1; ++c) {
                    const std::int64_t cellIndex = m_grid.findCell(a, b, c);
                    if (cellIndex < 0) continue;
                    for (std::size_t k = m_grid.cellBegin(std::size_t(cellIndex));
                         k < m_grid.cellBegin(std::size_t(cellIndex) + 1); ++k) {
                        const std::uint32_t j = m_grid.sortedIndices()[k];
                        const Real d = (m_x[j] - p).squaredNorm();
                        if (d < bestDistance) bestDistance = d, best = j;
                    }
                }
        return best;
    }

private:
    const std::vector<Vec3>& m_x;
    UniformGrid m_grid;
};

// A grid with the level set's topology whose voxels take value(nearest particle) (or `fallback`).
template <class GridT, class Value>
typename GridT::Ptr attributeGrid(const FloatGrid& surface, const NearestParticle& nearest, const std::string& name,
                                  Value&& value, typename GridT::ValueType fallback) {
    typename GridT::Ptr g = GridT::create(fallback);
    g->setTransform(surface.transform().copy());
    g->setName(name);
    g->tree().topologyUnion(surface.tree());
    openvdb::tree::LeafManager<typename GridT::TreeType> leaves(g->tree());
    leaves.foreach([&](typename GridT::TreeType::LeafNodeType& leaf, std::size_t) {
        for (auto it = leaf.beginValueOn(); it; ++it) {
            const openvdb::Vec3d p = surface.transform().indexToWorld(it.getCoord());
            const std::int64_t j = nearest.find(Vec3(p.x(), p.y(), p.z()));
            it.setValue(j < 0 ? fallback : value(std::size_t(j)));
        }
    });
    return g;
}

// --- meshing -----------------------------------------------------------------------------------------------

SurfaceMesh meshOf(const FloatGrid& surface, Real adaptivity) {
    SurfaceMesh mesh;
    surfacing::contourLevelSet(surface, adaptivity, mesh.points, mesh.triangles);
    mesh.normalsFromFaces();
    return mesh;
}

}  // namespace

struct FrameSurface::Grids {
    FloatGrid::Ptr surface;
    openvdb::GridPtrVec extra;
};

FrameSurface::FrameSurface() : m_grids(std::make_unique<Grids>()) {}
FrameSurface::~FrameSurface() = default;
FrameSurface::FrameSurface(FrameSurface&&) noexcept = default;
FrameSurface& FrameSurface::operator=(FrameSurface&&) noexcept = default;

Real FrameSurface::voxelSize() const { return m_grids->surface->voxelSize()[0]; }
std::size_t FrameSurface::activeVoxels() const { return m_grids->surface->activeVoxelCount(); }

Real FrameSurface::signedDistance(const Vec3& p) const {
    const openvdb::tools::GridSampler<FloatGrid, openvdb::tools::BoxSampler> sampler(*m_grids->surface);
    return sampler.wsSample(openvdb::Vec3R(p.x(), p.y(), p.z()));
}

void FrameSurface::writeVdb(const std::filesystem::path& path, const std::string& sceneName, std::int64_t frame) const {
    openvdb::GridPtrVec grids{m_grids->surface};
    grids.insert(grids.end(), m_grids->extra.begin(), m_grids->extra.end());
    for (auto& g : grids) {
        g->insertMeta("ganache_scene", openvdb::StringMetadata(sceneName));
        g->insertMeta("ganache_frame", openvdb::Int64Metadata(frame));
    }
    writeVdbAtomically(path, openvdb::GridCPtrVec(grids.begin(), grids.end()));
}

FrameSurface surfaceParticles(const ParticleSet& fluid, Real r, const SurfaceSettings& settings) {
    initialiseOpenVdb();
    const Real voxel = settings.voxelFraction * r;
    FrameSurface out;
    FloatGrid::Ptr& surface = out.m_grids->surface;
    const std::vector<Vec3>& x = fluid.x();
    SurfaceTimings& timings = out.m_timings;
    if (x.empty()) {
        surface = openvdb::createLevelSet<FloatGrid>(voxel, kHalfBand);
    } else {
        {
            const ScopedTimer timer(timings.levelSet);
            switch (settings.method) {
            case SurfaceMethod::Spheres: surface = spheres(x, r, voxel); break;
            case SurfaceMethod::SmoothSpheres:
                surface = surfacing::smoothSpheresLevelSet(x, kSmoothRadius * r, kSmoothSearch * r, voxel, kHalfBand);
                trimToBand(*surface);
                break;
            case SurfaceMethod::Anisotropic: surface = surfacing::anisotropicLevelSet(x, r, voxel, kHalfBand); break;
            }
        }
        if (settings.smoothing > 0) {
            const ScopedTimer timer(timings.smoothing);
            surfacing::smoothLevelSet(*surface, settings.smoothing);
        }
    }
    surface->setName("surface");
    surface->setGridClass(openvdb::GRID_LEVEL_SET);

    Stopwatch gridClock;
    if (settings.densityGrid) {
        FloatGrid::Ptr fog = surface->deepCopy();
        openvdb::tools::sdfToFogVolume(*fog);
        fog->setName("density");
        out.m_grids->extra.push_back(fog);
    }
    const std::vector<Real>* temperature = fluid.find(attribute::kTemperature);
    const bool wantTemperature = (settings.temperatureGrid || settings.meshTemperature) && temperature;
    std::unique_ptr<NearestParticle> nearest;
    if (!x.empty() && (wantTemperature || settings.velocityGrid))
        nearest = std::make_unique<NearestParticle>(x, 4 * r);
    if (settings.temperatureGrid && temperature && nearest)
        out.m_grids->extra.push_back(attributeGrid<FloatGrid>(
            *surface, *nearest, "temperature", [&](std::size_t j) { return float((*temperature)[j]); }, 0.f));
    if (settings.velocityGrid && nearest) {
        const auto& v = fluid.v();
        auto vel = attributeGrid<openvdb::Vec3SGrid>(
            *surface, *nearest, "vel",
            [&](std::size_t j) { return openvdb::Vec3s(float(v[j].x()), float(v[j].y()), float(v[j].z())); },
            openvdb::Vec3s(0.f));
        vel->setVectorType(openvdb::VEC_CONTRAVARIANT_RELATIVE);
        out.m_grids->extra.push_back(vel);
    }
    timings.grids = gridClock.seconds();
    if (settings.mesh) {
        const ScopedTimer timer(timings.mesh);
        out.m_mesh = meshOf(*surface, settings.adaptivity);
        if (settings.meshTemperature && temperature && nearest) {
            auto& t = out.m_mesh.temperature;
            t.resize(out.m_mesh.points.size());
            forEachParticle(t.size(), [&](std::size_t k) {
                const std::int64_t j = nearest->find(out.m_mesh.points[k]);
                t[k] = j < 0 ? 0.f : float((*temperature)[std::size_t(j)]);
            });
        }
    }
    return out;
}

namespace {

// Voxels of the final narrow band: twice that of a cube of the fluid's volume (splashes and sheets have more
// surface than a compact puddle, where this overestimates the band 1.25x).
Real bandVoxels(std::size_t particles, Real r, const SurfaceSettings& settings) {
    const Real voxel = settings.voxelFraction * r;
    const Real volume = Real(particles) * 8 * r * r * r;
    return 2 * 6 * std::pow(volume, 2.0 / 3.0) * 2 * kHalfBand / (voxel * voxel);
}

}  // namespace

double estimateSurfaceBytes(std::size_t particles, Real r, const SurfaceSettings& settings) {
    // Calibrated on surface_bench's puddles (200k and 1M particles, docs/benchmarks.md), where the measured peak
    // was 60-75 bytes per voxel of the final band (the band, its smoothing's copies, the mesh); 200 bytes a particle
    // cover the cache and the per-particle kernels. Every estimate was above the measured peak (1.6-2.3x; the
    // anisotropic kernel sum, now taken only near the surface, stays within the same bound).
    return 80 * bandVoxels(particles, r, settings) + 200.0 * double(particles);
}

double estimateSurfaceTriangles(std::size_t particles, Real r, const SurfaceSettings& settings) {
    // About two triangles per surface voxel (the band's middle layer) without adaptivity: a bound, which the
    // default adaptivity brings 4-7x under.
    return settings.mesh ? 2 * bandVoxels(particles, r, settings) / (2 * kHalfBand) : 0.0;
}

std::pair<double, double> estimateSurfaceFileBytes(std::size_t particles, Real r, const SurfaceSettings& settings) {
    // A level-set voxel takes about 4 bytes in the file (float values, compressed topology); each extra grid
    // about as much again. A triangle takes about 90 bytes of OBJ text with its share of the vertices and normals,
    // 26 of binary PLY (13 of its own, half a vertex of 24-28). On the default scene at preview (96 frames) these
    // give 83 MiB of level sets and 624 MiB of meshes against 61 and 583 MiB written.
    const int grids = 1 + settings.densityGrid + settings.temperatureGrid + 3 * settings.velocityGrid;
    return {4.0 * grids * bandVoxels(particles, r, settings),
            (settings.meshPly ? 26.0 : 90.0) * estimateSurfaceTriangles(particles, r, settings)};
}

Real SurfaceMesh::volume() const {
    Real v = 0;
    for (const auto& t : triangles) v += points[t[0]].dot(points[t[1]].cross(points[t[2]]));
    return v / 6;
}

std::pair<std::size_t, std::size_t> SurfaceMesh::openAndNonManifoldEdges() const {
    // Per edge (a < b): its uses from a to b and from b to a.
    std::map<std::pair<std::uint32_t, std::uint32_t>, std::array<int, 2>> uses;
    for (const auto& t : triangles)
        for (int k = 0; k < 3; ++k) {
            const std::uint32_t a = t[k], b = t[(k + 1) % 3];
            ++uses[{std::min(a, b), std::max(a, b)}][a < b ? 0 : 1];
        }
    std::size_t open = 0, nonManifold = 0;
    for (const auto& [edge, n] : uses) {
        open += n[0] + n[1] == 1;
        nonManifold += n[0] + n[1] > 1 && (n[0] != 1 || n[1] != 1);
    }
    return {open, nonManifold};
}

}  // namespace ganache

// The only sampler file that includes OpenVDB (its headers are slow to compile).
#include "sampler/inside.h"

#include <openvdb/openvdb.h>
#include <openvdb/tools/Interpolation.h>
#include <openvdb/tools/MeshToVolume.h>
#include <tbb/parallel_for.h>

namespace ganache {

std::vector<std::uint8_t> insideByLevelSet(const TriangleMesh& mesh, const std::vector<Vec3>& points, Real voxel) {
    openvdb::initialize();
    const auto transform = openvdb::math::Transform::createLinearTransform(voxel);
    std::vector<openvdb::Vec3s> vertices;
    vertices.reserve(mesh.vertices.size());
    for (const Vec3& v : mesh.vertices) vertices.emplace_back(float(v.x()), float(v.y()), float(v.z()));
    std::vector<openvdb::Vec3I> triangles;
    triangles.reserve(mesh.triangles.size());
    for (const auto& t : mesh.triangles) triangles.emplace_back(t[0], t[1], t[2]);
    // A narrow band of 3 voxels each side; OpenVDB signs the inside by flood fill, independent of face normals.
    const openvdb::FloatGrid::Ptr grid = openvdb::tools::meshToLevelSet<openvdb::FloatGrid>(*transform, vertices, triangles, 3.0f);

    std::vector<std::uint8_t> inside(points.size(), 0);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, points.size(), 4096), [&](const auto& range) {
        // Accessors cache tree nodes and are not shared between threads. The sampler keeps a reference to the
        // accessor, so it must be a named object that outlives it (a temporary dangled: AddressSanitizer).
        const openvdb::FloatGrid::ConstAccessor accessor = grid->getConstAccessor();
        const openvdb::tools::GridSampler<openvdb::FloatGrid::ConstAccessor, openvdb::tools::BoxSampler> sampler(
            accessor, grid->transform());
        for (std::size_t i = range.begin(); i != range.end(); ++i) {
            const Vec3& p = points[i];
            inside[i] = sampler.wsSample(openvdb::Vec3d(p.x(), p.y(), p.z())) < 0;
        }
    });
    return inside;
}

}  // namespace ganache

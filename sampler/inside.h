#pragma once
// Inside/outside tests for triangle meshes: what the sampler uses to fill a mesh with fluid and to carve fluid
// out of closed solids.

#include "geometry/mesh.h"
#include "scene/scene.h"

#include <cstdint>
#include <memory>
#include <vector>

namespace ganache {

/// Generalised winding numbers (Jacobson et al. 2013) evaluated fast with a bounding-volume tree whose far
/// clusters are replaced by their dipole (Barill et al. 2018, first order): w = 1 inside a closed outward mesh,
/// 0 outside, and a smooth, robust value for meshes with holes or self-intersections.
class WindingNumber {
public:
    explicit WindingNumber(const TriangleMesh& mesh);
    ~WindingNumber();
    Real at(const Vec3& q) const;

private:
    struct Node;
    Real visit(std::uint32_t node, const Vec3& q) const;
    const TriangleMesh& m_mesh;
    std::vector<std::uint32_t> m_order;  // triangles, grouped by leaf
    std::vector<Node> m_nodes;
};

/// For every point, 1 when it is inside the mesh. `voxel` is the level set's voxel size [m] (level sets only).
/// Runs in parallel over the points.
std::vector<std::uint8_t> insideMesh(const MeshShape& shape, const std::vector<Vec3>& points, Real voxel);

/// The level-set method alone (OpenVDB mesh-to-level-set, sign by flood fill); needs a closed mesh.
std::vector<std::uint8_t> insideByLevelSet(const TriangleMesh& mesh, const std::vector<Vec3>& points, Real voxel);

}  // namespace ganache

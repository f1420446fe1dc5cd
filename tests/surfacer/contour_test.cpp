// The mesher (surfacer/contour.cpp) on level sets built voxel by voxel: the corners a particle frame reaches rarely.

#include "surfacer/level_sets.h"
#include "surfacer/surfacer.h"

#include <gtest/gtest.h>

#include <cmath>

using namespace ganache;

namespace {

// The mesh of a level set (normals left out).
SurfaceMesh contour(const openvdb::FloatGrid& grid, Real adaptivity) {
    SurfaceMesh mesh;
    surfacing::contourLevelSet(grid, adaptivity, mesh.points, mesh.triangles);
    return mesh;
}

// A level set of unit voxels with `value` at every voxel of [lo, hi]^3 (inactive voxels elsewhere at +3).
template <class F>
openvdb::FloatGrid::Ptr gridOf(int lo, int hi, F&& value) {
    auto grid = openvdb::FloatGrid::create(3.f);
    auto access = grid->getAccessor();
    for (int i = lo; i <= hi; ++i)
        for (int j = lo; j <= hi; ++j)
            for (int k = lo; k <= hi; ++k) access.setValue(openvdb::Coord(i, j, k), value(Vec3(i, j, k)));
    return grid;
}

}  // namespace

TEST(Contour, AnAirThreadAlongACellFaceLeavesTheMeshManifold) {
    // A ball of 8 voxels' radius pierced by a channel of air 0.4 voxel wide, lying diagonally in the plane y = 0:
    // on the faces of that plane the inside corners sit diagonally, and the cells above and below the plane would
    // both join the face's two crossings around the channel. One vertex per cell on each side would then join the
    // other twice and four triangles would share an edge (as a thread of smooth spheres once did); the mesher cuts
    // the channel at such faces instead.
    const Vec3 direction = Vec3(1, 0, 1).normalized();
    const auto grid = gridOf(-12, 12, [&](const Vec3& p) {
        const Real channel = 0.4 - (p - p.dot(direction) * direction).norm();
        return float(std::max(p.norm() - 8, channel));
    });
    for (const Real adaptivity : {0.0, 0.1}) {
        const SurfaceMesh mesh = contour(*grid, adaptivity);
        ASSERT_GT(mesh.triangles.size(), 500u);
        const auto [open, nonManifold] = mesh.openAndNonManifoldEdges();
        EXPECT_EQ(open, 0u) << "adaptivity " << adaptivity;
        EXPECT_EQ(nonManifold, 0u) << "adaptivity " << adaptivity;
        // The ball's volume less the channel's, within a few percent (the lattice's first-order crossings).
        EXPECT_NEAR(mesh.volume() / (4 * M_PI / 3 * 512), 1.0, 0.05);
    }
}

TEST(Contour, CellsWhoseFirstCornerLiesInATileGetVertices) {
    // A cube of fluid whose voxels start at the origin, stored only in the leaves from the origin up: the cells
    // between x = -1 and 0 (and y, z) are named by voxels of the tile below, which has no leaf. Their vertices
    // must exist (the mesher once read a missing vertex there and crashed).
    const auto grid = gridOf(0, 12, [](const Vec3& p) {
        const Vec3 d = (p - Vec3::Constant(2.5)).cwiseAbs() - Vec3::Constant(3);
        return float(d.maxCoeff());
    });
    const SurfaceMesh mesh = contour(*grid, 0.0);
    ASSERT_GT(mesh.triangles.size(), 100u);
    const auto [open, nonManifold] = mesh.openAndNonManifoldEdges();
    EXPECT_EQ(open, 0u);
    EXPECT_EQ(nonManifold, 0u);
    EXPECT_GT(mesh.volume(), 0);  // outward, counter-clockwise faces
}

#pragma once
// The surfacer's own level-set builders, shared between its .cpp files (OpenVDB stays inside the surfacer).

#include "core/types.h"

#include <openvdb/openvdb.h>

#include <array>
#include <cstdint>
#include <vector>

namespace ganache::surfacing {

using FloatLeaf = openvdb::FloatTree::LeafNodeType;
/// Eight floats, one SIMD vector: a row of a leaf along z, or eight candidates of a kernel's spread.
using RowOfEight = Eigen::Array<float, 8, 1>;

/// A leaf's values and one layer of its neighbours' around it, read once so that stencils need no tree lookups.
class LeafNeighbourhood {
public:
    /// Reads leaves of `tree`, whose topology must not change while this is in use.
    explicit LeafNeighbourhood(const openvdb::FloatTree& tree) : m_tree(tree) {}
    /// Points outside the tree's leaves take its tiles' values; with inactiveAsNaN, every inactive point reads NaN.
    void gather(const FloatLeaf& leaf, bool inactiveAsNaN = false);
    /// The same from values already found: data[a][b][c] the 512 values of the leaf at offset 8 (a - 1, b - 1, c - 1)
    /// from this one (index 1 along each axis this leaf), or null where there is none and tile[a][b][c] its value.
    /// With facesOnly, the points outside the leaf that are no voxel's face neighbour read NaN.
    void gather(const float* const (&data)[3][3][3], const float (&tile)[3][3][3], bool facesOnly = false);
    /// Adds `move` to every value gathered whose magnitude is below `band`.
    void moveInside(float band, float move);
    /// The value at (i, j, k) of the leaf, each in -1..8.
    float operator()(int i, int j, int k) const { return m_values[i + 1][j + 1][k + 1]; }
    /// The row along z at (i, j), each in -1..8: its ten values from k = -1 to 8.
    const float* row(int i, int j) const { return m_values[i + 1][j + 1]; }

private:
    // Unregistered: one per task, so that finding the 26 neighbours goes through cached nodes, not from the root.
    openvdb::tree::ValueAccessor<const openvdb::FloatTree, false> m_tree;
    float m_values[10][10][10];
};

/// Takes the leaf's active voxels at or past `band` (a distance) out of the band, their values clamped to -band or
/// band.
void trimLeaf(FloatLeaf& leaf, float band);

/// Yu & Turk's anisotropic kernels (see surfacer.h): the narrow-band level set of half-width halfBand voxels
/// where the particles' kernel sum falls to half its value inside a lattice of spacing 2r.
openvdb::FloatGrid::Ptr anisotropicLevelSet(const std::vector<Vec3>& x, Real r, Real voxel, Real halfBand);

/// Zhu & Bridson's smooth spheres: the narrow-band level set of half-width halfBand voxels of the distance from each
/// point to the weighted mean of the particles within `search` [m], less `radius` [m].
openvdb::FloatGrid::Ptr smoothSpheresLevelSet(const std::vector<Vec3>& x, Real radius, Real search, Real voxel,
                                              Real halfBand);

/// The union of spheres of `radius` [m] around the particles: its narrow-band level set of half-width halfBand
/// voxels, inside included where the band reaches.
openvdb::FloatGrid::Ptr sphereUnionLevelSet(const std::vector<Vec3>& x, Real radius, Real voxel, Real halfBand);

/// `passes` steps of mean-curvature flow, each followed by one renormalisation (smoothing.cpp).
void smoothLevelSet(openvdb::FloatGrid& grid, std::int64_t passes);

/// Moves the surface inward by `distance` [m] in equal moves of at most half a voxel, renormalising the band twice
/// after each move (smoothing.cpp).
void offsetLevelSet(openvdb::FloatGrid& grid, float distance);

/// The mesh of the level set's zero crossing (contour.cpp): vertices in world space and triangles counter-clockwise
/// seen from outside, closed and manifold; `adaptivity` in [0, 1] merges cells where the surface is flat (0: none).
void contourLevelSet(const openvdb::FloatGrid& grid, Real adaptivity, std::vector<Vec3>& points,
                     std::vector<std::array<std::uint32_t, 3>>& triangles);

}  // namespace ganache::surfacing

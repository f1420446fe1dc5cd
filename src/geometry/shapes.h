#pragma once
// Procedural solids as closed triangle meshes with outward faces: what ganache builds itself rather than reads.

#include "geometry/mesh.h"

namespace ganache {

TriangleMesh boxMesh(const Vec3& min, const Vec3& max);
/// A sphere subdivided from an icosahedron until its edges are at most maxEdge long.
TriangleMesh sphereMesh(const Vec3& centre, Real radius, Real maxEdge);
/// A capped cylinder between two points.
TriangleMesh cylinderMesh(const Vec3& a, const Vec3& b, Real radius, Real maxEdge);

/// A square grid of horizontal bars (Weiler et al. 2018, Fig. 8): bars along x and along z, `count` of each,
/// spread evenly over a square of side `size` centred on `centre`, each with a square cross-section `thickness`.
struct BarsGrid {
    Vec3 centre = Vec3::Zero();
    Real size = 0;
    std::int64_t count = 0;
    Real thickness = 0;
};
TriangleMesh barsMesh(const BarsGrid& bars);

/// A dough hook (Fig. 1): a vertical shaft from `top` down to the start of a helix about the same axis that
/// turns `turns` times with radius `radius` while it descends `helixHeight`; the rod has radius `rodRadius`.
struct DoughHook {
    Vec3 top = Vec3::Zero();  ///< top of the shaft, on the axis
    Real shaftLength = 0;
    Real radius = 0;
    Real helixHeight = 0;
    Real turns = 0;
    Real rodRadius = 0;
};
TriangleMesh doughHookMesh(const DoughHook& hook, Real maxEdge);

/// A tube of radius `radius` along a polyline, closed with flat caps.
TriangleMesh tubeMesh(const std::vector<Vec3>& path, Real radius, Real maxEdge);

}  // namespace ganache

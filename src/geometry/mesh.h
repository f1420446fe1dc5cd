#pragma once
// Triangle meshes: loading through assimp (OBJ, PLY, STL, OFF, glTF, ...), placing them in a scene, repairing
// face orientation, and the pre-flight facts an artist needs before sampling (closed or not, bad edges, ...).

#include "core/types.h"

#include <array>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

namespace ganache {

struct TriangleMesh {
    std::vector<Vec3> vertices;
    std::vector<std::array<std::uint32_t, 3>> triangles;

    bool empty() const { return triangles.empty(); }
    /// Axis-aligned bounds of the vertices that triangles use; (inf, -inf) when empty.
    std::pair<Vec3, Vec3> bounds() const;
    /// Signed enclosed volume (divergence theorem) [m^3]; positive for a closed mesh with outward faces.
    Real signedVolume() const;
    Real area() const;
    /// Appends another mesh.
    void append(const TriangleMesh& other);
};

/// Reads every mesh of a file (all meshes and nodes merged, node transforms applied, polygons triangulated,
/// duplicate vertices joined). Throws InputError naming the file: missing, unreadable, unsupported format,
/// no triangles, non-finite vertices.
TriangleMesh readMeshFile(const std::filesystem::path& file);

/// Where a mesh goes in the scene: scaled, rotated (degrees about x, then y, then z), translated; or, with fit,
/// rotated and then scaled uniformly so its largest extent is fit.size and moved so its bounding box centre (or
/// its bottom centre, with fit.base) lands on the given point.
struct MeshPlacement {
    Vec3 scale = Vec3::Ones();
    Vec3 rotationDegrees = Vec3::Zero();
    Vec3 translation = Vec3::Zero();
    struct Fit {
        Real size = 0;           ///< [m]
        Vec3 point = Vec3::Zero();  ///< [m]
        bool base = false;       ///< point is the bottom centre (min y) rather than the centre
    };
    std::optional<Fit> fit;
};

/// Applies the placement; negative scales that mirror the mesh flip its faces back to outward.
void placeMesh(TriangleMesh& mesh, const MeshPlacement& placement);

/// The pre-flight facts of a mesh (`ganache sample --check`).
struct MeshCheck {
    std::size_t vertices = 0, triangles = 0;
    std::size_t boundaryEdges = 0;     ///< edges used by one triangle (holes)
    std::size_t nonManifoldEdges = 0;  ///< edges used by three or more triangles
    std::size_t degenerateTriangles = 0;  ///< zero area (repeated or collinear corners)
    std::size_t flippedTriangles = 0;  ///< faces turned against their neighbours (fixed by orientConsistently)
    std::size_t components = 0;        ///< edge-connected pieces
    Vec3 min = Vec3::Zero(), max = Vec3::Zero();
    Real volume = 0;                   ///< after orientation repair [m^3]
    bool closed() const { return boundaryEdges == 0 && nonManifoldEdges == 0 && triangles > 0; }
};

/// Removes degenerate triangles, makes every edge-connected piece consistently oriented (flipping the faces
/// that disagree with their neighbours) and turns each closed piece outward. Returns the facts, counted before
/// the repair.
MeshCheck repairMesh(TriangleMesh& mesh);

}  // namespace ganache

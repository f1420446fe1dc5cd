#include "geometry/mesh.h"

#include "core/errors.h"

#include <assimp/Importer.hpp>
#include <assimp/postprocess.h>
#include <assimp/scene.h>
#include <fmt/format.h>

#include <cmath>
#include <limits>
#include <queue>
#include <unordered_map>

namespace ganache {

namespace {

Vec3 normalTimesTwoArea(const TriangleMesh& m, const std::array<std::uint32_t, 3>& t) {
    const Vec3& a = m.vertices[t[0]];
    return (m.vertices[t[1]] - a).cross(m.vertices[t[2]] - a);
}

std::uint64_t edgeKey(std::uint32_t a, std::uint32_t b) {
    return (std::uint64_t(std::min(a, b)) << 32) | std::max(a, b);
}

}  // namespace

std::pair<Vec3, Vec3> TriangleMesh::bounds() const {
    Vec3 lo = Vec3::Constant(std::numeric_limits<Real>::infinity()), hi = -lo;
    for (const auto& t : triangles)
        for (std::uint32_t v : t) {
            lo = lo.cwiseMin(vertices[v]);
            hi = hi.cwiseMax(vertices[v]);
        }
    return {lo, hi};
}

Real TriangleMesh::signedVolume() const {
    // Sum of signed tetrahedra to a point near the mesh (less round-off than the origin).
    if (empty()) return 0;
    const auto [lo, hi] = bounds();
    const Vec3 o = 0.5 * (lo + hi);
    Real v = 0;
    for (const auto& t : triangles)
        v += (vertices[t[0]] - o).dot((vertices[t[1]] - o).cross(vertices[t[2]] - o));
    return v / 6;
}

Real TriangleMesh::area() const {
    Real a = 0;
    for (const auto& t : triangles) a += 0.5 * normalTimesTwoArea(*this, t).norm();
    return a;
}

void TriangleMesh::append(const TriangleMesh& other) {
    const auto offset = std::uint32_t(vertices.size());
    vertices.insert(vertices.end(), other.vertices.begin(), other.vertices.end());
    for (auto t : other.triangles) triangles.push_back({t[0] + offset, t[1] + offset, t[2] + offset});
}

TriangleMesh readMeshFile(const std::filesystem::path& file) {
    std::error_code ec;
    if (!std::filesystem::is_regular_file(file, ec))
        throw InputError(fmt::format("{}: no such mesh file\n  fix: check the path (it is relative to the scene file)",
                                     file.string()));
    Assimp::Importer importer;
    // Points and lines carry no volume or surface: leave them out of the merged mesh.
    importer.SetPropertyInteger(AI_CONFIG_PP_SBP_REMOVE, aiPrimitiveType_POINT | aiPrimitiveType_LINE);
    const aiScene* scene = importer.ReadFile(
        file.string(), aiProcess_ValidateDataStructure | aiProcess_Triangulate | aiProcess_JoinIdenticalVertices |
                           aiProcess_PreTransformVertices |
                           aiProcess_SortByPType);
    if (!scene)
        throw InputError(fmt::format("{}: cannot read a triangle mesh from it: {}\n  fix: give an OBJ, PLY, STL, OFF "
                                     "or glTF file (or another format assimp reads) whose objects have faces",
                                     file.string(), importer.GetErrorString()));
    TriangleMesh mesh;
    for (unsigned m = 0; m < scene->mNumMeshes; ++m) {
        const aiMesh* src = scene->mMeshes[m];
        if (!(src->mPrimitiveTypes & aiPrimitiveType_TRIANGLE)) continue;
        TriangleMesh part;
        for (unsigned v = 0; v < src->mNumVertices; ++v) {
            const aiVector3D& p = src->mVertices[v];
            part.vertices.emplace_back(p.x, p.y, p.z);
        }
        for (unsigned f = 0; f < src->mNumFaces; ++f) {
            const aiFace& face = src->mFaces[f];
            if (face.mNumIndices != 3) continue;
            part.triangles.push_back({face.mIndices[0], face.mIndices[1], face.mIndices[2]});
        }
        mesh.append(part);
    }
    if (mesh.empty())
        throw InputError(fmt::format("{}: the file holds no triangles\n  fix: export the surface of the object "
                                     "(faces, not only points or lines)",
                                     file.string()));
    for (std::size_t v = 0; v < mesh.vertices.size(); ++v)
        if (!mesh.vertices[v].allFinite())
            throw InputError(fmt::format("{}: vertex {} is not finite ({}, {}, {})\n  fix: repair or re-export the mesh",
                                         file.string(), v, mesh.vertices[v].x(), mesh.vertices[v].y(),
                                         mesh.vertices[v].z()));
    return mesh;
}

void placeMesh(TriangleMesh& mesh, const MeshPlacement& p) {
    const Vec3 r = p.rotationDegrees * (M_PI / 180);
    const Mat3 rotation = (Eigen::AngleAxis<Real>(r.z(), Vec3::UnitZ()) * Eigen::AngleAxis<Real>(r.y(), Vec3::UnitY()) *
                           Eigen::AngleAxis<Real>(r.x(), Vec3::UnitX()))
                              .toRotationMatrix();
    if (p.fit) {
        for (Vec3& v : mesh.vertices) v = rotation * v;
        const auto [lo, hi] = mesh.bounds();
        const Real extent = (hi - lo).maxCoeff();
        const Real s = extent > 0 ? p.fit->size / extent : 1;
        Vec3 anchor = 0.5 * (lo + hi);
        if (p.fit->base) anchor.y() = lo.y();
        for (Vec3& v : mesh.vertices) v = p.fit->point + s * (v - anchor);
        return;
    }
    for (Vec3& v : mesh.vertices) v = rotation * p.scale.cwiseProduct(v) + p.translation;
    if (p.scale.prod() < 0)  // a mirror turns faces inside out
        for (auto& t : mesh.triangles) std::swap(t[1], t[2]);
}

MeshCheck repairMesh(TriangleMesh& mesh) {
    MeshCheck c;
    c.vertices = mesh.vertices.size();
    c.triangles = mesh.triangles.size();
    std::tie(c.min, c.max) = mesh.bounds();
    if (mesh.empty()) return c;

    // Degenerate faces carry no area and no orientation.
    const Real scale = (c.max - c.min).norm();
    const Real tinyArea = 1e-14 * scale * scale;
    std::vector<std::array<std::uint32_t, 3>> kept;
    for (const auto& t : mesh.triangles) {
        if (t[0] == t[1] || t[1] == t[2] || t[0] == t[2] || normalTimesTwoArea(mesh, t).norm() <= tinyArea) {
            ++c.degenerateTriangles;
            continue;
        }
        kept.push_back(t);
    }
    mesh.triangles = std::move(kept);
    const std::size_t n = mesh.triangles.size();

    // Which faces use each edge.
    std::unordered_map<std::uint64_t, std::vector<std::uint32_t>> edgeFaces;
    edgeFaces.reserve(3 * n);
    for (std::uint32_t f = 0; f < n; ++f)
        for (int e = 0; e < 3; ++e)
            edgeFaces[edgeKey(mesh.triangles[f][e], mesh.triangles[f][(e + 1) % 3])].push_back(f);
    for (const auto& [key, faces] : edgeFaces) {
        if (faces.size() == 1) ++c.boundaryEdges;
        if (faces.size() > 2) ++c.nonManifoldEdges;
    }

    // Does face f traverse the edge a -> b in this direction?
    auto runs = [&](std::uint32_t f, std::uint32_t a, std::uint32_t b) {
        const auto& t = mesh.triangles[f];
        for (int e = 0; e < 3; ++e)
            if (t[e] == a && t[(e + 1) % 3] == b) return true;
        return false;
    };
    // Flood each piece across its two-face edges; a neighbour that runs a shared edge the same way is flipped.
    std::vector<std::int32_t> component(n, -1);
    std::vector<std::uint8_t> flip(n, 0);
    for (std::uint32_t seed = 0; seed < n; ++seed) {
        if (component[seed] >= 0) continue;
        const auto id = std::int32_t(c.components++);
        std::vector<std::uint32_t> members{seed};
        std::queue<std::uint32_t> queue;
        component[seed] = id;
        queue.push(seed);
        while (!queue.empty()) {
            const std::uint32_t f = queue.front();
            queue.pop();
            auto t = mesh.triangles[f];
            if (flip[f]) std::swap(t[1], t[2]);
            for (int e = 0; e < 3; ++e) {
                const std::uint32_t a = t[e], b = t[(e + 1) % 3];
                const auto& faces = edgeFaces[edgeKey(a, b)];
                if (faces.size() != 2) continue;
                const std::uint32_t g = faces[0] == f ? faces[1] : faces[0];
                if (component[g] >= 0) continue;
                component[g] = id;
                flip[g] = runs(g, a, b);  // consistent neighbours run the shared edge b -> a
                members.push_back(g);
                queue.push(g);
            }
        }
        // Count the minority as the flipped faces, apply the flood's orientation, then turn the piece outward.
        std::size_t flipped = 0;
        for (std::uint32_t f : members) flipped += flip[f];
        c.flippedTriangles += std::min(flipped, members.size() - flipped);
        Real volume = 0;
        const Vec3 o = mesh.vertices[mesh.triangles[seed][0]];
        for (std::uint32_t f : members) {
            auto& t = mesh.triangles[f];
            if (flip[f]) std::swap(t[1], t[2]);
            volume += (mesh.vertices[t[0]] - o).dot((mesh.vertices[t[1]] - o).cross(mesh.vertices[t[2]] - o));
        }
        if (volume < 0)
            for (std::uint32_t f : members) std::swap(mesh.triangles[f][1], mesh.triangles[f][2]);
    }
    c.volume = mesh.signedVolume();
    return c;
}

}  // namespace ganache

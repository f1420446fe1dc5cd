#include "sampler/inside.h"

#include "core/parallel.h"

#include <algorithm>
#include <cmath>
#include <numeric>

namespace ganache {

namespace {

constexpr std::uint32_t kLeafSize = 8;
// A cluster farther than this many of its radii is replaced by its dipole; 2 keeps the error of the first-order
// expansion well below the 0.5 threshold that decides inside (Barill et al. use 2 as well).
constexpr Real kFarRatio = 2;

// Solid angle of triangle abc seen from the origin (Van Oosterom and Strackee 1983).
Real solidAngle(const Vec3& a, const Vec3& b, const Vec3& c) {
    const Real la = a.norm(), lb = b.norm(), lc = c.norm();
    const Real num = a.dot(b.cross(c));
    const Real den = la * lb * lc + a.dot(b) * lc + b.dot(c) * la + c.dot(a) * lb;
    return 2 * std::atan2(num, den);
}

}  // namespace

struct WindingNumber::Node {
    Vec3 centre = Vec3::Zero();  // area-weighted centroid
    Vec3 normal = Vec3::Zero();  // sum of area-weighted normals
    Real radius = 0;             // of the ball around `centre` holding every triangle of the node
    std::uint32_t begin = 0, end = 0;  // range in m_order
    std::uint32_t left = 0, right = 0;  // children; 0 for a leaf
};

WindingNumber::~WindingNumber() = default;

WindingNumber::WindingNumber(const TriangleMesh& mesh) : m_mesh(mesh) {
    const auto& V = mesh.vertices;
    const auto& T = mesh.triangles;
    m_order.resize(T.size());
    std::iota(m_order.begin(), m_order.end(), 0u);
    std::vector<Vec3> centroid(T.size());
    for (std::size_t t = 0; t < T.size(); ++t) centroid[t] = (V[T[t][0]] + V[T[t][1]] + V[T[t][2]]) / 3;

    // Top-down build, splitting each node at the median of its longest axis.
    m_nodes.reserve(2 * T.size() / kLeafSize + 2);
    m_nodes.push_back({});
    m_nodes[0].end = std::uint32_t(T.size());
    std::vector<std::uint32_t> stack{0};
    while (!stack.empty()) {
        const std::uint32_t id = stack.back();
        stack.pop_back();
        Node node = m_nodes[id];
        Real area = 0;
        Vec3 lo = Vec3::Constant(INFINITY), hi = -lo;
        for (std::uint32_t k = node.begin; k < node.end; ++k) {
            const auto& t = T[m_order[k]];
            const Vec3 n = 0.5 * (V[t[1]] - V[t[0]]).cross(V[t[2]] - V[t[0]]);
            node.normal += n;
            area += n.norm();
            node.centre += n.norm() * centroid[m_order[k]];
            lo = lo.cwiseMin(centroid[m_order[k]]);
            hi = hi.cwiseMax(centroid[m_order[k]]);
        }
        node.centre = area > 0 ? Vec3(node.centre / area) : Vec3(0.5 * (lo + hi));
        for (std::uint32_t k = node.begin; k < node.end; ++k)
            for (std::uint32_t v : T[m_order[k]]) node.radius = std::max(node.radius, (V[v] - node.centre).norm());
        if (node.end - node.begin > kLeafSize) {
            int axis;
            (hi - lo).maxCoeff(&axis);
            const std::uint32_t mid = (node.begin + node.end) / 2;
            std::nth_element(m_order.begin() + node.begin, m_order.begin() + mid, m_order.begin() + node.end,
                             [&](std::uint32_t a, std::uint32_t b) { return centroid[a][axis] < centroid[b][axis]; });
            node.left = std::uint32_t(m_nodes.size());
            node.right = node.left + 1;
            Node l, r;
            l.begin = node.begin, l.end = mid;
            r.begin = mid, r.end = node.end;
            m_nodes.push_back(l);
            m_nodes.push_back(r);
            stack.push_back(node.left);
            stack.push_back(node.right);
        }
        m_nodes[id] = node;
    }
}

Real WindingNumber::visit(std::uint32_t id, const Vec3& q) const {
    const Node& node = m_nodes[id];
    const Vec3 d = node.centre - q;
    const Real dist = d.norm();
    if (dist > kFarRatio * node.radius) return node.normal.dot(d) / (dist * dist * dist);  // dipole
    if (node.left == 0) {
        Real sum = 0;
        for (std::uint32_t k = node.begin; k < node.end; ++k) {
            const auto& t = m_mesh.triangles[m_order[k]];
            sum += solidAngle(m_mesh.vertices[t[0]] - q, m_mesh.vertices[t[1]] - q, m_mesh.vertices[t[2]] - q);
        }
        return sum;
    }
    return visit(node.left, q) + visit(node.right, q);
}

Real WindingNumber::at(const Vec3& q) const {
    if (m_nodes.empty() || m_mesh.triangles.empty()) return 0;
    return visit(0, q) / (4 * M_PI);
}

std::vector<std::uint8_t> insideMesh(const MeshShape& shape, const std::vector<Vec3>& points, Real voxel) {
    if (shape.method() == InsideMethod::LevelSet) return insideByLevelSet(*shape.mesh, points, voxel);
    const WindingNumber w(*shape.mesh);
    const auto [lo, hi] = shape.mesh->bounds();
    std::vector<std::uint8_t> inside(points.size(), 0);
    forEachParticle(points.size(), [&](std::size_t i) {
        const Vec3& p = points[i];
        if ((p.array() >= lo.array()).all() && (p.array() <= hi.array()).all()) inside[i] = w.at(p) > 0.5;
    }, 256);
    return inside;
}

}  // namespace ganache

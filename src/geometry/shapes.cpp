#include "geometry/shapes.h"

#include <cmath>
#include <map>

namespace ganache {

namespace {

int segmentsFor(Real radius, Real maxEdge) {
    return std::max(12, int(std::ceil(2 * M_PI * radius / maxEdge)));
}

}  // namespace

TriangleMesh boxMesh(const Vec3& lo, const Vec3& hi) {
    TriangleMesh m;
    for (int i = 0; i < 8; ++i) m.vertices.emplace_back(i & 1 ? hi.x() : lo.x(), i & 2 ? hi.y() : lo.y(), i & 4 ? hi.z() : lo.z());
    // Two triangles per face, counter-clockwise seen from outside.
    const std::uint32_t quads[6][4] = {{0, 4, 6, 2}, {1, 3, 7, 5}, {0, 1, 5, 4}, {2, 6, 7, 3}, {0, 2, 3, 1}, {4, 5, 7, 6}};
    for (const auto& q : quads) {
        m.triangles.push_back({q[0], q[1], q[2]});
        m.triangles.push_back({q[0], q[2], q[3]});
    }
    return m;
}

TriangleMesh sphereMesh(const Vec3& centre, Real radius, Real maxEdge) {
    const Real t = (1 + std::sqrt(5.0)) / 2;
    TriangleMesh m;
    for (const Vec3& v : {Vec3(-1, t, 0), Vec3(1, t, 0), Vec3(-1, -t, 0), Vec3(1, -t, 0), Vec3(0, -1, t), Vec3(0, 1, t),
                          Vec3(0, -1, -t), Vec3(0, 1, -t), Vec3(t, 0, -1), Vec3(t, 0, 1), Vec3(-t, 0, -1), Vec3(-t, 0, 1)})
        m.vertices.push_back(v.normalized());
    m.triangles = {{0, 11, 5}, {0, 5, 1},  {0, 1, 7},   {0, 7, 10}, {0, 10, 11}, {1, 5, 9}, {5, 11, 4},
                   {11, 10, 2}, {10, 7, 6}, {7, 1, 8},   {3, 9, 4},  {3, 4, 2},   {3, 2, 6}, {3, 6, 8},
                   {3, 8, 9},  {4, 9, 5},  {2, 4, 11},  {6, 2, 10}, {8, 6, 7},   {9, 8, 1}};
    // Split every edge at its midpoint (pushed onto the sphere) until the edges are short enough.
    Real edge = (m.vertices[0] - m.vertices[11]).norm() * radius;
    while (edge > maxEdge && m.triangles.size() < 5'000'000) {
        std::map<std::pair<std::uint32_t, std::uint32_t>, std::uint32_t> mid;
        auto midpoint = [&](std::uint32_t a, std::uint32_t b) {
            const auto key = std::minmax(a, b);
            auto [it, fresh] = mid.try_emplace(key, std::uint32_t(m.vertices.size()));
            if (fresh) m.vertices.push_back((m.vertices[a] + m.vertices[b]).normalized());
            return it->second;
        };
        std::vector<std::array<std::uint32_t, 3>> next;
        for (const auto& f : m.triangles) {
            const std::uint32_t a = midpoint(f[0], f[1]), b = midpoint(f[1], f[2]), c = midpoint(f[2], f[0]);
            next.push_back({f[0], a, c});
            next.push_back({f[1], b, a});
            next.push_back({f[2], c, b});
            next.push_back({a, b, c});
        }
        m.triangles = std::move(next);
        edge /= 2;
    }
    for (Vec3& v : m.vertices) v = centre + radius * v;
    return m;
}

TriangleMesh tubeMesh(const std::vector<Vec3>& path, Real radius, Real maxEdge) {
    TriangleMesh m;
    if (path.size() < 2) return m;
    const int seg = segmentsFor(radius, maxEdge);
    // Rings carried along the path by parallel transport, so the tube does not twist.
    Vec3 tangent = (path[1] - path[0]).normalized();
    Vec3 u = tangent.unitOrthogonal();
    for (std::size_t k = 0; k < path.size(); ++k) {
        const Vec3 next = k + 1 < path.size() ? Vec3((path[k + 1] - path[k]).normalized()) : tangent;
        const Vec3 t = k == 0 ? tangent : Vec3((tangent + next).normalized());
        u = (u - u.dot(t) * t).normalized();
        const Vec3 w = t.cross(u);
        for (int s = 0; s < seg; ++s) {
            const Real a = 2 * M_PI * s / seg;
            m.vertices.push_back(path[k] + radius * (std::cos(a) * u + std::sin(a) * w));
        }
        tangent = next;
    }
    const auto ring = [&](std::size_t k, int s) { return std::uint32_t(k * seg + (s % seg)); };
    for (std::size_t k = 0; k + 1 < path.size(); ++k)
        for (int s = 0; s < seg; ++s) {
            m.triangles.push_back({ring(k, s), ring(k + 1, s + 1), ring(k + 1, s)});
            m.triangles.push_back({ring(k, s), ring(k, s + 1), ring(k + 1, s + 1)});
        }
    // Caps: a fan around a centre vertex at each end.
    const auto startCentre = std::uint32_t(m.vertices.size());
    m.vertices.push_back(path.front());
    const auto endCentre = std::uint32_t(m.vertices.size());
    m.vertices.push_back(path.back());
    const std::size_t last = path.size() - 1;
    for (int s = 0; s < seg; ++s) {
        m.triangles.push_back({startCentre, ring(0, s + 1), ring(0, s)});
        m.triangles.push_back({endCentre, ring(last, s), ring(last, s + 1)});
    }
    return m;
}

TriangleMesh cylinderMesh(const Vec3& a, const Vec3& b, Real radius, Real maxEdge) {
    const int n = std::max(1, int(std::ceil((b - a).norm() / maxEdge)));
    std::vector<Vec3> path;
    for (int k = 0; k <= n; ++k) path.push_back(a + (b - a) * (Real(k) / n));
    return tubeMesh(path, radius, maxEdge);
}

TriangleMesh barsMesh(const BarsGrid& g) {
    TriangleMesh m;
    const Real half = 0.5 * g.size, t = 0.5 * g.thickness;
    for (std::int64_t k = 0; k < g.count; ++k) {
        const Real offset = g.count == 1 ? 0 : -half + g.size * Real(k) / Real(g.count - 1);
        const Vec3 c = g.centre;
        m.append(boxMesh(c + Vec3(-half, -t, offset - t), c + Vec3(half, t, offset + t)));  // along x
        m.append(boxMesh(c + Vec3(offset - t, -t, -half), c + Vec3(offset + t, t, half)));  // along z
    }
    return m;
}

TriangleMesh doughHookMesh(const DoughHook& h, Real maxEdge) {
    std::vector<Vec3> path;
    const Vec3 helixTop = h.top - Vec3(0, h.shaftLength, 0);
    const int shaftSteps = std::max(1, int(std::ceil(h.shaftLength / maxEdge)));
    for (int k = 0; k < shaftSteps; ++k) path.push_back(h.top - Vec3(0, h.shaftLength * k / shaftSteps, 0));
    // The rod bends out from the axis to the helix radius over a quarter turn, then winds down.
    const Real length = 2 * M_PI * h.radius * h.turns + h.helixHeight;
    const int steps = std::max(16, int(std::ceil(length / maxEdge)));
    for (int k = 0; k <= steps; ++k) {
        const Real s = Real(k) / steps;
        const Real angle = 2 * M_PI * h.turns * s;
        const Real r = h.radius * std::min<Real>(1, 4 * h.turns * s);
        path.push_back(helixTop + Vec3(r * std::cos(angle), -h.helixHeight * s, r * std::sin(angle)));
    }
    return tubeMesh(path, h.rodRadius, maxEdge);
}

}  // namespace ganache

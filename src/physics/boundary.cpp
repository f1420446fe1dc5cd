#include "physics/boundary.h"

#include "core/neighbour_search.h"
#include "core/parallel.h"

#include <cmath>

namespace ganache {

std::vector<Vec3> boxWallPoints(const Vec3& min, const Vec3& max, bool openTop, Real r) {
    const Vec3 extent = max - min;
    Eigen::Vector3i n;
    for (int a = 0; a < 3; ++a) n[a] = std::max(1, int(std::ceil(extent[a] / r - 1e-9)));
    const Vec3 step = extent.cwiseQuotient(n.cast<Real>());
    std::vector<Vec3> x;
    for (int k = 0; k <= n.z(); ++k)
        for (int j = 0; j <= n.y(); ++j)
            for (int i = 0; i <= n.x(); ++i) {
                const bool side = i == 0 || i == n.x() || k == 0 || k == n.z();
                const bool bottom = j == 0, top = j == n.y();
                if (side || bottom || (top && !openTop))
                    x.push_back(min + Vec3(i * step.x(), j * step.y(), k * step.z()));
            }
    return x;
}

std::vector<Vec3> planePoints(const Vec3& origin, const Vec3& n, const Vec3& lo, const Vec3& hi, Real r, Real h) {
    const Vec3 u = (std::abs(n.x()) < 0.9 ? Vec3::UnitX() : Vec3::UnitY()).cross(n).normalized();
    const Vec3 w = n.cross(u);
    Real uMin = INFINITY, uMax = -INFINITY, wMin = INFINITY, wMax = -INFINITY;
    for (int c = 0; c < 8; ++c) {
        const Vec3 corner((c & 1) ? hi.x() : lo.x(), (c & 2) ? hi.y() : lo.y(), (c & 4) ? hi.z() : lo.z());
        const Vec3 d = corner - origin;
        uMin = std::min(uMin, d.dot(u)), uMax = std::max(uMax, d.dot(u));
        wMin = std::min(wMin, d.dot(w)), wMax = std::max(wMax, d.dot(w));
    }
    std::vector<Vec3> x;
    const Vec3 loH = lo.array() - h, hiH = hi.array() + h;
    for (Real a = std::floor(uMin / r) * r; a <= uMax + r; a += r)
        for (Real b = std::floor(wMin / r) * r; b <= wMax + r; b += r) {
            const Vec3 p = origin + a * u + b * w;
            if ((p.array() >= loH.array()).all() && (p.array() <= hiH.array()).all()) x.push_back(p);
        }
    return x;
}

Real flatWallCalibration(const CubicSpline& w) {
    // The fluid lattice (spacing d = 2r = h/2) on y >= 0 and a wall sheet (spacing r) at y = -d, where the
    // missing fluid layer would be. Akinci's 1/delta alone makes the sheet about 6 % heavier than that layer.
    const Real h = w.supportRadius(), d = h / 2, s = h / 4;
    const int m = int(std::ceil(h / s)) + 1;
    Real all = 0, half = 0;
    for (int k = -m; k <= m; ++k)
        for (int j = -m; j <= m; ++j)
            for (int i = -m; i <= m; ++i) {
                const Real wv = w.W(d * Vec3(i, j, k));
                all += wv;
                if (j >= 0) half += wv;
            }
    Real deltaFlat = 0, sheet = 0;
    for (int b = -2 * m; b <= 2 * m; ++b)
        for (int a = -2 * m; a <= 2 * m; ++a) {
            deltaFlat += w.W(Vec3(a * s, 0, b * s));
            sheet += w.W(Vec3(a * s, -d, b * s));
        }
    // rho_0 half / all + rho_0 (gamma / deltaFlat) sheet = rho_0
    return (1 - half / all) * deltaFlat / sheet;
}

std::vector<Real> boundaryVolumes(const std::vector<Vec3>& x, const CubicSpline& w) {
    const Real gamma = flatWallCalibration(w);
    UniformGrid grid(w.supportRadius());
    NeighbourList nl;
    findFluidNeighbours(grid, x, w.supportRadius(), nl);
    std::vector<Real> volume(x.size());
    forEachParticle(x.size(), [&](std::size_t k) {
        Real delta = w.W0();
        for (std::uint32_t l : nl.of(k)) delta += w.W(x[k] - x[l]);
        volume[k] = gamma / delta;
    });
    return volume;
}

}  // namespace ganache

#include "sampler.h"

#include "kernels.h"
#include "neighbour_search.h"
#include "parallel.h"
#include "progress.h"

#include <cmath>
#include <variant>

namespace ganache {

namespace {

bool contains(const FluidShape& shape, const Vec3& x) {
    if (auto* b = std::get_if<BoxShape>(&shape))
        return (x.array() >= b->min.array()).all() && (x.array() <= b->max.array()).all();
    const auto& s = std::get<SphereShape>(shape);
    return (x - s.centre).squaredNorm() <= s.radius * s.radius;
}

// Lattice sites of spacing d inside the shape. A box holds round(extent / d) sites per axis, centred in it,
// so that the sampled volume n d^3 matches the box; a sphere's lattice is centred on its centre.
std::vector<Vec3> latticeSites(const FluidShape& shape, Real d) {
    std::vector<Vec3> sites;
    if (auto* b = std::get_if<BoxShape>(&shape)) {
        Eigen::Vector3i n;
        for (int a = 0; a < 3; ++a) n[a] = std::max(1, int(std::lround((b->max[a] - b->min[a]) / d)));
        const Vec3 first = Real(0.5) * (b->min + b->max) - Real(0.5) * d * (n.cast<Real>() - Vec3::Ones());
        sites.reserve(std::size_t(n.prod()));
        for (int k = 0; k < n.z(); ++k)
            for (int j = 0; j < n.y(); ++j)
                for (int i = 0; i < n.x(); ++i) sites.push_back(first + d * Vec3(i, j, k));
        return sites;
    }
    const auto& s = std::get<SphereShape>(shape);
    const int m = int(std::ceil(s.radius / d));
    for (int k = -m; k <= m; ++k)
        for (int j = -m; j <= m; ++j)
            for (int i = -m; i <= m; ++i) {
                const Vec3 x = s.centre + d * Vec3(i, j, k);
                if (contains(shape, x)) sites.push_back(x);
            }
    return sites;
}

// Surface grid of a box with spacing <= r: every grid point with an index on a face, top face left out
// when the box is open (the rim of the side walls stays).
std::vector<Vec3> sampleBoxWalls(const BoxBoundary& box, Real r) {
    const Vec3 extent = box.max - box.min;
    Eigen::Vector3i n;
    for (int a = 0; a < 3; ++a) n[a] = std::max(1, int(std::ceil(extent[a] / r - 1e-9)));
    const Vec3 step = extent.cwiseQuotient(n.cast<Real>());
    std::vector<Vec3> x;
    for (int k = 0; k <= n.z(); ++k)
        for (int j = 0; j <= n.y(); ++j)
            for (int i = 0; i <= n.x(); ++i) {
                const bool side = i == 0 || i == n.x() || k == 0 || k == n.z();
                const bool bottom = j == 0, top = j == n.y();
                if (side || bottom || (top && !box.openTop))
                    x.push_back(box.min + Vec3(i * step.x(), j * step.y(), k * step.z()));
            }
    return x;
}

// A plane sampled with spacing r where it passes within one support radius of the domain.
std::vector<Vec3> samplePlane(const PlaneBoundary& plane, const Vec3& lo, const Vec3& hi, Real r, Real h) {
    const Vec3 n = plane.normal;
    const Vec3 u = (std::abs(n.x()) < 0.9 ? Vec3::UnitX() : Vec3::UnitY()).cross(n).normalized();
    const Vec3 w = n.cross(u);
    const Vec3 origin = plane.point;
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

}  // namespace

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

DensityCheck checkDensity(const ParticleSet& fluid, const std::vector<Real>& restDensity,
                          const std::vector<BoundaryBody>& boundaries, const CubicSpline& w) {
    DensityCheck out;
    const std::size_t n = fluid.size();
    if (n == 0) return out;
    const Real h = w.supportRadius();
    UniformGrid fluidGrid(h);
    NeighbourList ff;
    findFluidNeighbours(fluidGrid, fluid.x(), h, ff);

    std::vector<Vec3> bx;
    std::vector<Real> bv;
    for (const auto& b : boundaries) {
        bx.insert(bx.end(), b.x.begin(), b.x.end());
        bv.insert(bv.end(), b.volume.begin(), b.volume.end());
    }
    UniformGrid boundaryGrid(h);
    boundaryGrid.build(bx);
    NeighbourList fb;
    findNeighbours(fluidGrid, fluid.x(), boundaryGrid, bx, h, false, fb);

    // A particle with as many fluid neighbours as the fullest one has no free surface within reach.
    std::size_t fullest = 0;
    for (std::size_t i = 0; i < n; ++i) fullest = std::max(fullest, ff.of(i).size());

    const auto& x = fluid.x();
    const auto& m = fluid.mass();
    Real sumInterior = 0;
    for (std::size_t i = 0; i < n; ++i) {
        Real rho = m[i] * w.W0();
        for (std::uint32_t j : ff.of(i)) rho += m[j] * w.W(x[i] - x[j]);
        for (std::uint32_t k : fb.of(i)) rho += restDensity[i] * bv[k] * w.W(x[i] - bx[k]);
        const Real error = rho / restDensity[i] - 1;
        out.maxCompression = std::max(out.maxCompression, error);
        if (ff.of(i).size() == fullest && fb.of(i).size() == 0) {
            sumInterior += error;
            ++out.interiorCount;
        }
    }
    out.meanInterior = out.interiorCount ? sumInterior / Real(out.interiorCount) : 0;
    return out;
}

Sample sampleScene(const Scene& scene) {
    Sample out;
    const Real r = scene.particleRadius;
    const Real d = 2 * r;
    const CubicSpline w(supportRadiusFor(r));
    std::vector<Real> restDensity;

    Progress progress("sample", scene.fluids.size() + scene.boundaries.size());
    std::size_t done = 0;
    const Real h = w.supportRadius();
    std::vector<Vec3> allBoundary;
    for (const BoundarySpec& spec : scene.boundaries) {
        BoundaryBody body;
        body.name = spec.name;
        if (auto* box = std::get_if<BoxBoundary>(&spec.shape)) body.x = sampleBoxWalls(*box, r);
        else body.x = samplePlane(std::get<PlaneBoundary>(spec.shape), scene.domainMin, scene.domainMax, r, h);
        body.volume = boundaryVolumes(body.x, w);
        allBoundary.insert(allBoundary.end(), body.x.begin(), body.x.end());
        out.boundaries.push_back(std::move(body));
        progress.update(++done);
    }
    // Fluid closer to a wall than the lattice spacing would start compressed: a wall stands in for one layer
    // of fluid at that distance (see flatWallCalibration).
    UniformGrid boundaryGrid(d);
    boundaryGrid.build(allBoundary);
    const Real keepDistance2 = (d * (1 - 1e-6)) * (d * (1 - 1e-6));
    auto tooCloseToWall = [&](const Vec3& x) {
        const Vec3 c = (x / d).array().floor();
        for (int dz = -1; dz <= 1; ++dz)
            for (int dy = -1; dy <= 1; ++dy)
                for (int dx = -1; dx <= 1; ++dx) {
                    const std::int64_t cell = boundaryGrid.findCell(std::int64_t(c.x()) + dx, std::int64_t(c.y()) + dy,
                                                                    std::int64_t(c.z()) + dz);
                    if (cell < 0) continue;
                    for (std::size_t s = boundaryGrid.cellBegin(cell); s < boundaryGrid.cellBegin(cell + 1); ++s)
                        if ((allBoundary[boundaryGrid.sortedIndices()[s]] - x).squaredNorm() < keepDistance2) return true;
                }
        return false;
    };

    // Which fluid (or emitter) a particle came from matters only when there are several (per-fluid viscosity,
    // colours); emitters give their particles the indices after the fluids'.
    std::vector<Real>* fluidIndex = scene.sourceMaterials().size() > 1 ? &out.fluid.addScalar("fluid") : nullptr;
    for (std::size_t f = 0; f < scene.fluids.size(); ++f) {
        const FluidSpec& spec = scene.fluids[f];
        const Real mass = latticeMass(d, spec.material.density, w);
        std::size_t count = 0;
        for (const Vec3& x : latticeSites(spec.shape, d)) {
            bool taken = false;
            for (std::size_t e = 0; e < f && !taken; ++e) taken = contains(scene.fluids[e].shape, x);
            if (taken) {
                ++out.carved;
                continue;
            }
            if (tooCloseToWall(x)) {
                ++out.carvedByBoundaries;
                continue;
            }
            out.fluid.add(x, spec.velocity, mass, out.fluid.size());
            if (fluidIndex) fluidIndex->back() = Real(f);
            restDensity.push_back(spec.material.density);
            ++count;
        }
        out.fluidCounts.push_back(count);
        progress.update(++done);
    }
    progress.finish();
    out.density = checkDensity(out.fluid, restDensity, out.boundaries, w);
    return out;
}

}  // namespace ganache
